"""The study's report: report.md (per scenario: every method's mean and 95 % interval over the
seeds, PM against every other method on the same seeds, a verdict in words, the paper's claims
checked, the figures of tools/study/figures.py) and summary.txt (the table the CLI prints). A
person reads degrees: the tables give tracking errors in deg, study.json keeps the runs' radians."""

from __future__ import annotations

from pathlib import Path
from typing import Any, Callable

import numpy as np

from gen.lib.atomic_output import write_text_atomic
from gen.lib.escape import markdown_code as code, markdown_fence, markdown_text as md, shell_command
from gen.lib.one_line import one_line
from tools.run.verdict import FOLLOWING_ERROR_STOP_DEG, left_tracking_bound, stopped_by_following_error
from tools.study.config import ESTIMATING, STUDY_PROTOCOL
from tools.study.figure_data import ANSWER_FIGURE, METRIC_TEXT, fig_name, in_degrees, loop_rate_hz, worst_kept_run

PROTOCOL_TEXT = {"canopen": "CiA 402 (per-mille torque of the rated torque, positions in encoder increments)",
                 "arm": "the arm protocol (torques in micro-newton-metres, CAN FD state frames)"}

# Kim & Kim 2024, Tables 1-3 (Table 1 from their simulation, Tables 2-3 from their experiment).
PAPER_TABLE1 = {"usde-smc": [0.0292, 0.0950, 0.0320, 0.0462, 0.0157, 0.0157],
                "tde": [0.0594, 0.0231, 0.0164, 0.0212, 0.0431, 0.0155],
                "pm": [0.0117, 0.0100, 0.0119, 0.0100, 0.0140, 0.0103]}
PAPER_TABLE2 = {"usde-smc": [0.5956, 0.2118, 1.2881, 0.6978, 4.7868, 3.6274],
                "tde": [0.6201, 0.4429, 0.7234, 1.5404, 3.8190, 4.6619],
                "pm": [0.2163, 0.0883, 0.3618, 0.2889, 2.7415, 2.1596]}
PAPER_TABLE3 = {"usde-smc": 14.9473, "tde": 15.6809, "pm": 14.4772}
ALPHA = 0.05  # a paired difference counts as significant below this p (the paired t-test's: _p)


def _fmt(v: float | None) -> str:
    if v is None or not np.isfinite(v):
        return "-"
    return f"{v:.4f}" if abs(v) >= 1e-3 or v == 0 else f"{v:.2e}"


def _ci(s: dict[str, Any]) -> str:
    if s.get("mean") is None:
        return "-"
    if not s.get("ci95"):
        return _fmt(s["mean"])
    half = (s["ci95"][1] - s["ci95"][0]) / 2
    return f"{_fmt(s['mean'])} ± {_fmt(half)}"


def _md_table(header: list[str], rows: list[list[str]]) -> str:
    out = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    out += ["| " + " | ".join(r) + " |" for r in rows]
    return "\n".join(out)


def _p(c: dict[str, Any]) -> float | None:
    """The paired t-test's p: with 5 seeds Wilcoxon's cannot go below 0.0625 (both are in study.json)."""
    return c.get("t_test_p")


def _tuning_status(r: dict[str, Any]) -> str:
    if "status" not in r:  # a tuning kept from before the rule
        return f"{sum(len(x['trials']) for x in r['rounds'])} trials (no convergence rule)"
    return (f"{r['status']}: {r['trials_run']} of at most {r['cap']} trials (best improved <= "
            f"{100 * r['tolerance']:g} % over the last {r['plateau']})" if r["status"] == "converged" else
            f"capped: {r['trials_run']} trials, the cap (no plateau of {r['plateau']} trials within "
            f"{100 * r['tolerance']:g} %)")


def _labels(study: dict[str, Any], paper: bool) -> list[str]:
    names = study["arm"]["joint_names"]
    return [f"joint {j + 1}" if paper else f"{j + 1} {md(names[j])}" for j in range(len(names))]


