"""The study's headline, kept in the repository: `tools/armctl study --record` writes the default
study's per-run results and statistics to tools/studies/paper.headline.json and renders the README's
result tables from it (between the headline markers). tests/python/test_headline.py holds the
README to the record, and reruns a slice of the record (one scenario, one seed, two methods, the
full trajectory) bit for bit: the README's numbers cannot drift from the code at HEAD."""

from __future__ import annotations

from pathlib import Path
from typing import Any

from gen.lib.atomic_output import write_json_atomic, write_text_atomic
from gen.lib.escape import markdown_fence
from tools.build.code_identity import code_identity
from gen.lib.paths import REPO

RECORD = REPO / "tools" / "studies" / "paper.headline.json"
# the same study over the arm protocol with the same picks (study --protocol arm --record): what the
# protocol alone changes, beside the headline in the docs
RECORD_BY_PROTOCOL = {"arm": REPO / "tools" / "studies" / "paper.headline-arm-protocol.json"}
README = REPO / "README.md"
BEGIN = "<!-- headline: tools/armctl study --record writes this table (tools/study/headline.py) -->"
END = "<!-- /headline -->"
# What a run's record keeps: its verdict and the numbers the tables and the slice test compare.
RUN_FIELDS = ("result", "steps", "tracking_max_abs_rad", "tracking_rms_rad", "estimation_error_rms",
              "torque_power_w", "saturated_fraction",
              # what the report's findings read (docs/study.md renders them from this record)
              "verdict_reasons", "final_fault", "tracking_max_abs_deg", "bounds")


class HeadlineError(RuntimeError):
    pass


def record_of(study: dict[str, Any]) -> dict[str, Any]:
    """What summary_table needs (tools/study/report.py) and the runs' own numbers."""
    return {"config": study["config"], "code": code_identity(), "seeds": study["seeds"],
            "duration_s": study["duration_s"], "methods": study["methods"], "bus": study.get("bus"),
            "protocol": study.get("protocol"),
            "arm": {k: study["arm"][k] for k in ("name", "n_joints", "joint_names", "drivetrain",
                                                   "first_resonance_hz", "payload")},
            "scenarios": {s: {"runs": {m: [{k: r.get(k) for k in RUN_FIELDS} for r in runs]
                                       for m, runs in sc["runs"].items()},
                              "stats": sc["stats"],
                              "pm_versus": sc.get("pm_versus", {}),  # the report's comparisons (docs/study.md)
                              "bandwidth_hz": sc.get("bandwidth_hz", {}),
                              "definition": sc["definition"]}
                          for s, sc in study["scenarios"].items()}}


def render(record: dict[str, Any]) -> str:
    from tools.study.report import summary_table

    return markdown_fence(summary_table(record).splitlines())


def marked_block(text: str, begin: str, end: str) -> str | None:
    """What a page holds between two marker lines (a rendered block), or None without them."""
    try:
        start = text.index(begin) + len(begin)
        return text[start:text.index(end, start)].strip("\n")
    except ValueError:
        return None


def readme_block(text: str) -> str:
    block = marked_block(text, BEGIN, END)
    if block is None:
        raise HeadlineError(f"{README}: the headline markers ({BEGIN} ... {END}) are missing")
    return block


def write(study: dict[str, Any], readme: Path = README) -> None:
    record = record_of(study)
    if study.get("protocol"):  # another protocol's study: its own record, not the headline
        write_json_atomic(RECORD_BY_PROTOCOL[study["protocol"]], record)
        return
    text = readme.read_text()
    old = readme_block(text)
    write_json_atomic(RECORD, record)
    write_text_atomic(readme, text.replace(old, render(record), 1))
