"""The run analysis streams the telemetry log (tools/run/telemetry_log.py iter_chunks,
tools/run/run_analysis.py scan_log): the same run.json results, bit for bit, as decoding the whole log
with lcm-gen's classes (the way it was done before, kept here only as the reference); forged
telemetry is named, never `ok`; memory does not grow with the run's duration."""

from __future__ import annotations

import json
import shutil
import subprocess
import sys
import threading
import time
from pathlib import Path
from typing import Any

import lcm
import numpy as np
import pytest

from gen import lcmtypes
from tools.run.hil import HilOptions, run_hil
from tools.run.run_analysis import PairwiseSum, RowSum, analyse, control_metrics, scan_log
from tools.study import DEFAULT_CONFIG
from tools.study.config import load
from tools.run.telemetry_log import CHANNEL_TYPES, read_log

REPO = Path(__file__).resolve().parents[2]
CFG = load(DEFAULT_CONFIG)
CONFIG_KEYS = ("method", "mode", "duration_s", "joint_names", "ref_hold_s", "rate_hz")


# ---- the reference: the whole log decoded by lcm-gen, the metrics as computed before streaming ----

def _old_read_log(path: Path) -> dict[str, list[Any]]:
    types = lcmtypes.load()
    out: dict[str, list[Any]] = {ch: [] for ch in CHANNEL_TYPES}
    log = lcm.EventLog(str(path), "r")
    try:
        while True:
            try:
                ev = log.read_next_event()
            except (ValueError, OSError):
                break
            if ev is None:
                break
            if ev.channel in CHANNEL_TYPES:
                try:
                    out[ev.channel].append(getattr(types, CHANNEL_TYPES[ev.channel]).decode(ev.data))
                except Exception:  # noqa: BLE001, S112 - as the old reader: count, drop
                    continue
    finally:
        log.close()
    return out


def _rms(x: np.ndarray) -> list[float]:
    return np.sqrt((x**2).mean(axis=0)).tolist() if len(x) else []


def _old_control_metrics(ctl: list[Any], sim: list[Any], hold_s: float, rate_hz: float) -> dict[str, Any]:
    running = [m for m in ctl if m.state == 1 and m.t >= hold_s - 0.5 / rate_hz]
    if not running:
        return {"periods_running": 0}
    e = np.array([m.e for m in running], dtype=float)
    tau = np.array([m.tau for m in running], dtype=float)
    qd = np.array([m.qd for m in running], dtype=float)
    w_hat = {m.bus_period: np.array(m.w_hat, dtype=float) for m in running}
    w_true = {m.step: np.array(m.w_true, dtype=float) for m in sim}
    paired = [(w_true[p], w_hat[p]) for p in sorted(w_hat) if p in w_true]
    out: dict[str, Any] = {
        "periods_running": len(running),
        "tracking_max_abs_rad": np.abs(e).max(axis=0).tolist(),
        "tracking_rms_rad": _rms(e),
        "tracking_max_abs_deg": np.degrees(np.abs(e).max(axis=0)).tolist(),
        "tracking_rms_deg": np.degrees(np.sqrt((e**2).mean(axis=0))).tolist(),
        "max_abs_torque_nm": np.abs(tau).max(axis=0).tolist(),
        "torque_power_w": float(np.abs(tau * qd).sum(axis=1).mean()),
        "mean_sum_tau_squared_nm2": float((tau**2).sum(axis=1).mean()),
        "saturated_fraction": [float(np.mean([(m.saturated_mask >> j) & 1 for m in running]))
                               for j in range(e.shape[1])],
    }
    if paired:
        wt = np.array([p[0] for p in paired])
        wh = np.array([p[1] for p in paired])
        out["w_rms"] = _rms(wt)
        out["estimation_error_rms"] = _rms(wt - wh)
        out["estimation_periods"] = len(paired)
    return out


def _old_accounting(log: dict[str, list[Any]], sent: dict[str, int]) -> dict[str, Any]:
    out = {}
    for ch, n in sent.items():
        seqs = {m.seq for m in log[ch]}
        out[ch] = {"sent": n, "logged": len(log[ch]), "lost": n - len(log[ch]),
                   "sequence_gaps": (max(seqs) + 1 - len(seqs)) if seqs else 0}
    return out


def _summaries(out: Path) -> tuple[dict[str, Any], dict[str, Any], dict[str, Any]]:
    run = json.loads((out / "run.json").read_text())
    return (run, json.loads((out / "controller_summary.json").read_text()),
            json.loads((out / "sim_summary.json").read_text()))