def _stats_table(study: dict[str, Any], sc: dict[str, Any], metric: str, labels: list[str]) -> str:
    methods = [m for m in study["methods"] if metric != "est" or m in ESTIMATING]
    if metric == "power":
        return _md_table(["method", "mean ± 95 % CI"], [[md(m), _ci(sc["stats"][m]["power"]["total"])] for m in methods])
    rows = [[labels[j]] + [_ci(in_degrees(sc["stats"][m][metric]["per_joint"][j], metric)) for m in methods]
            for j in range(len(labels))]
    rows.append(["sum of joints"] + [_ci(in_degrees(sc["stats"][m][metric]["total"], metric)) for m in methods])
    return _md_table(["joint", *map(md, methods)], rows)


def _paired_table(study: dict[str, Any], sc: dict[str, Any], metric: str, labels: list[str]) -> str:
    bases = [b for b in sc["pm_versus"] if metric != "est" or b in ESTIMATING]
    n = len(study["seeds"])

    def cell(c: dict[str, Any]) -> str:
        p = _p(c)
        ratio = c.get("ratio_of_means")
        return (f"{ratio:.2f}x, {c['a_lower']}/{n}" if ratio is not None else f"-, {c['a_lower']}/{n}") + \
               (f", p {p:.2g}" if p is not None else "")

    if metric == "power":
        return _md_table(["", *map(md, bases)], [["total", *[cell(sc["pm_versus"][b]["power"]["total"]) for b in bases]]])
    rows = [[labels[j], *[cell(sc["pm_versus"][b][metric]["per_joint"][j]) for b in bases]] for j in range(len(labels))]
    rows.append(["sum of joints", *[cell(sc["pm_versus"][b][metric]["total"]) for b in bases]])
    return _md_table(["PM vs", *map(md, bases)], rows)


def _verdict(study: dict[str, Any], sc: dict[str, Any], labels: list[str]) -> list[str]:
    """Where PM wins and loses, and by how much, in words: per baseline and metric, the joints
    where PM's mean is lower, and how many of those differences are significant."""
    lines = []
    for m, st in sc["stats"].items():  # runs that did not end ok weigh on the means: said first
        bad = [(seed, r) for seed, r in zip(study["seeds"], st["results"]) if r != "ok"]
        if bad:
            kinds = sorted({r for _, r in bad}, key=str)
            why = next((reasons[0] for r in sc["runs"][m] if r.get("result") == "failed"
                        for reasons in [r.get("verdict_reasons") or []] if reasons), None)
            lines.append(f"- {md(m)}: {len(bad)} of {len(st['results'])} runs did not end ok ("
                         + "; ".join(f"{md(str(k))} on seed(s) {', '.join(str(s) for s, r in bad if r == k)}"
                                     for k in kinds)
                         + (f"; the first failure: {md(why)}" if why else "")
                         + ("); its runs stopped before the trajectory ended have no metrics: means and "
                            "comparisons cover the runs that have them, and the comparisons say on how many seeds."
                            if any(not r.get("tracking_max_abs_rad") for r in sc["runs"][m]) else
                            "); its means include them (a run the safety layer stopped counts the part it ran)."))
    for b in [x for x in ("tde", "usde-smc", "pd", "pm-paper-weights") if x in sc["pm_versus"]]:
        for metric in ("linf", "est", "power"):
            if metric == "est" and b not in ESTIMATING:
                continue
            comp = sc["pm_versus"][b][metric]
            if metric == "power":
                c = comp["total"]
                if c.get("ratio_of_means") is None:
                    continue
                lines.append(f"- {METRIC_TEXT[metric]}, PM vs {b}: {c['ratio_of_means']:.3f}x "
                             f"(PM lower on {c['a_lower']}/{c['n']} seeds).")
                continue
            wins = [labels[j] for j, c in enumerate(comp["per_joint"]) if (c.get("ratio_of_means") or np.inf) < 1]
            sig_w = [labels[j] for j, c in enumerate(comp["per_joint"])
                     if (c.get("ratio_of_means") or np.inf) < 1 and (_p(c) or 1) < ALPHA]
            sig_l = [labels[j] for j, c in enumerate(comp["per_joint"])
                     if (c.get("ratio_of_means") or 0) > 1 and (_p(c) or 1) < ALPHA]
            ratios = [c.get("ratio_of_means") for c in comp["per_joint"] if c.get("ratio_of_means") is not None]
            rng = f"{min(ratios):.2f}x-{max(ratios):.2f}x" if ratios else "-"
            tot = comp["total"]
            if not tot["n"]:
                lines.append(f"- {METRIC_TEXT[metric]}, PM vs {b}: no comparison: no seed where both have metrics.")
                continue
            lines.append(f"- {METRIC_TEXT[metric]}, PM vs {b}: PM's mean lower on {len(wins)} of {len(labels)} joints "
                         f"(ratios PM/{b} {rng}; sum of joints {tot.get('ratio_of_means') or float('nan'):.2f}x, "
                         f"PM lower on {tot['a_lower']}/{tot['n']} seeds); significantly (p < {ALPHA}) lower on "
                         f"{', '.join(sig_w) or 'none'}, significantly higher on {', '.join(sig_l) or 'none'}.")
    return lines


