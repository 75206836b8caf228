"""Statistics over seeds when some runs measured nothing (stopped early: NaN metrics)."""

from __future__ import annotations

import math

from tools.study.stats import paired, summary


def test_summary_covers_the_values_there_are_and_counts_the_missing() -> None:
    s = summary([1.0, float("nan"), 3.0])
    assert s["n"] == 2 and s["missing"] == 1 and s["mean"] == 2.0 and s["ci95"] is not None
    assert s["values"] == [1.0, None, 3.0]  # JSON null, and equal to itself (NaN is not)
    assert summary([float("nan")])["mean"] is None


def test_paired_compares_only_seeds_where_both_have_a_value() -> None:
    c = paired([1.0, 2.0, 5.0, 1.0], [2.0, float("nan"), 6.0, 3.0])
    assert c["n"] == 3 and c["excluded"] == 1 and c["a_lower"] == 3
    assert math.isclose(c["ratio_of_means"], (1 + 5 + 1) / (2 + 6 + 3))
    none = paired([1.0], [float("nan")])
    assert none["n"] == 0 and none["ratio_of_means"] is None
