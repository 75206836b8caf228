"""Statistics over seeds: the mean with a 95 % confidence interval (Student's t), and paired
comparisons of two methods on the same seeds (the fraction of seeds one wins, a paired t-test and
Wilcoxon's signed-rank test)."""

from __future__ import annotations

import math
import warnings
from typing import Any

import numpy as np


def summary(values: list[float]) -> dict[str, Any]:
    """mean, ci95 [low, high] (None for a single value), sd, n, and the values themselves, over
    the values there are: a NaN (a run stopped before it measured) is counted in `missing` and
    listed as None."""
    every = np.asarray(values, dtype=float)
    x = every[np.isfinite(every)]
    n, missing = int(x.size), int(every.size - x.size)
    listed = [float(v) if math.isfinite(v) else None for v in every]
    if n == 0:
        return {"n": 0, "missing": missing, "mean": None, "ci95": None, "sd": None, "values": listed}
    mean = float(x.mean())
    if n < 2:
        return {"n": n, "missing": missing, "mean": mean, "ci95": None, "sd": None, "values": listed}
    from scipy import stats

    sd = float(x.std(ddof=1))
    half = float(stats.t.ppf(0.975, n - 1)) * sd / math.sqrt(n)
    return {"n": n, "missing": missing, "mean": mean, "ci95": [mean - half, mean + half], "sd": sd,
            "values": listed}


def paired(a: list[float], b: list[float]) -> dict[str, Any]:
    """a against b on the same seeds (lower is better), over the seeds where both have a value
    (`excluded` counts the others): how often a is lower, the ratio of the means, and the
    p-values of a paired t-test and of Wilcoxon's signed-rank test (two-sided; None where they
    are undefined: one seed, or no differences)."""
    x, y = np.asarray(a, dtype=float), np.asarray(b, dtype=float)
    both = np.isfinite(x) & np.isfinite(y)
    excluded = int(x.size - np.sum(both))
    x, y = x[both], y[both]
    n = int(x.size)
    out: dict[str, Any] = {"n": n, "excluded": excluded, "a_lower": int(np.sum(x < y)), "a_lower_fraction": float(np.mean(x < y)) if n else None,
                           "ratio_of_means": float(x.mean() / y.mean()) if n and y.mean() != 0 else None,
                           "mean_difference": float((x - y).mean()) if n else None, "t_test_p": None, "wilcoxon_p": None}
    d = x - y
    if n >= 2 and np.all(np.isfinite(d)) and np.any(d != 0):
        from scipy import stats

        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            out["t_test_p"] = _p(stats.ttest_rel(x, y).pvalue)
            out["wilcoxon_p"] = _p(stats.wilcoxon(x, y).pvalue)
    return out


def _p(v: float) -> float | None:
    return float(v) if v is not None and math.isfinite(v) else None