POWER_TIE = 0.005  # torque power ratios this close to 1 are a tie, not a win


def _claims(sc: dict[str, Any]) -> list[str]:
    """The paper's claims, checked with this scenario's evidence."""
    out = []

    def lower_everywhere(metric: str, b: str) -> tuple[int, int]:
        comp = sc["pm_versus"][b][metric]["per_joint"]
        return sum(1 for c in comp if (c.get("ratio_of_means") or np.inf) < 1), len(comp)

    def seeds_note(metric: str, b: str) -> str:
        tot = sc["pm_versus"][b][metric]["total"]
        return f" (over the {tot['n']} seed(s) where both have metrics)" if tot.get("excluded") else ""

    for table, metric, what in (("Table 1", "est", "estimation error"), ("Table 2", "linf", "L-infinity tracking error")):
        counts = {b: lower_everywhere(metric, b) for b in ("tde", "usde-smc") if b in sc["pm_versus"]}
        if counts:
            holds = all(k == total for k, total in counts.values())
            out.append(f"- {table} (PM's {what} below TDE's and EUSDE-SMC's on every joint): "
                       f"{'holds' if holds else 'does not hold'} here: PM's mean is "
                       + "; ".join(f"lower than {b}'s on {k}/{total} joints{seeds_note(metric, b)}"
                                   for b, (k, total) in counts.items()) + ".")
    pw = [(b, sc["pm_versus"][b]["power"]["total"].get("ratio_of_means")) for b in ("tde", "usde-smc")
          if b in sc["pm_versus"]]
    if pw and all(r is not None for _, r in pw):
        tie = all(abs(1.0 - r) < POWER_TIE for _, r in pw)
        holds = all(r < 1 for _, r in pw)
        verdict = (f"a tie here (within {100 * POWER_TIE:g} %)" if tie else
                   f"{'holds' if holds else 'does not hold'} here")
        out.append(f"- Table 3 (PM needs the least torque power): {verdict}: "
                   + ", ".join(f"PM/{b} {r:.4f}" for b, r in pw) + ".")
    if "gh2" in sc["stats"]:
        res = sc["stats"]["gh2"]["results"]
        runs = sc.get("runs", {}).get("gh2") or [{"result": r} for r in res]
        lost = [r for r in runs if left_tracking_bound(r)]
        stops = sum(1 for r in lost if stopped_by_following_error(r))
        how = (f" ({stops} stopped by the safety layer's following-error stop at {FOLLOWING_ERROR_STOP_DEG:.3g} deg)"
               if stops else "")
        out.append(f"- Example 1 (the generalized-H2 controller alone, no estimator, loses track under 5 % "
                   f"uncertainty): {'holds' if len(lost) == len(runs) else 'does not hold'} here: {len(lost)} of "
                   f"{len(runs)} gh2 runs diverged or left the tracking bound{how} (results: "
                   f"{', '.join(sorted(set(res)))}).")
    return out


def _how_run(study: dict[str, Any]) -> str:
    bus = study.get("bus", "udp")
    return ("software in the loop (arm_sil: the controller and the drives in one process, frames in memory)"
            if bus == "sil" else f"lockstep HIL over the CAN bus ({bus})")


