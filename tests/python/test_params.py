"""The parameter registry (firmware/params/params.toml) is the one definition: the option tables
of docs/reference/parameters.md agree with it, both C programs' --help list exactly its options with its defaults, their
parser refuses a value just outside each registry range and takes the bounds themselves, and the
Python side (armctl hil, the drive model, the verdict) takes its numbers from it."""

from __future__ import annotations

import re
import subprocess
from pathlib import Path

import pytest

from gen.lib.params import Param, check_table, constant, markdown_table, param, params, readme_markers
from gen.lib.paths import DOCS, PARAMETERS_PAGE
from gen.params import main as gen_main, readme_with_tables

REPO = Path(__file__).resolve().parents[2]
PAGE = PARAMETERS_PAGE


def _readme_rows(program: str) -> dict[str, list[str]]:
    """The page's table of a program: option (without its argument) -> [default, range, unit]."""
    start, end = readme_markers(program)
    text = PAGE.read_text()
    block = text[text.index(start) + len(start):text.index(end)]
    rows: dict[str, list[str]] = {}
    for line in block.strip().splitlines()[2:]:
        cells = [c.strip() for c in re.split(r"(?<!\\)\|", line)[1:-1]]
        rows[cells[0].strip("`").split(" ")[0]] = cells[1:4]
    return rows


@pytest.mark.parametrize("program", ["controller", "simulator", "hil"])
def test_the_readme_tables_give_the_registrys_defaults_ranges_and_units(program: str) -> None:
    rows = _readme_rows(program)
    want = {p.option: p for p in params(program).values() if not p.hidden}
    assert set(rows) == set(want)
    for opt, (default, rng, unit) in rows.items():
        p = want[opt]
        assert default == (p.default_text().replace("{model}", "the built arm") or "-"), opt
        assert rng == (p.range_text() or "-"), opt
        assert unit == (p.unit or "-"), opt


def test_a_table_that_differs_is_caught(tmp_path: Path) -> None:
    text = PAGE.read_text()
    assert readme_with_tables(text, PAGE.name) == text
    row = "| `--duration S` | 5 | [0.001, 86400] | s |"
    stale = text.replace(row, row.replace("| 5 |", "| 10 |"), 1)
    assert stale != text
    (tmp_path / "parameters.md").write_text(stale)
    assert gen_main(["--check", str(tmp_path / "parameters.md")]) == 1
    assert gen_main(["--readme", str(tmp_path / "parameters.md")]) == 0
    assert (tmp_path / "parameters.md").read_text() == text
    assert gen_main(["--check"]) == 0  # without a file: the parameters page itself


def _help(exe: Path) -> str:
    r = subprocess.run([str(exe), "--help"], capture_output=True, text=True, timeout=60)
    assert r.returncode == 0, r.stderr
    return r.stdout


def _programs(controller_bin: Path, sim_exe: Path) -> dict[str, Path]:
    return {"controller": controller_bin, "simulator": sim_exe}


@pytest.mark.parametrize("program", ["controller", "simulator"])
def test_help_lists_exactly_the_registrys_options_with_its_defaults(program: str, controller_bin: Path,
                                                                   sim_exe: Path) -> None:
    text = _help(_programs(controller_bin, sim_exe)[program])
    listed = re.findall(r"^  (--[a-z0-9-]+)", text, flags=re.M)
    assert listed == [p.option for p in params(program).values() if not p.hidden]
    for p in params(program).values():
        if p.hidden or p.type not in ("float", "int") or not isinstance(p.default, (int, float)):
            continue
        entry = text.split(f"  {p.option} ", 1)[1].split("\n  --", 1)[0]
        assert f"[{p.default_text()}" in entry, (p.option, entry)


def _numeric(program: str) -> list[Param]:
    return [p for p in params(program).values()
            if p.type in ("float", "int") and p.min is not None and p.max is not None]


@pytest.mark.parametrize("program", ["controller", "simulator"])
def test_the_parser_takes_each_ranges_bounds_and_refuses_beyond(program: str, controller_bin: Path,
                                                                sim_exe: Path) -> None:
    exe = _programs(controller_bin, sim_exe)[program]
    assert _numeric(program)
    for p in _numeric(program):
        over = p.max + max(1.0, abs(p.max))
        r = subprocess.run([str(exe), p.option, repr(over)], capture_output=True, text=True, timeout=60)
        assert r.returncode == 2, (p.option, r.stderr)
        assert r.stderr.count("\n") == 1 and f"{p.option}: '{over!r}' is not a number in {p.range_text()}" in r.stderr
        lo = p.min if not p.min_open else (p.min + p.max) / 2
        if p.type == "int":
            lo = float(int(lo))
        for v in (lo, p.max):
            # --help after it: parsed, then nothing run (arm_sim's --bench-mj-step would otherwise time MuJoCo)
            r = subprocess.run([str(exe), p.option, repr(v), "--help"], capture_output=True, text=True, timeout=60)
            assert r.returncode == 0, (p.option, v, r.stderr)


