"""The study's PNG figures, named by scenario: distributions per method and joint; every metric per
joint as bars with their 95 % intervals; the paper's Figs. 6-8 for the first seed of every
scenario; the arm in the worst kept run (tools/run/render.py); each tuned method's best-so-far
curve. One colour per method in every figure, runs that did not end ok marked (what they draw:
tools/study/figure_data.py). Apart from the report's text
(tools/study/report.py) so that `--no-figures` costs neither the figures (about a second of CPU
each) nor matplotlib's import (0.4 s a process)."""

from __future__ import annotations

import gc
import os
import sys
from pathlib import Path
from typing import Any

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from tools.study.figure_data import (ANSWER_FIGURE, BAR_METRICS, ENVELOPE_S, METRIC_TEXT, METRIC_UNITS,  # noqa: E402
                                     answer_bars, colour_of, envelopes, fig_name, loop_rate_hz, metric_bars,
                                     scenario_series, stopped_early, worst_kept_run)
from tools.study.html_figures import (answer_figure, distribution_figure, envelope_figure, metrics_figure,  # noqa: E402
                                      tuning_figure)
from tools.study.config import ESTIMATING  # noqa: E402
from gen.lib.escape import matplotlib_text as mt  # noqa: E402
from gen.lib.one_line import one_line  # noqa: E402


def _time_figures(out: Path, study: dict[str, Any], scenario: str) -> list[tuple[str, str | None]]:
    """The paper's Figs. 6-8 for the first seed of one scenario: every method in its own colour, a
    run the safety layer stopped drawn up to its stop and marked there (a cross and a dotted line),
    one that ended badly otherwise named with its result in the legend, a run with no trajectory
    named in the title. Estimation and tracking errors as envelopes on a log scale: methods whose
    errors differ a hundredfold all stay visible, and none dissolves into a band of noise."""
    n = study["arm"]["n_joints"]
    colour = colour_of(study)
    runs = study["scenarios"][scenario]["runs"]
    series, empty = scenario_series(out, study, scenario)
    made: list[tuple[str, str | None]] = []
    if not series:
        return made
    env = envelopes(series, loop_rate_hz(study))

    def label(m: str) -> str:
        r = runs[m][0].get("result") if runs.get(m) else None
        return mt(m if r == "ok" else f"{m} ({r}{', stopped' if stopped_early(series[m]['t'], study) else ''})")

    def finish(fig: Any, axes: Any, title: str, kind: str, shown: list[str], at: Any = None,
               interactive: str | None = None) -> None:
        for m in shown:
            if stopped_early(series[m]["t"], study):  # where the safety layer stopped it
                for j, ax in enumerate(axes):
                    ax.axvline(series[m]["t"][-1], color=colour[m], lw=0.8, ls=":")
                    if at is not None:  # and a cross on its line, where it ended
                        ax.plot([series[m]["t"][-1]], [at(m, j)], marker="X", ms=8, color=colour[m], mec="k", zorder=5)
        fig.suptitle(title + (f"; {mt(', '.join(empty))}" if empty else ""), fontsize=9, y=0.995)
        axes[-1].set_xlabel("t (s)")
        made.append((_save(fig, out / fig_name(kind, scenario), tight=False), interactive))

    if "pm" in series:
        fig, axes = _joint_column(n)
        for j in range(n):
            axes[j].plot(series["pm"]["t"], series["pm"]["w"][:, j], lw=0.6, color=colour["pm"])
            axes[j].set_ylabel(f"w{j + 1}")
        finish(fig, axes, f"Total uncertainty w (rad/s^2) during the PM run, {mt(scenario)} (cf. the paper's Fig. 6)",
               "uncertainty", ["pm"])
    for kind, methods, unit, what, fig_of in (
            ("estimation", [m for m in ESTIMATING if m in series], "rad/s^2", "Estimation error: max |w - w_hat|",
             "Fig. 7"),
            ("tracking", list(series), "deg", "Tracking error: max |e|", "Fig. 8")):
        if not methods:
            continue
        fig, axes = _joint_column(n)
        for m in methods:
            for j in range(n):
                axes[j].semilogy(series[m]["t"], env[kind][m][:, j], lw=1.0, color=colour[m], label=label(m))
        for j in range(n):
            axes[j].set_ylabel(f"joint {j + 1} ({unit})")
        if kind == "tracking":
            bound = next((r[0]["bounds"]["max_error_deg"] for r in runs.values() if r and r[0].get("bounds")), None)
            if bound:  # the run's tracking bound: above it, the verdict is tracking-bound-exceeded
                for ax in axes:
                    ax.axhline(bound, color="k", lw=0.7, ls="--", label=f"tracking bound {bound:g} deg")
        # above the panels, where it hides no line
        axes[0].legend(loc="lower left", bbox_to_anchor=(0.0, 1.0), fontsize=7, ncol=4, frameon=False)
        finish(fig, axes, f"{what} over {ENVELOPE_S * 1e3:g} ms, {mt(scenario)}, seed {study['seeds'][0]} "
               f"(cf. the paper's {fig_of}); x: where the safety layer stopped a run",
               "estimation_error" if kind == "estimation" else "tracking_error", methods,
               at=lambda m, j, kind=kind: env[kind][m][-1, j],
               interactive=envelope_figure(study, scenario, kind, series, env[kind]))
    return made