def _confirmation(study: dict[str, Any]) -> list[str]:
    """What the software-in-the-loop runs were checked against."""
    conf = study.get("confirmation")
    if not conf:
        return []
    rows = conf["runs"]
    ok = sum(r["match"] for r in rows)
    head = (f"Confirmed over the CAN bus: {ok} of {len(rows)} runs repeated in lockstep HIL "
            f"({rows[0]['bus'] if rows else '-'}) gave the same results bit for bit"
            if conf["all_match"] else
            f"**Software in the loop and lockstep HIL disagree**: {len(rows) - ok} of {len(rows)} repeated runs differ")
    return [head + ":", "", *[f"- {md(r['method'])} in {code(r['scenario'])}, seed {r['seed']}: "
                              + ("same" if r["match"] else "differs in " + md(", ".join(r["differences"]))) for r in rows],
            ""]


def _trajectory_lines(study: dict[str, Any]) -> list[str]:
    """The reference every run followed: q_d = home + a (1 - cos 2 pi f t), per joint."""
    t = study.get("trajectory") or {}
    if not t.get("amp"):
        return []
    names = study["arm"]["joint_names"]
    return [f"Trajectory ({md(str(t.get('from', 'the config')))}): q_d = home + a (1 - cos 2 pi f t), "
            + "; ".join(f"{code(n)} a {a:g} rad, f {f:g} Hz" for n, a, f in zip(names, t["amp"], t["freq_hz"])) + "."]


def drivetrain_table(study: dict[str, Any]) -> str:
    """The arm's joints as the simulator makes them (gen/drivetrain.py) and each one's first
    resonance at home: what bounds the gains a real arm survives."""
    rows = [[md(j["name"]), md(str(j["size"])), f"{j['stiffness']:.3g}", f"{j['damping']:.3g}", f"{j['rotor_inertia']:.3g}",
             f"{j['link_inertia_at_home']:.3g}", f"{j['resonance_locked_hz']:.1f}",
             f"{j['resonance_free_hz']:.1f}" if j["resonance_free_hz"] is not None else "-",
             "flexible" if j["flexible"] else f"rigid: {md(str(j['rigid_because']))}"] for j in study["arm"]["drivetrain"]]
    return _md_table(["joint", "gear size", "stiffness (N m/rad)", "damping (N m s/rad)", "rotor inertia (kg m^2)",
                      "link inertia at home (kg m^2)", "resonance, motor locked (Hz)", "motor free (Hz)", "simulated"],
                     rows)


def _drivetrain_lines(study: dict[str, Any]) -> list[str]:
    arm = study["arm"]
    if not arm.get("drivetrain"):
        return []
    pay = arm.get("payload") or {}
    return ["## The arm's joints", "",
            "Each joint of the flexible scenarios is a rotor behind its gear, a strain-wave gear's spring and damper, "
            "then the link (gen/drivetrain.py); the controller's nominal model stays rigid. First resonances at the "
            "home pose, each joint on its own (the others held): motor locked sqrt(K / J_link), motor free "
            "sqrt(K (1 / J_link + 1 / J_rotor)).", "", drivetrain_table(study), "",
            f"The arm's first resonance: {arm['first_resonance_hz']:.1f} Hz ({2 * np.pi * arm['first_resonance_hz']:.0f} "
            "rad/s). Every tuned pick's closed-loop bandwidth is kept below it (each scenario's tuning table). Rated "
            f"payload {pay.get('rated_kg', 0):g} kg, at {md(str(pay.get('at', '-')))}.", ""]


def recommendation(study: dict[str, Any], name: str) -> str:
    """Which method to pick in one scenario, and by how much it wins, in words: among the methods
    whose every run ended ok, the lowest mean over the seeds of the sum over joints of the
    L-infinity tracking error, against the next best and against PM on the same seeds."""
    from tools.study.stats import paired

    sc = study["scenarios"][name]
    total = {m: sc["stats"][m]["linf"]["total"] for m in study["methods"]}
    clean = [m for m in study["methods"] if all(r == "ok" for r in sc["stats"][m]["results"])
             and total[m]["mean"] is not None]
    others = [m for m in study["methods"] if m not in clean]
    why_not = f" ({', '.join(f'{md(m)}: not every run ended ok' for m in others)})" if others else ""
    if not clean:
        return f"- {code(name)}: no method ran ok on every seed{why_not}."
    ranked = sorted(clean, key=lambda m: total[m]["mean"])
    best = ranked[0]

    def against(m: str) -> str:
        c = paired(total[best]["values"], total[m]["values"])
        p = f", p {c['t_test_p']:.2g}" if c.get("t_test_p") is not None else ""
        return f"{c['ratio_of_means']:.2f}x {md(m)}'s (lower on {c['a_lower']}/{c['n']} seeds{p})"

    bw = (sc.get("bandwidth_hz") or {}).get(best)
    res = study["arm"].get("first_resonance_hz")
    band = f"; its closed-loop bandwidth {bw:.3g} Hz, {bw / res:.2f}x the first resonance" if bw and res else ""
    cmp = [against(m) for m in ranked[1:2]] + ([against("pm")] if best != "pm" and "pm" in clean[1:] and
                                               ranked[1] != "pm" else [])
    return (f"- {code(name)}: pick **{md(best)}**: its L-infinity tracking error summed over the joints is "
            f"{np.degrees(total[best]['mean']):.3g} deg on average over {total[best]['n']} seeds"
            + (", " + " and ".join(cmp) if cmp else "") + f"{band}. Every run ended ok for "
            f"{', '.join(map(md, ranked))}{why_not}.")


