"""Statistics over seeds when some runs measured nothing (stopped early: NaN metrics)."""

from __future__ import annotations

import math

import pytest

from tools.study.stats import paired, summary


def test_summary_covers_the_values_there_are_and_counts_the_missing() -> None:
    s = summary([1.0, float("nan"), 3.0])
    assert s["n"] == 2 and s["missing"] == 1 and s["mean"] == 2.0
    # Student's t with one degree of freedom is Cauchy's: its 97.5 % point is tan(0.475 pi); sd of 1 and 3 is sqrt 2
    half = math.tan(0.475 * math.pi) * math.sqrt(2) / math.sqrt(2)
    assert s["sd"] == pytest.approx(math.sqrt(2)) and s["ci95"] == pytest.approx([2.0 - half, 2.0 + half]), s
    assert s["values"] == [1.0, None, 3.0]  # JSON null, and equal to itself (NaN is not)
    assert summary([float("nan")])["mean"] is None


def test_paired_compares_only_seeds_where_both_have_a_value() -> None:
    c = paired([1.0, 2.0, 5.0, 1.0], [2.0, float("nan"), 6.0, 3.0])
    assert c["n"] == 3 and c["excluded"] == 1 and c["a_lower"] == 3
    assert math.isclose(c["ratio_of_means"], (1 + 5 + 1) / (2 + 6 + 3))
    assert c["mean_difference"] == pytest.approx(-4 / 3) and c["a_lower_fraction"] == 1.0
    # the paired t-test of the differences -1, -1, -2: t = -4 on 2 degrees of freedom, whose
    # two-sided p is 1 - t / sqrt(2 + t^2) in closed form (a test of unpaired samples gives another)
    assert c["t_test_p"] == pytest.approx(1 - 4 / math.sqrt(18)), c
    assert 0.0 < c["wilcoxon_p"] <= 1.0, c
    none = paired([1.0], [float("nan")])
    assert none["n"] == 0 and none["ratio_of_means"] is None
