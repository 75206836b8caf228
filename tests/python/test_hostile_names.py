"""Hostile names in every name-bearing place (issue 51): the model (its name, bodies, joints and
their motors, a site), the arm file (its name, joints, home and torque limits by joint, flange), the
drive table (its joints, the EDS's file name) and the EDS (ProductName, ParameterName of mapped and
unmapped objects), and the study config (a scenario's name and description).

Once through the whole pipeline with the worst names we know (hostile_names.WORST), as a user runs
it: `armctl study --arm ...` imports the arm, synthesises its design, builds it, runs it in software
in the loop over CiA 402 and writes the report; then the checks: no symbol of a built program comes
from the input (nm), report.html in headless Chromium holds no element or script from the input,
the run's DBC parses with cantools, its MCAP export reads back, and every name is where a user
looks for it, escaped for that place.

Then hypothesis draws names (quotes, backslashes, line breaks, */, <script>, $(...), %s, unicode,
very long ones) for every place, and each example goes through every stage that does not take a
build folder of its own: the import (gen/arm, refused in one line or prepared), the generated C
(compiled with the build's warnings: its symbols the same as for plain names, its names the input's
bytes), the drive table and the DBC (cantools), and the report of the pipeline's study with the
drawn names in it (Chromium). A build per example would take minutes; a few examples, one build."""

from __future__ import annotations

import json
import shutil
import subprocess
import urllib.parse
from pathlib import Path
from typing import Any

import pytest
from hypothesis import HealthCheck, event, given, settings, strategies as st

from gen.lib.escape import c_string, identifier, markdown_code
from gen.lib.one_line import one_line
from gen.lib.paths import REPO
from headless_browser import Browser, page_facts
from hil_procs import armctl
from hostile_names import EDS_NAMED, JOINTS, STABLE, TOKEN, WORST, Names, hostile_arm, study_config

pytestmark = pytest.mark.long  # one arm built and studied (a minute or two), a few drawn arms imported

FOLDER = STABLE / "hostile arm"  # a space in the arm's folder, too
CC = shutil.which("cc") or shutil.which("gcc")
C_FLAGS = ["-std=c11", "-Wall", "-Wextra", "-Wconversion", "-Wshadow", "-Wvla", "-Werror"]


@pytest.fixture(scope="module")
def pipeline(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Any]:
    """The worst names through import, synthesis, build, a SIL run over CiA 402 and the report."""
    arm = hostile_arm(FOLDER, WORST)
    cfg = study_config(FOLDER / "study.toml", WORST)
    out = tmp_path_factory.mktemp("hostile") / "study"
    r = armctl("study", "--arm", str(arm), "--config", str(cfg), "--methods", "pm-paper-weights", "--scenarios",
               WORST.scenario, "--seeds", "1", "--duration", "0.5", "--confirm", "0", "--out", str(out), timeout=900)
    assert r.returncode == 0, r.stdout[-2000:] + r.stderr[-3000:]
    study = json.loads((out / "study.json").read_text())
    from gen.arm import load_arm_file
    from tools.build.arm import ArmRef, arm_build_dir

    ref = ArmRef(load_arm_file(arm.resolve()).model.resolve(), arm.resolve())  # as --arm makes it (arm_from_args)
    return {"out": out, "study": study, "run": out / WORST.scenario / "pm-paper-weights" / "seed-1",
            "build": arm_build_dir("release", ref), "stdout": r.stdout, "stderr": r.stderr}


def _executables(bdir: Path) -> list[Path]:
    out = []
    for p in bdir.rglob("*"):
        if p.is_file() and p.suffix in ("", ".a", ".so", ".elf") and "CMakeFiles" not in p.parts:
            with open(p, "rb") as fh:
                if fh.read(4) == b"\x7fELF" or p.suffix == ".a":
                    out.append(p)
    return out


def test_no_symbol_of_a_built_program_comes_from_the_input(pipeline: dict[str, Any]) -> None:
    progs = _executables(pipeline["build"])
    names = {p.name for p in progs}
    assert {"arm_controller", "arm_sim", "arm_sil", "arm_lcm_logger"} <= names, names
    for p in progs:
        r = subprocess.run(["nm", "-a", str(p)], capture_output=True, text=True)
        assert TOKEN not in r.stdout, (p, [ln for ln in r.stdout.splitlines() if TOKEN in ln][:5])


