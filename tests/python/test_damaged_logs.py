"""A damaged telemetry log or capture is named, never passed off as whole (issue 51): a log with
bytes flipped in its middle and a log cut inside an event. The run's analysis says where it breaks
(byte offset, the event number before it) and how much was left unread, and makes the run
`incomplete`, never `ok`; `armctl export --mcap` exports what reads, says the same and exits 1;
`armctl render` draws what reads, says the same and exits 1. A capture with a line that is no frame
and a gzip stream cut short is named by line."""

from __future__ import annotations

import gzip
import json
import re
import shutil
import subprocess
from pathlib import Path
from typing import Any

import pytest

from gen.lib.paths import REPO
from tools.run.hil import HilOptions, run_hil
from tools.run.run_analysis import analyse
from tools.run.telemetry_log import HEADER, SYNC, log_damage

ARMCTL = str(REPO / "tools" / "armctl")
CONFIG_KEYS = ("method", "mode", "duration_s", "joint_names", "ref_hold_s", "rate_hz")


@pytest.fixture(scope="module")
def sil_run(tmp_path_factory: pytest.TempPathFactory, controller_bin: Path) -> Path:
    out = tmp_path_factory.mktemp("sil")
    run = run_hil(HilOptions(out=out, duration_s=1.0, method="pm", preset=controller_bin.parent.parent.name, bus="sil",
                             capture=True, compress_capture=True))
    assert run["results"]["result"] == "ok"
    assert not run["transport"]["telemetry_log"]["damaged"], run["transport"]["telemetry_log"]
    return out


def _copy(src: Path, dst: Path) -> Path:
    """The run folder elsewhere, its run.json pointing at the copy's capture and DBC."""
    shutil.copytree(src, dst)
    run = json.loads((dst / "run.json").read_text())
    for k in ("capture", "dbc"):
        if run["environment"].get(k):
            run["environment"][k] = str(dst / Path(run["environment"][k]).name)
    (dst / "run.json").write_text(json.dumps(run))
    return dst


def _reanalyse(out: Path) -> dict[str, Any]:
    run = json.loads((out / "run.json").read_text())
    ctl = json.loads((out / "controller_summary.json").read_text()) if (out / "controller_summary.json").exists() else {}
    sim = json.loads((out / "sim_summary.json").read_text()) if (out / "sim_summary.json").exists() else {}
    return analyse(out, ctl, sim, {k: run["results"][k] for k in CONFIG_KEYS}, run["environment"])


def _events(data: bytes) -> list[int]:
    """The offset of every event of a whole log (its sync words on the event chain)."""
    out, at = [], 0
    while at < len(data):
        assert data[at:at + 4] == SYNC
        out.append(at)
        at += HEADER + int.from_bytes(data[at + 20:at + 24], "big") + int.from_bytes(data[at + 24:at + 28], "big")
    return out


def _flipped(data: bytes, at: int, n: int = 200) -> bytes:
    b = bytearray(data)
    for i in range(at, at + n):
        b[i] ^= 0xFF
    return bytes(b)


