"""Seeing runs (docs/seeing-runs.md), on one demo-sized study made through the CLI (three methods,
one scenario, one seed, a 1 s trajectory; a tuning of two trials, kept beside its config in
tmp_path): its worst run rendered (the arm and its ghost stand apart from each other and from the
background, in the strip the report shows and in the video), that run exported to MCAP and read
back with the mcap library against its LCM log (read by liblcm) and its capture (read as text),
and report.html opened in headless Chromium (no console error, nothing fetched from outside the
page, every figure drawn, the tables holding study.json's numbers)."""

from __future__ import annotations

import gzip
import io
import json
import re
import struct
import subprocess
import tomllib
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from gen.lib.paths import REPO
from headless_browser import Browser, browser_path
from hil_procs import armctl
from study_configs import with_tuning

pytestmark = pytest.mark.long  # a study, its renders, a browser: a minute or two

ARMCTL = str(REPO / "tools" / "armctl")
SCENARIO = "realistic"
METHODS = "pm,tde,usde-smc"


@pytest.fixture(scope="module")
def study(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, dict[str, Any]]:
    tmp = tmp_path_factory.mktemp("seeing")
    cfg = tmp / "small.toml"
    cfg.write_text(with_tuning((REPO / "tools" / "studies" / "paper.toml").read_text(), duration_s=0.2, batch=2))
    assert tomllib.loads(cfg.read_text())["tuning"]["duration_s"] == 0.2
    out = tmp / "study"
    r = armctl("study", "--config", str(cfg), "--scenarios", SCENARIO, "--methods", METHODS, "--seeds", "1",
               "--duration", "1", "--trials", "2", "--confirm", "0", "--out", str(out))
    assert r.returncode == 0, r.stdout[-3000:] + r.stderr[-3000:]
    return out, json.loads((out / "study.json").read_text())


def _worst(out: Path, study: dict[str, Any]) -> Path:
    from tools.study.report import worst_kept_run

    m, seed, _ = worst_kept_run(study, SCENARIO)
    return out / SCENARIO / m / f"seed-{seed}"


def _png(data: bytes) -> np.ndarray:
    from PIL import Image

    return np.asarray(Image.open(io.BytesIO(data)).convert("RGB")).astype(float)


def _apart(a: np.ndarray, b: np.ndarray) -> float:
    return float(np.linalg.norm(a.mean(axis=0) - b.mean(axis=0)))


def test_the_worst_runs_strip_shows_the_arm_beside_its_ghost(study: tuple[Path, dict[str, Any]]) -> None:
    """In each panel of the strip the report shows, the arm's pixels, the ghost's and the floor's
    differ in colour. Where each stands comes from the renderer itself: the same camera drawing
    the arm alone, the ghost alone and neither."""
    from tools.run.render import ArmView, PANEL, load_motion, load_run
    from tools.study.report import fig_name

    out, st = study
    name = fig_name("arm", SCENARIO)
    assert f"![{name}]({name})" in (out / "report.md").read_text()
    strip = _png((out / name).read_bytes())
    rec = json.loads((out / name).with_suffix(".json").read_text())
    run_dir = _worst(out, st)
    assert Path(rec["run"]) == run_dir.resolve() or Path(rec["run"]) == run_dir
    assert sum("worst" in p["moment"] for p in rec["panels"]) == 1 and 2 <= len(rec["panels"]) <= 4
    run, model = load_run(run_dir)
    mo = load_motion(run_dir, run)
    view = ArmView(model, PANEL, np.concatenate([mo.q, mo.q_d]))
    try:
        for p in rec["panels"]:
            i = p["index"]
            floor, _ = view.render(None, None)
            arm = np.any(view.render(mo.q[i], None)[0] != floor, axis=2)
            ghost = np.any(view.render(None, mo.q_d[i])[0] != floor, axis=2)
            x, y, w, h = p["box"]
            panel = strip[y:y + h, x:x + w]
            only_arm, only_ghost, neither = arm & ~ghost, ghost & ~arm, ~arm & ~ghost
            assert only_arm.sum() > 500 and only_ghost.sum() > 500, (p, only_arm.sum(), only_ghost.sum())
            a, g, b = panel[only_arm], panel[only_ghost], panel[neither]
            assert _apart(a, g) > 40 and _apart(a, b) > 40 and _apart(g, b) > 40, (p["moment"], a.mean(0), g.mean(0),
                                                                                  b.mean(0))
    finally:
        view.close()