def _reanalyse(out: Path) -> dict[str, Any]:
    run, ctl, sim = _summaries(out)
    return analyse(out, ctl, sim, {k: run["results"][k] for k in CONFIG_KEYS}, run["environment"])


def _same(a: Any, b: Any) -> bool:
    """Equal bit for bit: the JSON run.json would hold, and float for float."""
    return json.dumps(a, sort_keys=True) == json.dumps(b, sort_keys=True) and a == b


# ---- bit for bit ----

@pytest.mark.parametrize("bus", ["sil", "udp"])
@pytest.mark.parametrize("scenario", list(CFG.scenarios))
def test_streamed_analysis_equals_the_whole_log_decoded(tmp_path: Path, controller_bin: Path, scenario: str,
                                                        bus: str) -> None:
    sc = CFG.scenarios[scenario]
    out = tmp_path / "run"
    # pm untuned (the study's tuning is synthesised and built per scenario): a short hold, as in test_sil.py
    run = run_hil(HilOptions(out=out, duration_s=1.0, method="pm", preset=controller_bin.parent.parent.name, bus=bus,
                             controller_args=("--ref-hold", "0.1"), uncertainty={**sc.uncertainty, "seed": 7},
                             drives=sc.drives, bus_timing=sc.bus_timing))
    r, ctl_summary, sim_summary = _summaries(out)
    old = _old_read_log(out / "telemetry.lcmlog")
    hold, rate = r["results"]["ref_hold_s"], r["results"]["rate_hz"]
    want = _old_control_metrics(old["ARM_CTL"], old["ARM_SIM"], hold, rate)
    assert want["periods_running"] > 100 and want["estimation_periods"] == want["periods_running"]
    got = {k: r["results"][k] for k in want}
    assert _same(got, want), {k: (got[k], want[k]) for k in want if got[k] != want[k]}
    assert r["results"]["final_state"] == run["results"]["final_state"]
    assert set(r["results"]) - set(want) == set(run["results"]) - set(want)
    sent = {**ctl_summary["telemetry"]["sent"], **sim_summary["telemetry_sent"]}
    acct = {ch: {k: a[k] for k in ("sent", "logged", "lost", "sequence_gaps")}
            for ch, a in r["transport"]["telemetry"].items()}
    assert acct == _old_accounting(old, sent)
    assert r["transport"]["telemetry_foreign"] == []
    # any chunk size, and the second pass the pairwise means take when the count was not the expected one
    n = want["periods_running"]
    for chunk in (1 << 12, 100_003):
        scan = scan_log(out / "telemetry.lcmlog", hold, rate, sent, n, chunk_bytes=chunk)
        assert _same(control_metrics(scan), want), chunk
    scan = scan_log(out / "telemetry.lcmlog", hold, rate, sent, n - 1)
    assert _same(control_metrics(scan), want)
    # the reader's messages are lcm-gen's, field for field
    new = read_log(out / "telemetry.lcmlog")
    for ch in ("ARM_CTL", "ARM_SIM", "ARM_TIMING"):
        arr = new[ch].messages
        assert len(arr) == len(old[ch])
        for f in arr.dtype.names:
            assert np.array_equal(arr[f], np.array([getattr(m, f) for m in old[ch]])), (ch, f)
    for ch in ("ARM_EVENT", "ARM_SIM_EVENT"):
        assert [(m.seq, m.step, m.text) for m in new[ch].messages] == [(m.seq, m.step, m.text) for m in old[ch]]


@pytest.mark.parametrize("n", [0, 1, 7, 8, 9, 127, 128, 129, 136, 1000, 1001, 4097, 10000, 100_003])
def test_pairwise_sum_fed_in_pieces_is_numpys_sum(n: int) -> None:
    rng = np.random.default_rng(n)
    x = rng.random(n) * rng.choice([1.0, 1e8, 1e-8], n)
    for pieces in (1, 3, 17):
        s = PairwiseSum(n)
        for part in np.array_split(x, pieces):
            s.feed(part)
        assert s.result() == np.add.reduce(x)
    short = PairwiseSum(n + 1)
    short.feed(x)
    assert short.result() is None
    rows = rng.random((n, 6)) * 1e3
    r = RowSum()
    for part in np.array_split(rows, 5):
        r.feed(part)
    assert n == 0 or np.array_equal(r.total, rows.sum(axis=0))