def test_python_takes_the_registrys_numbers() -> None:
    from host_sim.drive_model import DriveModel
    from host_sim.uncertainty import UncertaintyConfig
    from tools.run.hil import CONTROLLER_DEFAULT_HOLD_S, HilOptions
    from tools.run.run_analysis import STATE_NAMES
    from tools.run.verdict import EXIT, FOLLOWING_ERROR_STOP_DEG, Bounds

    assert CONTROLLER_DEFAULT_HOLD_S == param("controller", "ref-hold").default
    assert HilOptions(out=Path("x")).duration_s == param("controller", "duration").default
    assert Bounds().max_saturated_fraction == param("hil", "max-saturated-fraction").default
    assert FOLLOWING_ERROR_STOP_DEG == pytest.approx(28.6479, abs=1e-4)
    assert STATE_NAMES[1] == "running" and list(STATE_NAMES.values()) == constant("controller-states")
    assert EXIT["interrupted"] == 5
    assert DriveModel().ripple_periods == param("simulator", "ripple-periods").default
    assert UncertaintyConfig().paper_knot_s == param("simulator", "paper-knot-s").default
    hi = param("simulator", "ripple").max
    with pytest.raises(ValueError, match=r"drives.ripple: must be a number in \[0, 1\]"):
        DriveModel.from_dict({"ripple": hi * 2})
    with pytest.raises(ValueError, match=r"uncertainty.viscous\[1\]: must be a number in \[0, 1e\+06\]"):
        UncertaintyConfig.from_dict({"viscous": [1.0, -1.0]})
    with pytest.raises(ValueError, match="unknown field"):
        check_table({"nope": 1}, {"a"}, "t")


def test_every_table_has_a_row_per_option() -> None:
    for program in ("controller", "simulator", "hil"):
        table = markdown_table(program)
        assert table.count("\n") == 2 + sum(not p.hidden for p in params(program).values())


# A default the prose mentions: "`--opt`, default 20 s", "(`--opt`, 0.5 s)", "`--opt` of the time (default 0.05".
_PROSE = re.compile(r"`(--[a-z0-9-]+)`\)?(?:,? \(?|[^`.;\n]{0,20}\(default )(?:default )?(-?\d[\d.]*)(?![\d.])")


def prose_defaults(text: str) -> list[tuple[int, str, float]]:
    return [(text.count("\n", 0, m.start()) + 1, m.group(1), float(m.group(2))) for m in _PROSE.finditer(text)]


def test_the_defaults_the_readmes_prose_names_are_the_registrys() -> None:
    defaults: dict[str, set[float]] = {}
    for program in ("controller", "simulator", "hil"):
        for p in params(program).values():
            if isinstance(p.default, (int, float)) and not isinstance(p.default, bool):
                defaults.setdefault(p.option, set()).add(float(p.default))
    pages = [REPO / "README.md", REPO / "host_sim" / "README.md", *sorted(DOCS.rglob("*.md"))]
    found = [(str(f.relative_to(REPO)), *m) for f in pages for m in prose_defaults(f.read_text())]
    assert len(found) >= 6  # the hold, the timeouts, the watchdog, the bounds
    for name, line, opt, value in found:
        if opt in defaults:
            assert value in defaults[opt], f"{name}:{line}: {opt} {value:g}, the registry says {sorted(defaults[opt])}"
    # and the check bites: a stale mention is found
    assert prose_defaults("hold (`--ref-hold`, 0.7 s) first") == [(1, "--ref-hold", 0.7)]


def test_a_number_a_help_text_quotes_is_the_constants(tmp_path: Path) -> None:
    """{const:NAME} in a help or default text is the constant's value (the C usage text, the docs
    and armctl read the same), so the number is never typed twice; an unknown name is refused."""
    from gen.lib.params import PROGRAMS, RegistryError, _load

    for program in PROGRAMS:
        for p in params(program).values():
            assert "{const:" not in p.help and "{const:" not in str(p.default), (program, p.name)
    assert f"RATE {constant('safe-stop-hold-rate'):g} 1/s" in param("controller", "safe-stop").help
    assert param("controller", "rt-priority").default.startswith(f"realtime: {constant('rt-priority')} ")
    bad = tmp_path / "params.toml"
    bad.write_text('[controller.x]\ntype = "float"\ndefault = 1.0\nhelp = "at most {const:nowhere}"\n')
    with pytest.raises(RegistryError, match=r"\{const:nowhere\}: no \[constant.nowhere\]"):
        _load(bad)