def test_every_name_is_where_a_user_looks_escaped_for_that_place(pipeline: dict[str, Any]) -> None:
    run = json.loads((pipeline["run"] / "run.json").read_text())
    assert run["results"]["joint_names"] == WORST.joints  # the data keeps the names as they are
    assert run["results"]["result"] == "ok", run["results"].get("verdict_reasons")
    header = (pipeline["build"] / "generated" / "arm_robot_model_data.h").read_text()
    for i, j in enumerate(WORST.joints):
        assert c_string(j, "x") in header, j
    md = (pipeline["out"] / "report.md").read_text()
    for j in WORST.joints:
        assert markdown_code(j) in md, j
    assert markdown_code(WORST.scenario) in md
    summary = (pipeline["out"] / "summary.txt").read_text()
    assert summary.startswith(one_line(WORST.scenario) + " (1 seed(s); means)")
    # the command that runs it again is the same words in a shell
    import shlex

    cmd = next(iter(pipeline["study"]["commands"][WORST.scenario].values()))
    argv = shlex.split(cmd.replace("SEED", "1"))
    assert argv[argv.index("--scenario") + 1] == WORST.scenario


# What report.html's own elements are: the Markdown's, the figures' and plotly's (its SVG and its
# controls). An element of any other kind came from the input.
PAGE_ELEMENTS = {"h1", "h2", "h3", "p", "ul", "li", "code", "pre", "strong", "em", "table", "thead", "tbody", "tr",
                 "th", "td", "div", "script", "img", "a", "span", "svg", "g", "path", "rect", "text", "tspan",
                 "defs", "clippath", "line", "circle", "style", "button", "input", "label", "br", "details", "summary"}


def _check_page(facts: dict[str, Any], names: list[str]) -> None:
    assert facts["title"] not in (TOKEN, "1"), "a name's script ran in the report"
    assert facts["scripts"] <= 2, facts["scripts"]
    assert facts["foreign_images"] == facts["handlers"] == facts["links"] == 0, \
        {k: facts[k] for k in ("foreign_images", "handlers", "links")}
    assert set(facts["elements"]) <= PAGE_ELEMENTS, set(facts["elements"]) - PAGE_ELEMENTS
    for n in names:  # shown as text, on one line (a line break in a name is shown as \n)
        assert one_line(n).strip() in facts["text"], n


def test_the_report_in_a_browser_holds_no_element_or_script_from_the_input(pipeline: dict[str, Any]) -> None:
    b = Browser()
    try:
        facts = page_facts(b, pipeline["out"] / "report.html")
    finally:
        b.close()
    _check_page(facts, [*WORST.joints, WORST.scenario, WORST.description])
    for j in WORST.joints:  # plotly's labels: the figures name the joints too
        assert one_line(j) in facts["svg_text"], j


def test_the_runs_dbc_parses_and_keeps_the_eds_names_beside_their_identifiers(pipeline: dict[str, Any]) -> None:
    import cantools

    db = cantools.database.load_file(str(pipeline["run"] / "canopen.dbc"))
    rpdo = db.get_message_by_name("RPDO1_node1")
    torque = WORST.parameters[0x6071]
    sig = rpdo.get_signal_by_name(identifier(torque, "x"))
    assert urllib.parse.unquote(sig.comment) == f"0x6071:00 {torque}"
    assert urllib.parse.unquote(rpdo.comment).startswith(f"joint {WORST.joints[0]}: ")
    tpdo = db.get_message_by_name("TPDO1_node3")
    assert identifier(WORST.parameters[0x6064], "x") in [s.name for s in tpdo.signals]


def test_the_runs_mcap_export_reads_back_with_the_names(pipeline: dict[str, Any], tmp_path: Path) -> None:
    import lcm
    from mcap.reader import make_reader

    target = tmp_path / "run.mcap"
    r = armctl("export", str(pipeline["run"]), "--mcap", "--out", str(target))
    assert r.returncode == 0, r.stdout + r.stderr
    counts: dict[str, int] = {}
    with open(target, "rb") as f:
        reader = make_reader(f)
        meta = {m.name: m.metadata for m in reader.iter_metadata()}
        for _, channel, message in reader.iter_messages(log_time_order=False):
            json.loads(message.data)
            counts[channel.topic] = counts.get(channel.topic, 0) + 1
    events: dict[str, int] = {}
    for ev in lcm.EventLog(str(pipeline["run"] / "telemetry.lcmlog"), "r"):
        events[ev.channel] = events.get(ev.channel, 0) + 1
    assert {ch: counts.get(ch, 0) for ch in events} == events
    assert any(",".join(WORST.joints) in m.get("joint_names", "") for m in meta.values()), meta.keys()