def test_a_fork_of_a_process_that_has_rendered_still_draws_the_strip(study: tuple[Path, dict[str, Any]],
                                                                     tmp_path: Path) -> None:
    """A study's figures are drawn in forks (tools/study/figures.py). Once a process has rendered,
    Mesa keeps worker threads that a fork lacks, and the fork's first render waited forever: the
    strip is drawn in a fresh interpreter instead, and a fork of this process, which renders
    first here, gets its strip."""
    import multiprocessing

    from tools.run.render import PANEL, ArmView, load_motion, load_run, write_strip_apart

    run_dir = _worst(*study)
    run, model = load_run(run_dir)
    mo = load_motion(run_dir, run)
    view = ArmView(model, PANEL, np.concatenate([mo.q, mo.q_d]))
    view.render(mo.q[0], mo.q_d[0])
    view.close()
    fork = multiprocessing.get_context("fork").Process(target=write_strip_apart, args=(run_dir, tmp_path, "s.png"))
    fork.start()
    fork.join(180)
    hung = fork.is_alive()
    if hung:
        fork.kill()
    assert not hung and fork.exitcode == 0, f"the fork's strip: {'no end in 180 s' if hung else fork.exitcode}"
    assert _png((tmp_path / "s.png").read_bytes()).shape[0] > PANEL[1]


def test_render_writes_the_video_and_strip_of_a_run(study: tuple[Path, dict[str, Any]], tmp_path: Path) -> None:
    import imageio_ffmpeg

    out, st = study
    run_dir = _worst(out, st)
    r = armctl("render", str(run_dir), "--out", str(tmp_path))
    assert r.returncode == 0, r.stdout + r.stderr
    assert f"strip: {tmp_path / 'arm-strip.png'}" in r.stdout and f"video: {tmp_path / 'arm.mp4'}" in r.stdout
    frames = imageio_ffmpeg.read_frames(str(tmp_path / "arm.mp4"))
    meta = next(frames)
    w, h = meta["size"]
    video = [np.frombuffer(f, np.uint8).reshape(h, w, 3) for f in frames]
    run = json.loads((run_dir / "run.json").read_text())["results"]
    assert len(video) >= int((run["duration_s"] + run["ref_hold_s"]) * 20) - 1  # the whole run at 20 frames a second
    assert np.abs(video[0].astype(int) - video[-1].astype(int)).max() > 50  # the arm moved
    bad = armctl("render", str(tmp_path))  # no run.json there
    assert bad.returncode == 2 and bad.stderr.strip() == (f"armctl render: {tmp_path / 'run.json'}: no such file: not "
                                                          "a run folder (armctl hil --out writes one)")


def _capture_lines(path: Path) -> list[tuple[float, str, int, str]]:
    """(time, bus, id, data hex) of every frame of a candump log, read as text."""
    opener = gzip.open if path.suffix == ".gz" else open
    out = []
    with opener(path, "rt") as f:
        for line in f:
            m = re.fullmatch(r"\((\d+\.\d+)\) (\S+) ([0-9A-Fa-f]+)#(#[0-9A-Fa-f])?([0-9A-Fa-f]*)\s*", line)
            assert m, line  # ID#DATA, or CAN FD's ID##FDATA with F its flags
            out.append((float(m.group(1)), m.group(2), int(m.group(3), 16), m.group(5).lower()))
    return out


