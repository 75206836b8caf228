"""The time series the study's figures draw, apart from any drawing: each method's kept run of a
scenario (the first seed's: the study keeps that seed's telemetry) read once, and the envelopes
(max |x| over a trailing window) that let methods whose errors differ a hundredfold stay apart.
The PNG figures (tools/study/figures.py) and report.html's interactive ones
(tools/study/html_report.py) both draw these."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from tools.run.telemetry_log import read_log, truth_rows

ENVELOPE_S = 0.1  # the tracking and estimation figures draw each method's max |x| over this trailing window


def envelope(x: np.ndarray, window: int) -> np.ndarray:
    """max |x| over the trailing `window` samples: a band of sensor noise around zero becomes one
    line at its height, and lines of methods that differ stay apart."""
    from scipy.ndimage import maximum_filter1d

    w = max(1, min(window, len(x)))
    return maximum_filter1d(np.abs(x), size=w, origin=(w - 1) // 2, mode="nearest", axis=0)


def run_series(run_dir: Path, hold: float) -> dict[str, np.ndarray]:
    """One kept run's trajectory series: t after the hold (s), e (rad), w and w_hat (rad/s^2; w NaN
    where the simulator logged no message for the period)."""
    log = read_log(run_dir / "telemetry.lcmlog", channels=("ARM_CTL", "ARM_SIM"))
    ctl, sim = log["ARM_CTL"].messages, log["ARM_SIM"].messages
    ctl = ctl[(ctl.state == 1) & (ctl.t >= hold - 1e-9)]
    w_hat = ctl.w_hat.astype(float)
    at = truth_rows(ctl, sim)  # w_true of the period each controller message names, NaN if none
    w = np.full(w_hat.shape, np.nan)
    w[at >= 0] = sim.w_true[at[at >= 0]]
    return {"t": ctl.t - hold, "e": ctl.e.astype(float), "w": w, "w_hat": w_hat}


def scenario_series(out: Path, study: dict[str, Any], scenario: str) -> tuple[dict[str, dict[str, np.ndarray]],
                                                                               list[str]]:
    """Every method's series of the first seed of a scenario, and a note for each method whose run
    left no trajectory."""
    hold, seed = study["hold_s"], study["seeds"][0]
    runs = study["scenarios"][scenario]["runs"]
    series, empty = {}, []
    for m in study["methods"]:
        d = out / scenario / m / f"seed-{seed}"
        got = run_series(d, hold) if (d / "telemetry.lcmlog").exists() else None
        if got is not None and len(got["t"]) >= 2:
            series[m] = got
        else:
            empty.append(f"{m} ({runs[m][0].get('result') if runs.get(m) else 'not run'}: no trajectory)")
    return series, empty


def envelopes(series: dict[str, dict[str, np.ndarray]], rate_hz: float) -> dict[str, dict[str, np.ndarray]]:
    """Per kind ("tracking": |e| in deg, "estimation": |w - w_hat| in rad/s^2) and method, the
    envelope over ENVELOPE_S, (periods, joints); floored at 1e-6 for a log scale."""
    window = int(ENVELOPE_S * rate_hz)
    return {"tracking": {m: np.maximum(np.degrees(envelope(sr["e"], window)), 1e-6) for m, sr in series.items()},
            "estimation": {m: np.maximum(envelope(np.nan_to_num(sr["w"] - sr["w_hat"]), window), 1e-6)
                           for m, sr in series.items()}}


def stopped_early(t: np.ndarray, study: dict[str, Any]) -> bool:
    """Whether a run's series ends before its trajectory did (the safety layer stopped it)."""
    return float(t[-1]) < study["duration_s"] - 2.0 / study.get("rate_hz", 1000.0)


def decimate(t: np.ndarray, y: np.ndarray, points: int) -> tuple[np.ndarray, np.ndarray]:
    """At most `points` samples of an envelope, each the max over its block: no peak is lost."""
    k = max(1, int(np.ceil(len(t) / points)))
    if k == 1:
        return t, y
    cut = len(t) // k * k
    tb = t[:cut].reshape(-1, k)[:, -1]
    yb = y[:cut].reshape(-1, k, *y.shape[1:]).max(axis=1)
    if cut < len(t):
        tb, yb = np.append(tb, t[-1]), np.concatenate([yb, y[cut:].max(axis=0, keepdims=True)])
    return tb, yb