def _bandwidth_cell(sc: dict[str, Any], m: str, resonance: float | None) -> str:
    bw = (sc.get("bandwidth_hz") or {}).get(m)
    if bw is None:
        return "-"
    if not resonance:
        return f"{bw:.3g} Hz"
    return f"{bw:.3g} Hz ({bw / resonance:.2f}x the first resonance)"


def _shown(path: Path) -> str:
    """A path as a command in the report names it: from the repository's root when inside it."""
    from gen.lib.paths import REPO

    p = path.resolve()
    return str(p.relative_to(REPO)) if p.is_relative_to(REPO) else str(p)


def _remove_figures(out: Path, scenarios: list[str]) -> None:
    """A report without figures leaves none beside it of an earlier study of these scenarios in
    the same folder: every figure there is the report's."""
    for s in scenarios:
        png = fig_name("*", s)
        for f in [*out.glob(png), *out.glob(png.removesuffix(".png") + ".json")]:  # the arm strip's record too
            f.unlink()


Images = Callable[[str, str], list[str]]


def _paper_table(sc: dict[str, Any], labels: list[str], n: int, metric: str, ours: str,
                 paper_table: dict[str, list[float]]) -> str:
    """This scenario's per-joint means of `metric` for PM, TDE and USDE-SMC beside one of the paper's tables."""
    methods = ("pm", "tde", "usde-smc")
    return _md_table(["joint", *[f"{ours} {m}" for m in ("PM", "TDE", "USDE-SMC")],
                      "paper PM", "paper TDE", "paper EUSDE-SMC"],
                     [[labels[j], *[_fmt(sc["stats"][m][metric]["per_joint"][j]["mean"]) if m in sc["stats"] else "-"
                                    for m in methods],
                       *[_fmt(paper_table[m][j]) for m in methods]] for j in range(n)])


def _beside_the_paper(sc: dict[str, Any], labels: list[str], n: int) -> list[str]:
    return ["### Beside the paper's numbers", "",
            "The paper's Table 1 is its simulation (its units and uncertainty), Tables 2-3 its hardware "
            "experiment; ours are this scenario's means.", "",
            _paper_table(sc, labels, n, "est", "est", PAPER_TABLE1), "",
            _paper_table(sc, labels, n, "linf", "L-inf", PAPER_TABLE2), "",
            f"Torque power, the paper: PM {PAPER_TABLE3['pm']} W, TDE {PAPER_TABLE3['tde']} W, EUSDE-SMC "
            f"{PAPER_TABLE3['usde-smc']} W.", ""]


