"""What the study's figures draw, apart from any drawing, so that the PNG figures
(tools/study/figures.py, matplotlib) and report.html's interactive ones (tools/study/html_report.py,
plotly) draw the same: one colour per method, each method's kept run of a scenario (the first
seed's: the study keeps that seed's telemetry) and its envelopes (max |x| over a trailing window,
which lets methods whose errors differ a hundredfold stay apart), and each metric's means with
their 95 % intervals per joint."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from tools.run.run_files import TELEMETRY_LOG
from tools.run.telemetry_log import read_log, truth_rows
from gen.lib.escape import file_stem
from gen.lib.params import default
from tools.study.config import ESTIMATING, METHODS

# matplotlib's tab10, the colours of every figure's methods in their order in the study's method
# table (METHODS): the same colour for a method in every figure of every study, PNG or HTML
PALETTE = ("#1f77b4", "#ff7f0e", "#2ca02c", "#d62728", "#9467bd", "#8c564b", "#e377c2", "#7f7f7f", "#bcbd22",
           "#17becf")
METRIC_UNITS = {"linf": "deg", "rms": "deg", "est": "rad/s^2", "power": "W"}
BAR_METRICS = ("linf", "rms", "est", "power")

ENVELOPE_S = 0.1  # the tracking and estimation figures draw each method's max |x| over this trailing window

METRIC_TEXT = {"linf": "L-infinity tracking error (deg)", "rms": "RMS tracking error (deg)",
               "est": "RMS estimation error w - w_hat (rad/s^2)", "power": "torque power (W)"}
# What a person reads is in degrees; study.json keeps the runs' radians.
IN_DEGREES = ("linf", "rms")


def in_degrees(s: dict[str, Any], metric: str) -> dict[str, Any]:
    """A statistic of radians, in degrees when the metric is an angle (IN_DEGREES)."""
    if metric not in IN_DEGREES or s.get("mean") is None:
        return s
    return {**s, "mean": float(np.degrees(s["mean"])),
            "ci95": [float(np.degrees(v)) for v in s["ci95"]] if s.get("ci95") else s.get("ci95")}


def fig_name(kind: str, scenario: str) -> str:
    """fig_KIND_SCENARIO.png, the scenario's name made a file name."""
    return f"fig_{kind}_{file_stem(scenario)}.png"


def worst_kept_run(study: dict[str, Any], scenario: str) -> tuple[str, int, str] | None:
    """The scenario's worst run among those whose telemetry the study keeps (every method's first
    seed): one the safety layer stopped before its trajectory ended, else the largest sum over the
    joints of the L-infinity tracking error (the tuning's objective). (method, seed, why), or None."""
    seed = study["seeds"][0]
    ranked = []
    for m, runs in study["scenarios"][scenario]["runs"].items():
        if not runs:
            continue
        r = runs[0]
        linf = r.get("tracking_max_abs_deg")
        if linf:
            ranked.append((0, float(sum(linf)), m, f"the largest L-infinity tracking error summed over the joints, "
                                                   f"{sum(linf):.3g} deg; {r.get('result')}"))
        elif r.get("result") != "ok":
            ranked.append((1, 0.0, m, f"{r.get('result')} before its trajectory ended"))
    if not ranked:
        return None
    _, _, m, why = max(ranked)
    return m, seed, why


ANSWER_FIGURE = "answer"  # tools/study/figures.py ANSWER: draw_figures' key of the study's one figure


def loop_rate_hz(study: dict[str, Any]) -> float:
    """The loop rate the study ran at (study.json's rate_hz, the arm's design's); a record made
    before it was kept ran at the registry's default."""
    return float(study.get("rate_hz") or default("controller", "rate"))


def colour_of(study: dict[str, Any]) -> dict[str, str]:
    """One colour per method, the same in every figure of every study: by its place in the table
    of study methods (tools/study/config.py METHODS), whichever of them a study runs."""
    order = list(METHODS)
    return {m: PALETTE[(order.index(m) if m in order else len(order) + i) % len(PALETTE)]
            for i, m in enumerate(study["methods"])}


def metric_bars(study: dict[str, Any], scenario: str, metric: str) -> tuple[list[str], dict[str, dict[str, Any]]]:
    """One metric of a scenario as the bar charts draw it: the groups (a joint each; "total" for
    power) and per method its means, the 95 % interval's half-widths below and above (NaN: none)
    and how many of its runs did not end ok."""
    sc = study["scenarios"][scenario]
    names = study["arm"]["joint_names"]
    groups = ["total"] if metric == "power" else [f"{j + 1} {names[j]}" for j in range(len(names))]
    out = {}
    for m in study["methods"]:
        if metric == "est" and m not in ESTIMATING:
            continue
        st = sc["stats"][m][metric]
        cells = [in_degrees(s, metric) for s in ([st["total"]] if metric == "power" else st["per_joint"])]
        mean = np.array([c["mean"] if c.get("mean") is not None else np.nan for c in cells], float)
        lo = np.array([c["ci95"][0] if c.get("ci95") else np.nan for c in cells], float)
        hi = np.array([c["ci95"][1] if c.get("ci95") else np.nan for c in cells], float)
        out[m] = {"mean": mean, "below": mean - lo, "above": hi - mean,
                  "not_ok": sum(1 for r in sc["stats"][m]["results"] if r != "ok"), "runs": len(sc["stats"][m]["results"])}
    return groups, out


def answer_bars(study: dict[str, Any]) -> tuple[list[str], dict[str, dict[str, Any]]]:
    """The study's answer as bars: per scenario (the groups) each method's L-infinity tracking error
    summed over the joints (deg), the mean over the seeds, the 95 % interval's half-widths and how
    many of its runs did not end ok: what the pick is picked by."""
    groups = list(study["scenarios"])
    out: dict[str, dict[str, Any]] = {}
    for m in study["methods"]:
        cells = [in_degrees(study["scenarios"][s]["stats"][m]["linf"]["total"], "linf") for s in groups]
        mean = np.array([c["mean"] if c.get("mean") is not None else np.nan for c in cells], float)
        lo = np.array([c["ci95"][0] if c.get("ci95") else np.nan for c in cells], float)
        hi = np.array([c["ci95"][1] if c.get("ci95") else np.nan for c in cells], float)
        not_ok = [sum(1 for r in study["scenarios"][s]["stats"][m]["results"] if r != "ok") for s in groups]
        out[m] = {"mean": mean, "below": mean - lo, "above": hi - mean, "not_ok": not_ok,
                  "runs": [len(study["scenarios"][s]["stats"][m]["results"]) for s in groups]}
    return groups, out


def envelope(x: np.ndarray, window: int) -> np.ndarray:
    """max |x| over the trailing `window` samples: a band of sensor noise around zero becomes one
    line at its height, and lines of methods that differ stay apart."""
    from scipy.ndimage import maximum_filter1d

    w = max(1, min(window, len(x)))
    return maximum_filter1d(np.abs(x), size=w, origin=(w - 1) // 2, mode="nearest", axis=0)


def run_series(run_dir: Path, hold: float) -> dict[str, np.ndarray]:
    """One kept run's trajectory series: t after the hold (s), e (rad), w and w_hat (rad/s^2; w NaN
    where the simulator logged no message for the period)."""
    log = read_log(run_dir / TELEMETRY_LOG, channels=("ARM_CTL", "ARM_SIM"))
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
        got = run_series(d, hold) if (d / TELEMETRY_LOG).exists() else None
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
    return float(t[-1]) < study["duration_s"] - 2.0 / loop_rate_hz(study)


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