def _armctl(*args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run([ARMCTL, *args], cwd=REPO, capture_output=True, text=True, timeout=600)


def _damage_line(r: subprocess.CompletedProcess[str]) -> str:
    assert r.returncode == 1 and "Traceback" not in r.stderr, (r.returncode, r.stdout[-2000:], r.stderr[-2000:])
    lines = [ln for ln in r.stderr.splitlines() if ln.startswith("armctl ")]
    assert len(lines) == 1, r.stderr
    return lines[0]


def test_a_log_with_flipped_bytes_is_named_where_it_breaks_and_the_run_is_incomplete(sil_run: Path,
                                                                                   tmp_path: Path) -> None:
    out = _copy(sil_run, tmp_path / "flipped")
    log = out / "telemetry.lcmlog"
    whole = log.read_bytes()
    events = _events(whole)
    k = len(events) // 2
    log.write_bytes(_flipped(whole, events[k] + 4))  # from event k's number on: its header and what follows
    d = log_damage(log)
    assert d.damaged and d.stop is not None and d.stop["offset"] == events[k] and d.stop["after_event"] == k - 1
    assert d.unread == len(whole) - events[k] and d.events == k
    run = _reanalyse(out)
    r, t = run["results"], run["transport"]
    assert r["result"] == "incomplete", r["verdict_reasons"]
    why = next(w for w in r["verdict_reasons"] if "telemetry log is damaged" in w)
    assert f"byte {events[k]} (after event {k - 1})" in why and f"{len(whole) - events[k]} of its {len(whole)} bytes" in why
    assert t["telemetry_log"]["unread_bytes"] == len(whole) - events[k]

    r = _armctl("export", str(out), "--mcap", "--out", str(tmp_path / "f.mcap"))
    line = _damage_line(r)
    assert f"byte {events[k]} (after event {k - 1})" in line and f"the export holds {k} of them" in line, line
    assert (tmp_path / "f.mcap").stat().st_size > 0  # what reads, exported


def test_flipped_bytes_inside_an_event_are_skipped_to_the_next_event_and_counted(sil_run: Path, tmp_path: Path) -> None:
    out = _copy(sil_run, tmp_path / "inside")
    log = out / "telemetry.lcmlog"
    whole = log.read_bytes()
    events = _events(whole)
    k = len(events) // 3
    log.write_bytes(_flipped(whole, events[k] + HEADER + 20, events[k + 3] - events[k] - HEADER - 20))
    d = log_damage(log)  # events k+1 and k+2 lost their sync words: read from k+3 on
    assert d.stop is None and d.missing_events == 2 and d.first_missing == {"offset": events[k + 3], "event": k + 1}
    assert d.skipped[0]["after_event"] == k and d.events == len(events) - 2
    run = _reanalyse(out)
    assert run["results"]["result"] == "incomplete"
    assert any("2 event(s) missing between those read, the first event" in w for w in run["results"]["verdict_reasons"])
    r = _armctl("export", str(out), "--mcap", "--out", str(tmp_path / "i.mcap"))  # on past the bytes, as the analysis
    held = int(re.search(r"the export holds (\d+) of them", _damage_line(r)).group(1))
    assert held >= len(events) - 3, (held, len(events))  # liblcm also refuses event k, not followed by an event


def test_a_truncated_log_says_what_was_cut_and_render_and_export_say_so(sil_run: Path, tmp_path: Path) -> None:
    out = _copy(sil_run, tmp_path / "cut")
    log = out / "telemetry.lcmlog"
    whole = log.read_bytes()
    events = _events(whole)
    k = 2 * len(events) // 3
    cut = events[k] + 40  # inside event k
    log.write_bytes(whole[:cut])
    d = log_damage(log)
    assert d.stop is not None and d.stop["offset"] == events[k] and d.stop["after_event"] == k - 1
    assert "cut short" in d.stop["why"] and d.unread == cut - events[k] and d.events == k
    run = _reanalyse(out)
    assert run["results"]["result"] == "incomplete"
    assert any(f"it breaks at byte {events[k]} (after event {k - 1})" in w for w in run["results"]["verdict_reasons"])
    r = _armctl("render", str(out), "--no-video", "--out", str(tmp_path))
    line = _damage_line(r)
    assert f"it breaks at byte {events[k]} (after event {k - 1})" in line and "the strip shows the periods read" in line
    assert json.loads((tmp_path / "arm-strip.json").read_text())["log_damage"]
    r = _armctl("export", str(out), "--mcap", "--out", str(tmp_path / "c.mcap"))
    assert f"it breaks at byte {events[k]}" in _damage_line(r)


def test_a_damaged_capture_is_named_by_line(sil_run: Path, tmp_path: Path) -> None:
    out = _copy(sil_run, tmp_path / "capture")
    cap = out / "bus.log.gz"
    lines = gzip.decompress(cap.read_bytes()).split(b"\n")
    lines[99] = b"(0.1) can0 no frame here"
    packed = gzip.compress(b"\n".join(lines))
    cap.write_bytes(packed[:len(packed) * 3 // 4])  # and the gzip stream cut short
    r = _armctl("export", str(out), "--mcap", "--out", str(tmp_path / "c.mcap"))
    line = _damage_line(r)
    assert "bus.log.gz: 1 line(s) that are no frame skipped, the first line 100" in line, line
    assert "it breaks after line" in line and "EOFError" in line, line


def test_a_whole_log_is_whole(sil_run: Path) -> None:
    d = log_damage(sil_run / "telemetry.lcmlog")
    assert not d.damaged and d.events == len(_events((sil_run / "telemetry.lcmlog").read_bytes()))
    assert d.describe() == f"whole: {d.events} events read"
