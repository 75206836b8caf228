"""The study's answer in plain words: which method to pick on this arm in each scenario, by how much
it wins, and where the paper's method stands. The first thing report.md and report.html say, and
the opening of docs/study.md (rendered from the headline record by tools/armctl docs), so the words
follow the numbers whenever the study is recorded again."""

from __future__ import annotations

from typing import Any

import numpy as np

from gen.lib.escape import markdown_code as code, markdown_text as md

PAPER_METHOD = "pm"  # the paper's method, with its structure corrected (tools/study/config.py METHODS)


def ranking(study: dict[str, Any], scenario: str) -> tuple[list[str], list[str]]:
    """(methods whose every run ended ok, best first by the mean over the seeds of the sum over
    joints of the L-infinity tracking error: the tuning's objective; the other methods)."""
    sc = study["scenarios"][scenario]
    total = {m: sc["stats"][m]["linf"]["total"]["mean"] for m in study["methods"]}
    clean = [m for m in study["methods"]
             if total[m] is not None and all(r == "ok" for r in sc["stats"][m]["results"])]
    return sorted(clean, key=lambda m: total[m]), [m for m in study["methods"] if m not in clean]


def _error(study: dict[str, Any], scenario: str, m: str) -> float:
    return float(study["scenarios"][scenario]["stats"][m]["linf"]["total"]["mean"])


def _margin(study: dict[str, Any], scenario: str, best: str, other: str) -> str:
    """How much lower best's error is than other's, in words, and whether the seeds bear it out
    (the paired t-test on the same seeds)."""
    from tools.study.stats import paired

    totals = study["scenarios"][scenario]["stats"]
    c = paired(totals[best]["linf"]["total"]["values"], totals[other]["linf"]["total"]["values"])
    a, b = _error(study, scenario, best), _error(study, scenario, other)
    p = c.get("t_test_p")
    sure = ("" if p is None else f", lower on {c['a_lower']} of {c['n']} seeds"
            + (f", p {p:.2g}: not significant" if p >= 0.05 else ""))
    return f"{100.0 * (1.0 - a / b):.0f} % below the next best ({md(other)}{sure})"


def scenario_answer(study: dict[str, Any], scenario: str) -> str:
    """One scenario's answer: the pick, its margin over the next best, and the paper's method."""
    ranked, failed = ranking(study, scenario)
    name = f"**{code(scenario)}**"
    if not ranked:
        return f"- {name}: no method ran ok on every seed; none can be recommended here."
    best = ranked[0]
    e = _error(study, scenario, best)
    words = [f"- {name}: use **{md(best)}**, {np.degrees(e):.2g} deg of tracking error"]
    if len(ranked) > 1:
        words.append(f", {_margin(study, scenario, best, ranked[1])}")
    if best == PAPER_METHOD:
        words.append("; the paper's method is the pick here")
    elif PAPER_METHOD in ranked:
        words.append(f"; the paper's method ({md(PAPER_METHOD)}) has "
                     f"{_error(study, scenario, PAPER_METHOD) / e:.2f}x its error")
    elif PAPER_METHOD in failed:
        words.append(f"; the paper's method ({md(PAPER_METHOD)}) did not end ok on every seed")
    dropped = [m for m in failed if m != PAPER_METHOD]
    if dropped:
        words.append(f"; {', '.join(map(md, dropped))} did not end ok on every seed")
    return "".join(words) + "."


def answer(study: dict[str, Any]) -> list[str]:
    """The whole answer, as Markdown lines: one sentence for the arm, one line per scenario, and
    how often the paper's method is the pick."""
    scenarios = list(study["scenarios"])
    picks = [s for s in scenarios if (ranking(study, s)[0] or [None])[0] == PAPER_METHOD]
    seeds = len(study["seeds"])
    head = (f"On the arm {code(study['arm']['name'])}, per scenario, the method with the lowest tracking error (the "
            f"L-infinity error summed over the joints, mean over {seeds} seed(s)) among those whose every run ended ok:")
    paper = (f"The paper's method ({md(PAPER_METHOD)}) is the pick in "
             + (f"{len(picks)} of the {len(scenarios)} scenario(s): {', '.join(map(code, picks))}." if picks else
                f"none of the {len(scenarios)} scenario(s)."))
    return [head, "", *[scenario_answer(study, s) for s in scenarios], "", paper]