def _report_head(study: dict[str, Any], figures: bool, images: Images) -> list[str]:
    """The answer, how the study was run, and what to pick per scenario."""
    from tools.study.answer import answer

    arm = study["arm"]
    n = arm["n_joints"]
    wiring = ", ".join(f"{md(b['name'])}: drives {','.join(map(str, b['drives']))}" for b in arm["buses"])
    return [f"# Study: {md(study['description'])}", "",
            "## The answer", "", *answer(study), "",
            "Means over the seeds per scenario and method (the detail of each is in its scenario's section):", "",
            markdown_fence(summary_table(study).splitlines()), "", *images(ANSWER_FIGURE, ANSWER_FIGURE),
            "## How the study was run", "",
            f"Arm {code(arm['name'])} ({n} joints: {', '.join(map(code, arm['joint_names']))}; model "
            f"{code(arm['model'])}, hash {md(arm['model_hash'])}), its CAN buses {wiring}, {md(_how_run(study))} at "
            f"{loop_rate_hz(study) / 1000:g} kHz. Config {code(study['config'])}; "
            f"seeds {study['seeds']}; trajectory {study['duration_s']:g} s after a {study['hold_s']:g} s hold on the "
            "start pose (metrics cover the trajectory only). Intervals are 95 % confidence intervals of the mean over "
            "the seeds (Student's t); PM against another method is paired on the same seeds: the ratio of the means, "
            "on how many seeds PM was lower, and the p-value of the paired t-test (two-sided; study.json also has "
            "Wilcoxon's signed-rank p, which with 5 seeds cannot go below 0.0625).",
            "", *_trajectory_lines(study),
            "", f"Tuning: {md(study['tuning_procedure'])}", "", *_confirmation(study),
            *([] if figures else ["Figures: not drawn (`--no-figures`).", ""]),
            *(["Notes:", "", *[f"- {md(x)}" for x in study.get("notes", [])], ""] if study.get("notes") else []),
            *_drivetrain_lines(study),
            "## What to pick, in detail", "",
            "Per scenario, the method with the lowest mean tracking error (the sum over joints of the L-infinity "
            "error, the tuning's objective) among those whose every run ended ok, against the next best and PM on the "
            "same seeds (paired t-test):", "",
            *[recommendation(study, name) for name in study["scenarios"]], ""]


def _scenario_intro(study: dict[str, Any], name: str, sc: dict[str, Any], labels: list[str]) -> list[str]:
    """A scenario's definition, its verdict, the command that runs one of its runs again, and the paper's claims."""
    d = sc["definition"]
    text = [f"## Scenario {code(name)}", "", md(d["description"]), "",
            f"Uncertainty {code(str(d['uncertainty']))}; drives {code(str(d['drives']))}, speaking "
            f"{PROTOCOL_TEXT[study.get('protocol') or d.get('protocol', STUDY_PROTOCOL)]}"
            + (" (every scenario's runs, with the picks tuned on its own protocol)" if study.get("protocol") else "")
            + f"; bus timing {'emulated' if d['bus_timing'] else 'not emulated'}.", "",
            *([f"Per-joint values on this arm from the config's {code(str(d['per_joint_from']))}.", ""]
              if d.get("per_joint_from") else []), "### Verdict", ""]
    text += _verdict(study, sc, labels) + [""]
    if study.get("commands", {}).get(name):
        text += [f"One run again on its own (SEED: one of {study['seeds']}; the same run.json results):", "",
                 markdown_fence(study["commands"][name].values(), "sh"), ""]
    return text + ["The paper's claims, with this scenario's evidence:", ""] + _claims(sc) + [""]


def _tuning_section(study: dict[str, Any], name: str, sc: dict[str, Any], images: Images) -> list[str]:
    resonance = study["arm"].get("first_resonance_hz")
    return ["### Tuning", "", _md_table(
              ["method", "knobs", "closed-loop bandwidth", "objective (worst seed's sum L-inf, rad)", "trials",
               "validation", "source", "note"],
              [[md(m), code(str({k: (round(v, 4) if isinstance(v, float) else v) for k, v in r['knobs'].items()})),
                _bandwidth_cell(sc, m, resonance), _fmt(r["objective"]), md(_tuning_status(r)),
                md(str((r.get("validation") or {}).get("note", "-"))), md(str(r.get("source", ""))),
                md(str(r.get("edge_note") or (f"no trial ended well; the best: {r['failed']}" if r.get("failed") else "")))]
               for m, r in sc["tuning"].items()]), "",
            "pm-paper-weights: the paper's own weights (gen/configs/paper.toml), not tuned; its closed-loop "
            f"bandwidth: {_bandwidth_cell(sc, 'pm-paper-weights', resonance)}. Every trial is in "
            "study.json; the Optuna studies in the tuning's SQLite storage (optuna-dashboard opens it).", "",
            *images(name, "tuning"), ""]