def _joint_column(n: int) -> tuple[Any, Any]:
    """One panel a joint, stacked, on a shared time axis, laid out once and for all: tight_layout
    measured every tick label again, 40 % of a time figure's cost, for margins these figures never
    need to change (short labels, a one-line title)."""
    fig, axes = plt.subplots(n, 1, figsize=(9, 11), sharex=True, squeeze=False)
    fig.subplots_adjust(left=0.1, right=0.98, bottom=0.05, top=0.93, hspace=0.12)
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
            ax.scatter(np.full(len(b), i + 1.0), b, s=45, color="k", marker="x", linewidths=1.5, zorder=4)
        if any(np.any(d > 0) for d in data):  # a scale of logs needs a value; no run may have measured
            ax.set_yscale("log")
        else:
            ax.text(0.5, 0.5, "no run measured", ha="center", va="center", transform=ax.transAxes, fontsize=7)
        ax.set_xticks(range(1, len(methods) + 1), [mt(m) for m in methods], rotation=70, fontsize=7)
        ax.set_title(mt(study["arm"]["joint_names"][j]), fontsize=8)
    axes[0].set_ylabel("L-inf tracking error (deg), one point per seed")
    fig.suptitle(f"{mt(scenario)}: {len(study['seeds'])} seed(s); dot: a run that ended ok, x: one that did not")
    return _save(fig, out / fig_name("distribution", scenario))


def _grouped_bars(ax: Any, groups: list[str], bars: dict[str, dict[str, Any]], colour: dict[str, str]) -> None:
    """One group of bars per entry of `groups`, a bar a method in its colour with its 95 % interval;
    hatched where some of its runs did not end ok (`not_ok`: one count, or one per group; `labels`:
    the legend's, one per group, None for none); a log scale where the means span more than 30x."""
    width = 0.8 / max(len(bars), 1)
    x0 = np.arange(len(groups))
    for k, (m, b) in enumerate(bars.items()):
        x = x0 + (k - (len(bars) - 1) / 2) * width
        bad = np.broadcast_to(np.asarray(b["not_ok"]) > 0, x.shape)
        for xi, mean, hatched, label in zip(x, b["mean"], bad, b["labels"]):
            ax.bar(xi, mean, width, color=colour[m], edgecolor="k" if hatched else colour[m], lw=0.6,
                   hatch="///" if hatched else None, alpha=0.9, label=label)
        ax.errorbar(x, b["mean"], yerr=[b["below"], b["above"]], fmt="none", ecolor="k", lw=0.8, capsize=2)
    vals = np.concatenate([b["mean"] for b in bars.values()]) if bars else np.array([])
    vals = vals[np.isfinite(vals) & (vals > 0)]
    if len(vals) and vals.max() / vals.min() > 30:
        ax.set_yscale("log")
    ax.set_xticks(x0, [mt(g) for g in groups], fontsize=8)


def _answer_figure(out: Path, study: dict[str, Any]) -> str:
    """The answer drawn (fig_answer_all.png): per scenario, each method's L-infinity tracking error
    summed over the joints, mean and 95 % interval; hatched where some runs did not end ok."""
    colour = colour_of(study)
    groups, bars = answer_bars(study)
    fig, ax = plt.subplots(figsize=(max(7.0, 2.2 * len(groups) + 2), 3.6))
    _grouped_bars(ax, groups, {m: {**b, "labels": [None] * len(groups)} for m, b in bars.items()}, colour)
    ax.set_ylabel("deg")
    ax.grid(axis="y", lw=0.3, alpha=0.6)
    from matplotlib.patches import Patch

    ax.legend(handles=[Patch(color=colour[m], label=mt(m)) for m in bars], fontsize=7, ncol=min(len(bars), 7),
              loc="lower left", bbox_to_anchor=(0.0, 1.0), frameon=False)
    fig.suptitle(f"L-infinity tracking error summed over the joints: mean over {len(study['seeds'])} seed(s),\n"
                 "95 % interval (hatched: some runs not ok)", fontsize=9)
    return _save(fig, out / fig_name(ANSWER_FIGURE, "all"))