# ---- drawn names, every stage without a build of its own ------------------------------------------
XML_SAFE = st.characters(codec="utf-8", exclude_categories=("Cs", "Cc")) | st.sampled_from(list("\n\t"))
PIECES = ['"', "'", "\\", "\n", "*/", "/*", "??/", "<script>document.title='x'</script>", "<b>", "$(touch /tmp/p)",
          "`id`", "%s%n", "%{y}", "[a](javascript:x)", "![i](x.png)", "```", "~~~", "|", "#", "_e_", "&lt;", "é",
          "😀", "\u202e", "{", "}", ";"]
short = st.one_of(
    st.lists(st.sampled_from(PIECES) | st.text(XML_SAFE, min_size=1, max_size=4), min_size=1, max_size=6).map("".join),
    st.text(XML_SAFE, min_size=1, max_size=30))
long = st.builds(lambda c, k: c * k, st.sampled_from(['"', "x", "é", "\\"]), st.integers(300, 5000))  # very long
INI_SAFE = st.text(st.characters(codec="utf-8", exclude_categories=("Cs", "Cc", "Zl", "Zp"), exclude_characters=";"),
                   min_size=1, max_size=24).map(str.strip).filter(bool)


def _folder_name(s: str) -> str:
    """A drawn name made one a scenario may have (it names a folder: tools/study/config.py refuses others)."""
    s = s.replace("/", "\\")[:30]
    return s + "x" if s in (".", "..") else s


@st.composite
def names(draw: st.DrawFn) -> Names:
    """Short hostile names everywhere, very long ones where any length is data (bodies, the model,
    the site, the description), and in a quarter of the arms one very long joint name (which the C
    may not hold: refused in one line, or kept)."""
    joints = draw(st.lists(short, min_size=6, max_size=6, unique=True))
    if draw(st.integers(0, 3)) == 0:
        joints[draw(st.integers(0, 5))] = draw(long.filter(lambda s: s not in joints))
    bodies = draw(st.lists(short | long, min_size=6, max_size=6, unique=True))
    return Names(model=draw(short | long), arm=draw(short), joints=joints, bodies=bodies, site=draw(short | long),
                 product=draw(INI_SAFE), parameters={k: draw(INI_SAFE) for k in EDS_NAMED},
                 eds_file=draw(st.text(st.characters(codec="utf-8", exclude_categories=("Cs", "Cc"),
                                                     exclude_characters="/"), min_size=1, max_size=20)) + ".eds",
                 scenario=draw(short.map(_folder_name)),
                 description=draw(short | long))


def _compiled(gen_dir: Path, tmp: Path) -> tuple[set[str], list[str]]:
    """The arm's generated C built under the build's warnings with a main that prints
    ARM_JOINT_NAMES: the program's symbols, and the names as its bytes say."""
    main = tmp / "names.c"
    main.write_text('#include <stdio.h>\n#include "arm_robot_model_data.h"\n#include "arm_rnea_kernel.h"\n'
                    "int main(void) {\n    for (int i = 0; i < ARM_N_JOINTS; i++) {\n"
                    '        for (const char *c = ARM_JOINT_NAMES[i]; *c; c++) printf("%02x", (unsigned char)*c);\n'
                    '        printf("\\n");\n    }\n    return arm_rnea_kernel_fits(&ARM_ROBOT_MODEL) ? 0 : 1;\n}\n')
    exe = tmp / "names"
    r = subprocess.run([CC, *C_FLAGS, f"-I{gen_dir}", f"-I{REPO / 'firmware' / 'core' / 'include'}", str(main),
                        str(gen_dir / "arm_rnea_kernel.c"), "-o", str(exe), "-lm"], capture_output=True, text=True)
    assert r.returncode == 0, r.stderr[-3000:]
    run = subprocess.run([str(exe)], capture_output=True, text=True, check=True)
    nm = subprocess.run(["nm", "-a", str(exe)], capture_output=True, text=True, check=True).stdout
    symbols = {ln.split()[-1] for ln in nm.splitlines() if ln.split() and not ln.split()[-1].startswith(str(tmp))}
    return {s for s in symbols if "/" not in s and not s.endswith(".c")}, \
        [bytes.fromhex(h).decode("utf-8") for h in run.stdout.split()]