def test_reader_counts_wrong_fingerprint_and_size_and_reads_a_torn_log(tmp_path: Path, sil_run: Path) -> None:
    types = lcmtypes.load()
    src = read_log(sil_run / "telemetry.lcmlog")
    path = tmp_path / "t.lcmlog"
    log = lcm.EventLog(str(path), "w", overwrite=True)
    good = types.sim_truth_t()
    m = src["ARM_SIM"].messages[5]
    good.seq, good.step, good.t, good.n = int(m.seq), int(m.step), float(m.t), int(m.n)
    good.q, good.qd, good.tau_applied, good.w_true = (list(map(float, getattr(m, f))) for f in ("q", "qd", "tau_applied", "w_true"))
    data = good.encode()
    log.write_event(0, "ARM_SIM", data)
    log.write_event(1, "ARM_SIM", b"\x00" * 8 + data[8:])   # wrong fingerprint
    log.write_event(2, "ARM_SIM", data + b"\x00")           # wrong size
    log.write_event(3, "ARM_CTL", data)                     # another type's message
    log.write_event(4, "ARM_SIM", data)
    log.close()
    out = read_log(path)
    assert len(out["ARM_SIM"].messages) == 2 and out["ARM_SIM"].undecodable == 2
    assert out["ARM_CTL"].undecodable == 1
    assert np.array_equal(out["ARM_SIM"].messages[0].w_true, m.w_true)
    whole = path.read_bytes()
    for cut in (1, 10, 40, len(data)):  # a killed writer: the log ends inside its last event
        path.write_bytes(whole[:-cut])
        assert len(read_log(path)["ARM_SIM"].messages) == 1
    path.write_bytes(b"junk" + whole[:len(whole) // 2] + b"\xed\xa1" + whole)  # bytes that are no event are skipped
    assert len(read_log(path)["ARM_SIM"].messages) >= 2


# ---- forged telemetry ----

@pytest.fixture(scope="module")
def sil_run(tmp_path_factory: pytest.TempPathFactory, controller_bin: Path) -> Path:
    out = tmp_path_factory.mktemp("sil")
    run = run_hil(HilOptions(out=out, duration_s=1.0, method="pm", preset=controller_bin.parent.parent.name, bus="sil"))
    assert run["results"]["result"] == "ok"
    return out


def _forged_sim(src: np.recarray, seq: int, step: int, w_true: Any) -> bytes:
    m = lcmtypes.load().sim_truth_t()
    m.seq, m.step, m.t, m.n = seq, step, step * 1e-3, int(src.n)
    m.q, m.qd, m.tau_applied = (list(map(float, getattr(src, f))) for f in ("q", "qd", "tau_applied"))
    m.w_true = list(map(float, w_true))
    return m.encode()


@pytest.mark.parametrize("forgery", ["republished", "beyond-sent", "contradicting-step"])
def test_forged_sim_truth_appended_to_a_run_makes_it_incomplete(tmp_path: Path, sil_run: Path, forgery: str) -> None:
    out = tmp_path / "run"
    shutil.copytree(sil_run, out)
    log = read_log(out / "telemetry.lcmlog")
    sims, ctl = log["ARM_SIM"].messages, log["ARM_CTL"].messages
    sent = len(sims)
    w_hat = {int(m.bus_period): m.w_hat for m in ctl}
    forged_log = tmp_path / "forged.lcmlog"
    ev = lcm.EventLog(str(forged_log), "w", overwrite=True)
    forged = 0
    for m in sims[-300:]:  # the attack of issue 24: w_true set to the controller's w_hat
        step = int(m.step)
        seq = {"republished": step, "beyond-sent": sent + forged, "contradicting-step": step}[forgery]
        fstep = {"republished": step, "beyond-sent": sent + forged, "contradicting-step": step + 1}[forgery]
        ev.write_event(0, "ARM_SIM", _forged_sim(m, seq, fstep, w_hat.get(step, m.w_true)))
        forged += 1
    ev.close()
    with open(out / "telemetry.lcmlog", "ab") as f:  # appended to the run's log, as if the logger had heard it
        f.write(forged_log.read_bytes())
    run = _reanalyse(out)
    r, t = run["results"], run["transport"]
    assert r["result"] == "incomplete", r["verdict_reasons"]
    assert any(w.startswith("incomplete: foreign telemetry: ARM_SIM: ") for w in r["verdict_reasons"]), r
    acct = t["telemetry"]["ARM_SIM"]
    assert acct["lost"] == 0 and acct["logged"] == sent + forged and acct["logged_beyond_sent"] == forged
    key = {"republished": "duplicates", "beyond-sent": "beyond_sent", "contradicting-step": "contradicting_step"}
    assert acct[key[forgery]] == forged and acct["foreign"] == forged
    assert t["telemetry_lost_total"] == 0  # never negative: nothing the senders sent is missing


def test_telemetry_published_by_a_foreign_process_during_a_lockstep_run(tmp_path: Path, controller_bin: Path) -> None:
    """Another process on the run's telemetry port republishes ARM_SIM while the run goes."""
    from tools.run.slots import acquire_slot

    with acquire_slot() as slot:
        url = f"udpm://239.255.76.67:{slot.lcm_port}?ttl=0"
        out = tmp_path / "run"
        stop = threading.Event()
        published = [0]

        def forge() -> None:
            lc = lcm.LCM(url)
            sub_log = out / "telemetry.lcmlog"
            while not stop.is_set() and not sub_log.exists():  # the logger listens
                time.sleep(0.001)
            m = lcmtypes.load().sim_truth_t()
            m.n = 6
            m.q = m.qd = m.tau_applied = m.w_true = [0.0] * 6
            while not stop.is_set() and published[0] < 400:
                m.seq = m.step = published[0]  # sequence numbers the simulator sends too
                lc.publish("ARM_SIM", m.encode())
                published[0] += 1
                time.sleep(0.0005)

        th = threading.Thread(target=forge, daemon=True)
        th.start()
        try:
            run = run_hil(HilOptions(out=out, duration_s=3.0, method="pm", preset=controller_bin.parent.parent.name,
                                     bus="udp", can_port=slot.can_port, lcm_port=slot.lcm_port))
        finally:
            stop.set()
            th.join()
    assert published[0] > 0
    r = run["results"]
    assert r["result"] == "incomplete", r["verdict_reasons"]
    assert any("foreign telemetry: ARM_SIM" in w for w in r["verdict_reasons"]), r["verdict_reasons"]
    assert run["transport"]["telemetry"]["ARM_SIM"]["foreign"] > 0


# ---- bounded memory ----

PEAK = """
import json, resource, sys
sys.path.insert(0, {repo!r})
from pathlib import Path
from tools.run.run_analysis import analyse
from tools.run.telemetry_log import read_log  # noqa: F401 - imported as in armctl
out = Path(sys.argv[1])
run = json.loads((out / "run.json").read_text())
ctl = json.loads((out / "controller_summary.json").read_text())
sim = json.loads((out / "sim_summary.json").read_text())
base = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
new = analyse(out, ctl, sim, {{k: run["results"][k] for k in {keys!r}}}, run["environment"])
differs = [k for k, v in new["results"].items() if k in run["results"] and run["results"][k] != v]
assert not differs and new["results"]["result"] == "ok", differs
print(json.dumps({{"before": base, "peak": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss}}))
"""


def test_analysis_memory_does_not_grow_with_the_run(tmp_path: Path, controller_bin: Path) -> None:
    # The analysis's memory is under test, not the firmware: the release build makes the 192 MB
    # log in a tenth of the sanitizer build's time (the sanitizers run the firmware everywhere else).
    preset = "release"
    peaks = {}
    for duration in (30.0, 300.0):
        out = tmp_path / f"d{duration:g}"
        run = run_hil(HilOptions(out=out, duration_s=duration, method="pm", preset=preset, bus="sil"))
        assert run["results"]["result"] == "ok"
        got = subprocess.run([sys.executable, "-c", PEAK.format(repo=str(REPO), keys=CONFIG_KEYS), str(out)],
                             capture_output=True, text=True, check=True)
        peaks[duration] = json.loads(got.stdout)
        peaks[duration]["log_mb"] = (out / "telemetry.lcmlog").stat().st_size / 1e6
        shutil.rmtree(out)
    # ten times the log (192 MB): the analysis's own memory (beyond the imports) grows by under 10 MB more
    grow = {d: (p["peak"] - p["before"]) / 1024 for d, p in peaks.items()}
    assert peaks[300.0]["log_mb"] > 9 * peaks[30.0]["log_mb"]
    assert grow[300.0] < grow[30.0] + 10, (grow, peaks)
    assert grow[300.0] < 60, (grow, peaks)