def _metrics_figure(out: Path, study: dict[str, Any], scenario: str) -> str:
    """Each metric per joint as bars, the mean over the seeds with its 95 % interval (the paper's
    Tables 1-3 drawn): one bar a method in its colour, hatched where some of its runs did not end
    ok (the legend says how many); a log scale where the means span more than 30x."""
    colour = colour_of(study)
    n = study["arm"]["n_joints"]
    fig, axes = plt.subplots(len(BAR_METRICS), 1, figsize=(max(9.0, 1.4 * n + 2), 13),
                             gridspec_kw={"height_ratios": [3, 3, 3, 2]})
    for ax, metric in zip(axes, BAR_METRICS):
        groups, bars = metric_bars(study, scenario, metric)
        _grouped_bars(ax, groups, {m: {**b, "labels": [mt(m + (f" ({b['not_ok']} of {b['runs']} runs not ok)"
                                                               if b["not_ok"] else ""))] + [None] * (len(groups) - 1)}
                                   for m, b in bars.items()}, colour)
        ax.set_ylabel(METRIC_UNITS[metric])
        ax.set_title(f"{METRIC_TEXT[metric]}: mean over {len(study['seeds'])} seed(s), 95 % interval", fontsize=9)
        ax.grid(axis="y", lw=0.3, alpha=0.6)
    axes[0].legend(fontsize=7, ncol=min(len(study["methods"]), 4), loc="upper left")
    fig.suptitle(f"{mt(scenario)}: every metric per joint (hatched: a method some of whose runs did not end ok)",
                 fontsize=10)
    return _save(fig, out / fig_name("metrics", scenario))


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
        ax.step(x, curve, where="post", color=c, label=mt(f"{m}: {status}, {curve.size} of at most {r.get('cap')} "
                                                            f"trials, best {curve[-1]:.4g}"))
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
    ax.set_title(f"{mt(scenario)}: tuning, best so far (o converged, x capped; dotted: a widening round starts)",
                 fontsize=9)
    ax.legend(fontsize=7)
    return _save(fig, out / fig_name("tuning", scenario))


def _arm_strip(out: Path, study: dict[str, Any], scenario: str) -> list[tuple[str, str | None]]:
    """The frame strip of the scenario's worst kept run (tools/study/figure_data.py worst_kept_run)."""
    from tools.run.render import RenderError, write_strip_apart

    worst = worst_kept_run(study, scenario)
    if worst is None:
        return []
    name = fig_name("arm", scenario)
    try:
        write_strip_apart(out / scenario / worst[0] / f"seed-{worst[1]}", out, name)
    except RenderError as exc:  # the report says why it has no strip, and the study goes on
        print(f"armctl study: no arm strip for {one_line(scenario)}: {one_line(str(exc))}", file=sys.stderr)
        return []
    return [(name, None)]


def _scenario_figures(out: Path, study: dict[str, Any], scenario: str, kind: str) -> list[tuple[str, str | None]]:
    """One scenario's figures of one kind (FIGURE_KINDS): each one's file name and its interactive
    version for report.html (plotly's JSON; None: the PNG itself)."""
    if kind == "tuning":
        recs = study["scenarios"][scenario]["tuning"]
        return [(convergence_figure(out, scenario, recs, colour_of(study)),
                 tuning_figure(scenario, recs, colour_of(study)))]
    if kind == "distribution":
        return [(_distribution_figure(out, study, scenario), distribution_figure(study, scenario))]
    if kind == "metrics":
        return [(_metrics_figure(out, study, scenario), metrics_figure(study, scenario))]
    if kind == "arm":
        return _arm_strip(out, study, scenario)
    return _time_figures(out, study, scenario)


FIGURE_KINDS = ("time", "arm", "distribution", "metrics", "tuning")  # the slowest first: the workers end together


def draw_figures(out: Path, study: dict[str, Any], jobs: int | None = None) -> dict[tuple[str, str],
                                                                                   list[tuple[str, str | None]]]:
    """Every scenario's figures, drawn in `jobs` processes (default: every core this process may
    use; matplotlib holds the GIL, and the figures were a third of a study's time): (scenario,
    kind) -> each figure's file name and interactive version. Each task gets its own scenario of
    the study alone."""
    import multiprocessing
    from concurrent.futures import ProcessPoolExecutor

    tasks = [(name, kind) for kind in FIGURE_KINDS for name in study["scenarios"]]
    jobs = min(len(tasks), jobs or len(os.sched_getaffinity(0)))
    answer = {(ANSWER_FIGURE, ANSWER_FIGURE): [(_answer_figure(out, study), answer_figure(study))]}  # the whole study's, here
    if jobs <= 1:
        return {**answer, **{(name, kind): _scenario_figures(out, study, name, kind) for name, kind in tasks}}
    # fork: the workers have matplotlib imported already, and need no importable __main__ (a
    # forkserver or spawn would re-run the caller's script); the study's run threads have ended
    ctx = multiprocessing.get_context("fork")
    # the caller's heap (a whole study, the solver's imports) stays shared with the workers only while
    # nothing writes to it: the collector in each worker would walk, and so copy, every object the
    # parent had
    gc.collect()
    gc.freeze()
    try:
        with ProcessPoolExecutor(max_workers=jobs, mp_context=ctx) as pool:
            futs = {t: pool.submit(_scenario_figures, out, {**study, "scenarios": {t[0]: study["scenarios"][t[0]]}},
                                   *t) for t in tasks}
            return {**answer, **{t: f.result() for t, f in futs.items()}}
    finally:
        gc.unfreeze()

