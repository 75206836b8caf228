"""The study's PNG figures, named by scenario: distributions per method and joint; the paper's
Figs. 6-8 for the first seed of every scenario; each tuned method's best-so-far curve. One colour
per method in every figure, runs that did not end ok marked. Apart from the report's text
(tools/study/report.py) so that `--no-figures` costs neither the figures (about a second of CPU
each) nor matplotlib's import (0.4 s a process)."""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from tools.run.telemetry_log import read_log, truth_rows  # noqa: E402
from tools.study.config import METHODS  # noqa: E402
from tools.study.report import ESTIMATING, fig_name  # noqa: E402


ENVELOPE_S = 0.1  # the tracking figure draws each method's max |e| over this trailing window


def colour_of(study: dict[str, Any]) -> dict[str, Any]:
    """One colour per method, the same in every figure of every study: by its place in the table
    of study methods (tools/study/config.py METHODS), whichever of them a study runs."""
    cmap = plt.get_cmap("tab10")
    order = list(METHODS)
    return {m: cmap((order.index(m) if m in order else len(order) + i) % 10) for i, m in enumerate(study["methods"])}


def envelope(x: np.ndarray, window: int) -> np.ndarray:
    """max |x| over the trailing `window` samples: a band of sensor noise around zero becomes one
    line at its height, and lines of methods that differ stay apart."""
    from scipy.ndimage import maximum_filter1d

    w = max(1, min(window, len(x)))
    return maximum_filter1d(np.abs(x), size=w, origin=(w - 1) // 2, mode="nearest")


def _series(run_dir: Path, hold: float) -> dict[str, np.ndarray]:
    """One kept run's trajectory series (the figures plot a seed): its whole ARM_CTL and ARM_SIM."""
    log = read_log(run_dir / "telemetry.lcmlog", channels=("ARM_CTL", "ARM_SIM"))
    ctl, sim = log["ARM_CTL"].messages, log["ARM_SIM"].messages
    ctl = ctl[(ctl.state == 1) & (ctl.t >= hold - 1e-9)]
    w_hat = ctl.w_hat.astype(float)
    at = truth_rows(ctl, sim)  # w_true of the period each controller message names, NaN if none
    w = np.full(w_hat.shape, np.nan)
    w[at >= 0] = sim.w_true[at[at >= 0]]
    return {"t": ctl.t - hold, "e": ctl.e.astype(float), "w": w, "w_hat": w_hat}


def _time_figures(out: Path, study: dict[str, Any], scenario: str) -> list[str]:
    """The paper's Figs. 6-8 for the first seed of one scenario: every method in its own colour, a
    run the safety layer stopped drawn up to its stop and marked, a run with no trajectory named."""
    hold, seed = study["hold_s"], study["seeds"][0]
    n = study["arm"]["n_joints"]
    colour = colour_of(study)
    runs = study["scenarios"][scenario]["runs"]
    series, empty = {}, []
    for m in study["methods"]:
        d = out / scenario / m / f"seed-{seed}"
        got = _series(d, hold) if (d / "telemetry.lcmlog").exists() else None
        if got is not None and len(got["t"]) >= 2:
            series[m] = got
        else:
            empty.append(f"{m} ({runs[m][0].get('result') if runs.get(m) else 'not run'}: no trajectory)")
    made: list[str] = []
    if not series:
        return made

    def label(m: str) -> str:
        r = runs[m][0].get("result") if runs.get(m) else None
        return m if r == "ok" else f"{m} ({r})"

    def finish(fig: Any, axes: Any, title: str, kind: str, at: Any = None) -> None:
        for m in series:
            if runs.get(m) and runs[m][0].get("result") != "ok":  # where it stopped or ended badly
                for j, ax in enumerate(axes):
                    ax.axvline(series[m]["t"][-1], color=colour[m], lw=0.8, ls=":")
                    if at is not None:  # and a cross on its line, where it ended
                        ax.plot([series[m]["t"][-1]], [at(m, j)], marker="X", ms=8, color=colour[m], mec="k", zorder=5)
        axes[0].set_title(title + (f"; {', '.join(empty)}" if empty else ""), fontsize=9)
        axes[-1].set_xlabel("t (s)")
        made.append(_save(fig, out / fig_name(kind, scenario), tight=False))

    if "pm" in series:
        fig, axes = _joint_column(n)
        for j in range(n):
            axes[j].plot(series["pm"]["t"], series["pm"]["w"][:, j], lw=0.6, color=colour["pm"])
            axes[j].set_ylabel(f"w{j + 1}")
        finish(fig, axes, f"Total uncertainty w (rad/s^2) during the PM run, {scenario} (cf. the paper's Fig. 6)",
               "uncertainty")
    est = [m for m in ESTIMATING if m in series]
    if est:
        fig, axes = _joint_column(n)
        for m in est:
            for j in range(n):
                axes[j].plot(series[m]["t"], series[m]["w"][:, j] - series[m]["w_hat"][:, j], lw=0.6,
                             color=colour[m], label=label(m))
        for j in range(n):
            axes[j].set_ylabel(f"joint {j + 1}")
        axes[0].legend(loc="upper right", fontsize=7, ncol=len(est))
        finish(fig, axes, f"Estimation error w - w_hat (rad/s^2), {scenario} (cf. the paper's Fig. 7)",
               "estimation_error")
    # the envelope of |e| on a log scale: methods whose errors differ a hundredfold all stay visible,
    # and none dissolves into a band of noise that crosses zero
    fig, axes = _joint_column(n)
    env = {m: np.maximum(np.degrees(np.stack([envelope(sr["e"][:, j], int(ENVELOPE_S * study.get("rate_hz", 1000.0)))
                                              for j in range(n)], axis=1)), 1e-6) for m, sr in series.items()}
    for m, sr in series.items():
        for j in range(n):
            axes[j].semilogy(sr["t"], env[m][:, j], lw=1.0, color=colour[m], label=label(m))
    for j in range(n):
        axes[j].set_ylabel(f"|e{j + 1}| (deg)")
    axes[0].legend(loc="upper right", fontsize=7, ncol=min(len(series), 4))
    finish(fig, axes, f"Tracking error: max |e| over {ENVELOPE_S * 1e3:g} ms, {scenario} (cf. the paper's Fig. 8); "
           "x: where a run that did not end ok stopped", "tracking_error", at=lambda m, j: env[m][-1, j])
    return made


def _joint_column(n: int) -> tuple[Any, Any]:
    """One panel a joint, stacked, on a shared time axis, laid out once and for all: tight_layout
    measured every tick label again, 40 % of a time figure's cost, for margins these figures never
    need to change (short labels, a one-line title)."""
    fig, axes = plt.subplots(n, 1, figsize=(9, 11), sharex=True, squeeze=False)
    fig.subplots_adjust(left=0.1, right=0.98, bottom=0.05, top=0.965, hspace=0.12)
    return fig, axes[:, 0]


def _save(fig: Any, path: Path, tight: bool = True) -> str:
    if tight:
        fig.tight_layout()
    fig.savefig(path, dpi=90)
    plt.close(fig)
    return path.name


def _distribution_figure(out: Path, study: dict[str, Any], scenario: str) -> str:
    """Per joint, each method's L-infinity error over the seeds (a box in the method's colour, every
    seed's point; a run that did not end ok is a red cross)."""
    sc = study["scenarios"][scenario]
    n, methods = study["arm"]["n_joints"], study["methods"]
    colour = colour_of(study)
    fig, axes = plt.subplots(1, n, figsize=(2.2 * n + 1, 4.2), sharey=False)
    axes = np.atleast_1d(axes)
    for j in range(n):
        ax = axes[j]
        data, bad = [], []
        for m in methods:
            vals = sc["stats"][m]["linf"]["per_joint"][j]["values"]
            res = sc["stats"][m]["results"]
            ok = [(v, r) for v, r in zip(vals, res) if v is not None and np.isfinite(v)]
            data.append(np.degrees([v for v, _ in ok]))
            bad.append(np.degrees([v for v, r in ok if r != "ok"]))
        box = ax.boxplot(data, showfliers=False, patch_artist=True)
        for patch, m in zip(box["boxes"], methods):
            patch.set_facecolor(colour[m])
            patch.set_alpha(0.5)
        for i, (d, b) in enumerate(zip(data, bad)):
            ax.scatter(np.full(len(d), i + 1.0), d, s=8, color="k", zorder=3)
            ax.scatter(np.full(len(b), i + 1.0), b, s=30, color="red", marker="x", zorder=4)
        if any(np.any(d > 0) for d in data):  # a scale of logs needs a value; no run may have measured
            ax.set_yscale("log")
        else:
            ax.text(0.5, 0.5, "no run measured", ha="center", va="center", transform=ax.transAxes, fontsize=7)
        ax.set_xticks(range(1, len(methods) + 1), methods, rotation=70, fontsize=7)
        ax.set_title(study["arm"]["joint_names"][j], fontsize=8)
    axes[0].set_ylabel("L-inf tracking error (deg), one point per seed")
    fig.suptitle(f"{scenario}: {len(study['seeds'])} seed(s); red x: a run that did not end ok")
    return _save(fig, out / fig_name("distribution", scenario))


def convergence_figure(out: Path, scenario: str, recs: dict[str, dict[str, Any]], colour: dict[str, Any]) -> str:
    """Each tuned method's best-so-far objective over its trials (log scale), in its colour; the
    cap a dashed line; a converged method's end a dot, a capped one's a cross; round starts ticked."""
    fig, ax = plt.subplots(figsize=(7.5, 4.2))
    cap, lows = 0, []
    for m, r in recs.items():
        curve = np.asarray(r.get("best_so_far") or [], dtype=float)
        if not curve.size:
            continue
        cap = max(cap, int(r.get("cap") or 0))
        lows.append(curve.min())
        x = np.arange(1, curve.size + 1)
        c = colour.get(m)
        status = r.get("status", "?")
        ax.step(x, curve, where="post", color=c, label=f"{m}: {status}, {curve.size} of at most {r.get('cap')} "
                                                         f"trials, best {curve[-1]:.4g}")
        ax.scatter([x[-1]], [curve[-1]], color=c, marker="o" if status == "converged" else "x", s=40, zorder=3)
        starts = np.cumsum([len(rd["trials"]) for rd in r.get("rounds", [])])[:-1]
        for st in starts:
            ax.axvline(st + 0.5, color=c, lw=0.6, ls=":")
    if cap:
        ax.axvline(cap, color="k", ls="--", lw=0.8, label=f"cap {cap}")
    if lows and min(lows) > 0:
        ax.set_yscale("log")
    ax.axhline(1000.0, color="red", lw=0.6, ls="-.")  # at and above: no trial ended well (tools/study/tuning.py)
    ax.set_xlabel("trial (every round, in order)")
    ax.set_ylabel("best objective so far (sum L-inf, rad; >= 1000: failed)")
    ax.set_title(f"{scenario}: tuning, best so far (o converged, x capped; dotted: a widening round starts)",
                 fontsize=9)
    ax.legend(fontsize=7)
    return _save(fig, out / fig_name("tuning", scenario))


def _scenario_figures(out: Path, study: dict[str, Any], scenario: str, kind: str) -> list[str]:
    """One scenario's figures of one kind ("tuning", "distribution" or "time"): their file names."""
    if kind == "tuning":
        return [convergence_figure(out, scenario, study["scenarios"][scenario]["tuning"], colour_of(study))]
    if kind == "distribution":
        return [_distribution_figure(out, study, scenario)]
    return _time_figures(out, study, scenario)


FIGURE_KINDS = ("time", "distribution", "tuning")  # the slowest first: the workers end together


def draw_figures(out: Path, study: dict[str, Any], jobs: int | None = None) -> dict[tuple[str, str], list[str]]:
    """Every scenario's figures, drawn in `jobs` processes (default: every core this process may
    use; matplotlib holds the GIL, and the figures were a third of a study's time): (scenario,
    kind) -> file names. Each task gets its own scenario of the study alone."""
    import multiprocessing
    from concurrent.futures import ProcessPoolExecutor

    tasks = [(name, kind) for kind in FIGURE_KINDS for name in study["scenarios"]]
    jobs = min(len(tasks), jobs or len(os.sched_getaffinity(0)))
    if jobs <= 1:
        return {(name, kind): _scenario_figures(out, study, name, kind) for name, kind in tasks}
    # fork: the workers have matplotlib imported already, and need no importable __main__ (a
    # forkserver or spawn would re-run the caller's script); the study's run threads have ended
    ctx = multiprocessing.get_context("fork")
    with ProcessPoolExecutor(max_workers=jobs, mp_context=ctx) as pool:
        futs = {t: pool.submit(_scenario_figures, out, {**study, "scenarios": {t[0]: study["scenarios"][t[0]]}}, *t)
                for t in tasks}
        return {t: f.result() for t, f in futs.items()}