def test_mcap_export_reads_back_message_for_message(study: tuple[Path, dict[str, Any]], tmp_path: Path) -> None:
    import lcm
    from mcap.reader import make_reader

    from tools.run.telemetry_log import read_log

    out, st = study
    run_dir = _worst(out, st)
    target = tmp_path / "run.mcap"
    r = armctl("export", str(run_dir), "--mcap", "--out", str(target))
    assert r.returncode == 0, r.stdout + r.stderr
    by_topic: dict[str, list[tuple[int, dict[str, Any]]]] = {}
    with open(target, "rb") as f:
        reader = make_reader(f)
        schemas = {ch.topic: (ch.message_encoding, reader.get_summary().schemas[ch.schema_id].encoding)
                   for ch in reader.get_summary().channels.values()}
        for _, channel, message in reader.iter_messages(log_time_order=False):
            by_topic.setdefault(channel.topic, []).append((message.log_time, json.loads(message.data)))
    assert set(schemas.values()) == {("json", "jsonschema")}
    # counts: every LCM event (liblcm's reader) and every captured frame, once
    events: dict[str, int] = {}
    for ev in lcm.EventLog(str(run_dir / "telemetry.lcmlog"), "r"):
        events[ev.channel] = events.get(ev.channel, 0) + 1
    assert {ch: len(by_topic.get(ch, [])) for ch in events} == events
    assert set(events) >= {"ARM_CTL", "ARM_SIM", "ARM_TIMING", "ARM_EVENT", "ARM_SIM_EVENT"}
    env = json.loads((run_dir / "run.json").read_text())["environment"]
    frames = _capture_lines(run_dir / Path(env["capture"]).name)
    can_topics = sorted(t for t in by_topic if t.startswith("can/"))
    assert sum(len(by_topic[t]) for t in can_topics) == len(frames) > 1000
    # timestamps: monotonic on every topic; the controller's at its bus period, on the capture's clock
    for topic, msgs in by_topic.items():
        times = [t for t, _ in msgs]
        assert times == sorted(times), topic
    period_ns = 1e9 / json.loads((run_dir / "run.json").read_text())["results"]["rate_hz"]
    assert all(t == round(m["bus_period"] * period_ns) for t, m in by_topic["ARM_CTL"])
    assert all(t == round(m["step"] * period_ns) for t, m in by_topic["ARM_SIM"])
    # values: the controller's and the simulator's every field, as our own reader decodes the log
    log = read_log(run_dir / "telemetry.lcmlog")
    for ch in ("ARM_CTL", "ARM_SIM", "ARM_TIMING"):
        arr = log[ch].messages
        got = by_topic[ch]
        assert len(got) == len(arr)
        for name in arr.dtype.names:
            want = arr[name]
            have = np.array([m[name] for _, m in got], dtype=want.dtype)
            assert np.array_equal(have, want), (ch, name)
    assert [m["text"] for _, m in by_topic["ARM_EVENT"]] == [e.text for e in log["ARM_EVENT"].messages]
    # the frames in capture order per bus and id, their bytes, and the position each drive reports
    # in rad: the DBC's factor (read here from its text) times the frame's first four bytes
    dbc = Path(env["dbc"]) if Path(env["dbc"]).exists() else run_dir / Path(env["dbc"]).name
    factor = float(re.search(r"SG_ position_actual_value : 0\|32@1- \(([^,]+),0\) \[[^]]*\] \"rad\"",
                             dbc.read_text()).group(1))
    exported = sorted(((t, m["frame"]["bus"], m["frame"]["id"], m["frame"]["data"]) for topic in can_topics
                       for t, m in by_topic[topic]),
                      key=lambda x: (x[1], x[2], x[0]))
    captured = sorted(((round(t * 1e9), bus, i, d) for t, bus, i, d in frames), key=lambda x: (x[1], x[2], x[0]))
    assert exported == captured
    tpdo = [m for topic in can_topics if "/TPDO1_node" in topic for _, m in by_topic[topic]]
    assert len(tpdo) > 100
    for m in tpdo:
        raw = struct.unpack_from("<i", bytes.fromhex(m["frame"]["data"]))[0]
        assert m["signals"]["position_actual_value"] == pytest.approx(raw * factor, rel=1e-12, abs=1e-15)


def test_export_refuses_a_folder_that_is_no_run(tmp_path: Path) -> None:
    r = armctl("export", str(tmp_path), "--mcap")
    assert r.returncode == 2
    assert r.stderr.strip() == (f"armctl export: {tmp_path / 'run.json'}: no such file: not a run folder (armctl hil "
                                "--out writes one)")


@pytest.mark.skipif(browser_path() is None, reason="no headless Chromium (tools/apt-packages-test.txt)")
def _wait(b: Browser, js: str) -> None:
    """Until the page's `js` is true (at most a minute)."""
    for _ in range(600):
        if b.evaluate(js):
            return
        b.call("Runtime.evaluate", {"expression": "new Promise(r => setTimeout(r, 100))", "awaitPromise": True},
               session=True)
    assert b.evaluate(js), js