def _metric_sections(study: dict[str, Any], sc: dict[str, Any], labels: list[str]) -> list[str]:
    text: list[str] = []
    for metric in ("linf", "rms", "est", "power"):
        text += [f"### {METRIC_TEXT[metric]}", "", _stats_table(study, sc, metric, labels), "",
                 "PM against each method (ratio of means PM/other, seeds PM lower, p):", "",
                 _paired_table(study, sc, metric, labels), ""]
    return text


def _scenario_figures(out: Path, study: dict[str, Any], name: str, drawn: dict[Any, Any], images: Images) -> list[str]:
    """Its distribution and time series, and the arm in its worst run whose telemetry is kept."""
    text = [*images(name, "distribution"), "", f"Time series, the first seed of {code(name)}:", "",
            *images(name, "time"), ""]
    worst = worst_kept_run(study, name)
    if worst and drawn.get((name, "arm")):
        render = shell_command(["tools/armctl", "render", _shown(out / name / worst[0] / f"seed-{worst[1]}")])
        text += [f"The arm in the worst run of {code(name)} whose telemetry is kept (seed {worst[1]}): "
                 f"{md(worst[0])}, {md(worst[2])}. Solid: the arm as simulated; translucent, beside it: the "
                 f"commanded reference ({code(render)} makes its video):", "", *images(name, "arm"), ""]
    return text


def write_report(out: Path, study: dict[str, Any], figures: bool = True) -> None:
    """report.md, report.html (the same, one self-contained page, its figures interactive) and
    summary.txt, and the figures unless `figures` is False (`--no-figures`)."""
    if figures:
        from tools.study.figures import draw_figures  # matplotlib: only when there are figures to draw

        drawn = draw_figures(out, study)
    else:
        drawn = {}
        _remove_figures(out, [*study["scenarios"], "all"])  # "all": the study's own figure (fig_answer_all)

    def images(name: str, kind: str) -> list[str]:  # a paragraph each (report.html puts a figure in its place)
        return [line for f, _ in drawn.get((name, kind), []) for line in ("", f"![{f}]({f})", "")]

    n = study["arm"]["n_joints"]
    paper = study["arm"]["is_default"] and n == 6  # the paper's numbers are for its six-joint arm
    labels = _labels(study, paper)
    text = _report_head(study, figures, images)
    for name, sc in study["scenarios"].items():
        text += _scenario_intro(study, name, sc, labels)
        text += _tuning_section(study, name, sc, images)
        text += _metric_sections(study, sc, labels) + [*images(name, "metrics"), ""]
        if paper and name == next(iter(study["scenarios"])):
            text += _beside_the_paper(sc, labels, n)
        if figures:
            text += _scenario_figures(out, study, name, drawn, images)
    write_text_atomic(out / "report.md", "\n".join(text))
    write_text_atomic(out / "summary.txt", summary_table(study) + "\n")
    from tools.study.html_report import write_html

    write_html(out, study, "\n".join(text), {f: fig for figs in drawn.values() for f, fig in figs if fig is not None})


def summary_table(study: dict[str, Any]) -> str:
    """Per scenario and method: the mean L-infinity error per joint (deg), the mean estimation
    error and power, and how the runs ended."""
    n = study["arm"]["n_joints"]
    width = 7 * n + 2
    lines = []
    for name, sc in study["scenarios"].items():
        lines.append(f"{one_line(name)} ({len(study['seeds'])} seed(s); means)")
        lines.append(f"  {'method':<17}{f'Linf e (deg), joints 1-{n}':<{width}}{'RMS w-w_hat':>12}{'power W':>9}  runs")
        for m in study["methods"]:
            st = sc["stats"][m]
            linf = " ".join(f"{np.degrees(s['mean']):6.3f}" if s["mean"] is not None and np.isfinite(s["mean"])
                            else "     -" for s in st["linf"]["per_joint"])
            est = st["est"]["total"]["mean"]
            est_s = f"{est / n:.4f}" if m in ESTIMATING and est is not None and np.isfinite(est) else "-"
            pw = st["power"]["total"]["mean"]
            pw_s = f"{pw:.2f}" if pw is not None and np.isfinite(pw) else "-"
            res = st["results"]
            ends = ", ".join(f"{res.count(r)} {r}" for r in sorted(set(res), key=str))
            lines.append(f"  {one_line(m):<17}{linf:<{width}}{est_s:>12}{pw_s:>9}  {one_line(ends)}")
    return "\n".join(lines)