def _generated(arm_toml: Path, out: Path) -> dict[str, Any] | str:
    """The import and every generator of the build that reads names, in a folder: arm.json's info,
    or the one-line refusal."""
    from gen import canopen_dbc, drives, robot_model, rnea_kernel
    from gen.arm import ArmError, load_arm_file, prepare
    from gen.lib.model_hash import fnv1a64

    try:
        prep = prepare(load_arm_file(arm_toml.resolve()))
    except ArmError as exc:
        return str(exc)
    out.mkdir(parents=True, exist_ok=True)
    (out / "arm.xml").write_text(prep.xml)
    model = robot_model.extract(out / "arm.xml")
    h = fnv1a64((out / "arm.xml").read_bytes())
    (out / "arm_robot_dims.h").write_text(robot_model.dims_header(model))
    (out / "arm_robot_model_data.h").write_text(robot_model.model_header(model, "arm.xml", h))
    header, source = rnea_kernel.kernel_source(model, h)
    (out / "arm_rnea_kernel.h").write_text(header)
    (out / "arm_rnea_kernel.c").write_text(source)
    prep.info["arm_file"] = str(arm_toml.resolve())
    try:
        dbc = canopen_dbc.dbc_text(drives.load(prep.info))
    except (drives.DrivesError, canopen_dbc.DbcError) as exc:
        return str(exc)
    return {"info": prep.info, "dbc": dbc}


@pytest.fixture(scope="module")
def plain(tmp_path_factory: pytest.TempPathFactory) -> set[str]:
    """The symbols of the generated C of an arm with plain names: what every drawn arm's must be."""
    if CC is None:
        pytest.skip("no C compiler")
    tmp = tmp_path_factory.mktemp("plain")
    plain_names = Names(model="m", arm="a", joints=list(JOINTS), bodies=[f"b{i}" for i in range(6)], site="s",
                        product="p", parameters=dict(EDS_NAMED), eds_file="d.eds", scenario="s", description="d")
    got = _generated(hostile_arm(tmp / "arm", plain_names), tmp / "gen")
    assert isinstance(got, dict), got
    return _compiled(tmp / "gen", tmp)[0]


@pytest.fixture(scope="module")
def browser() -> Any:
    b = Browser()
    yield b
    b.close()


def _report_with(pipeline: dict[str, Any], n: Names, out: Path) -> Path:
    """The pipeline's study, its arm's and scenario's names replaced by the drawn ones (its run kept
    under the drawn scenario's folder, for the figures), written as a report."""
    from tools.study.report import write_report

    study = json.loads(json.dumps(pipeline["study"]))
    study["description"] = n.description
    study["arm"]["joint_names"] = n.joints
    study["arm"]["name"] = n.arm
    for j, d in zip(n.joints, study["arm"].get("drivetrain") or []):
        d["name"] = j
    sc = study["scenarios"].pop(WORST.scenario)
    sc["definition"]["description"] = n.description
    study["scenarios"][n.scenario] = sc
    study["commands"] = {n.scenario: {m: c for m, c in study["commands"][WORST.scenario].items()}}
    shutil.copytree(pipeline["out"] / WORST.scenario, out / n.scenario)
    write_report(out, study, figures=True)
    return out / "report.html"


@settings(max_examples=4, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture,
                                                                HealthCheck.too_slow, HealthCheck.data_too_large])
@given(n=names())
def test_drawn_names_in_every_place_are_refused_in_one_line_or_kept_as_data(
        n: Names, pipeline: dict[str, Any], plain: set[str], browser: Browser, tmp_path_factory: Any) -> None:
    tmp = tmp_path_factory.mktemp("drawn")
    got = _generated(hostile_arm(tmp / "arm", n), tmp / "gen")
    if isinstance(got, str):  # refused: one line, naming what
        assert "\n" not in got and len(got) < 2000, got
        event(f"refused: {got.split(': ')[-1][:60]}")
        return
    event("kept as data")
    assert [j["name"] for j in got["info"]["joints"]] == n.joints
    symbols, shown = _compiled(tmp / "gen", tmp)
    assert symbols == plain  # no symbol comes from a name
    assert shown == n.joints  # the names, byte for byte
    import cantools

    db = cantools.database.load_string(got["dbc"], database_format="dbc")
    comments = {urllib.parse.unquote(s.comment or "") for m in db.messages for s in m.signals}
    assert f"0x6071:00 {one_line(n.parameters[0x6071])}" in comments  # gen/eds.py reads a name as one line
    facts = page_facts(browser, _report_with(pipeline, n, tmp / "study"))
    _check_page(facts, [*n.joints, n.scenario])