def test_report_html_answers_on_its_first_screen(study: tuple[Path, dict[str, Any]]) -> None:
    """On a laptop's screen (1280 x 800), report.html opens with the answer: every scenario's pick
    whole within the first screen, the table of means and the answer's figure starting on it; every
    later section (how the study was run, each scenario's detail) folded, its figures not drawn
    until it is opened."""
    from tools.study.answer import ranking

    out, st = study
    b = Browser(width=1280, height=800)
    try:
        b.open(out / "report.html")
        _wait(b, "document.body.dataset.figures === 'drawn'")
        height = b.evaluate("window.innerHeight")
        assert height == 800 and b.evaluate("window.scrollY") == 0
        picks = b.evaluate("""Array.from(document.querySelectorAll('h2')[0].parentElement.querySelectorAll('li'))
            .filter(li => !li.closest('details')).map(li => ({text: li.textContent,
            bottom: li.getBoundingClientRect().bottom}))""")
        assert len(picks) == len(st["scenarios"]), picks
        for (name, pick) in zip(st["scenarios"], picks):
            best = ranking(st, name)[0][0]
            assert pick["text"].startswith(f"{name}: use {best}"), (name, best, pick["text"])
            assert pick["bottom"] <= height, f"{name}'s answer ends below the first screen: {pick}"
        tops = b.evaluate("""(() => { const g = document.querySelector('.glance');
            return [g.querySelector('pre'), g.querySelector('.figure')].map(e => e ? e.getBoundingClientRect().top : null);
            })()""")
        assert all(t is not None and t < height for t in tops), tops
        sections = b.evaluate("""Array.from(document.querySelectorAll('h2')).map(h => ({text: h.textContent,
            folded: !!h.closest('details'), open: !!h.closest('details[open]')}))""")
        assert sections[0] == {"text": "The answer", "folded": False, "open": False}, sections
        assert len(sections) >= 3 and all(s["folded"] and not s["open"] for s in sections[1:]), sections
        assert b.evaluate("document.querySelectorAll('details div.figure[data-drawn]').length") == 0
        assert b.console_errors() == []
    finally:
        b.close()


def test_report_html_in_a_headless_browser(study: tuple[Path, dict[str, Any]]) -> None:
    """report.html offline in Chromium: it loads with no console error and fetches nothing but
    itself; every folded section opened, every figure is drawn (its screenshot is not blank: many
    colours, many non-white pixels); its tables hold study.json's numbers as report.md writes them."""
    from tools.study.report import METRIC_TEXT, _ci, _labels, in_degrees

    out, st = study
    page = out / "report.html"
    text = page.read_text()
    # no script, style or image from elsewhere (plotly.js names its web site in strings of its own)
    assert not re.search(r"""<(script|link|img|iframe)\b[^>]*\b(src|href)=["']?(https?:)?//""", text)
    shown = len(re.findall(r"!\[[^]]*\]\([^)]*\.png\)", (out / "report.md").read_text()))
    b = Browser(width=1300, height=1500)
    try:
        b.open(page)
        _wait(b, "document.body.dataset.figures === 'drawn'")
        b.evaluate("document.querySelectorAll('details').forEach(d => { d.open = true; })")
        _wait(b, "document.querySelectorAll('div.figure[data-figure]').length === "
                 "document.querySelectorAll('div.figure[data-drawn=\"yes\"]').length")
        assert b.console_errors() == []
        urls = b.requested_urls()
        assert urls and all(u.startswith(("file:", "data:")) for u in urls), urls
        count = b.evaluate("document.querySelectorAll('.figure').length")
        assert count == shown >= 7, (count, shown)
        for k in range(count):
            png, box = b.screenshot_of(".figure", k)
            img = _png(png)
            assert box["height"] > 200 and img.shape[0] > 200, (k, box)
            colours = len(np.unique(img.reshape(-1, 3).astype(np.uint8), axis=0))
            inked = float((img.min(axis=2) < 200).mean())
            assert colours > 20 and inked > 0.01, (k, box, colours, inked)
        tables = b.evaluate("""Array.from(document.querySelectorAll('table')).map(t => {
            let h3 = t.previousElementSibling; while (h3 && !/^H[23]$/.test(h3.tagName)) h3 = h3.previousElementSibling;
            return {heading: h3 ? h3.textContent : '', rows: Array.from(t.rows).map(r => Array.from(r.cells).map(
                c => c.textContent.trim()))}; })""")
    finally:
        b.close()
    sc = st["scenarios"][SCENARIO]
    labels = _labels(st, st["arm"]["is_default"] and st["arm"]["n_joints"] == 6)
    checked = 0
    for metric in ("linf", "rms", "est"):
        table = next(t for t in tables if t["heading"].startswith(METRIC_TEXT[metric]))
        header, rows = table["rows"][0], table["rows"][1:]
        for col, m in enumerate(header[1:], start=1):
            for j, row in enumerate(rows[:len(labels)]):
                assert row[0] == labels[j]
                assert row[col] == _ci(in_degrees(sc["stats"][m][metric]["per_joint"][j], metric)), (metric, m, j)
                checked += 1
    power = next(t for t in tables if t["heading"].startswith(METRIC_TEXT["power"]))
    for row in power["rows"][1:]:
        assert row[1] == _ci(sc["stats"][row[0]]["power"]["total"])
        checked += 1
    assert checked >= 3 * 6 * 2 + 3
