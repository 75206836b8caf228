"""Closed-loop bandwidths (tools/study/bandwidth.py): the -3 dB frequency of the input's
complementary sensitivity of each method's loop, checked against what is known in closed form and
against the methods' structure; and the tuning's rule that refuses a candidate above the arm's
first resonance."""

from __future__ import annotations

import math

import numpy as np
import pytest

from tools.study import bandwidth
from tools.study.config import usde_smc_gains

T = 1e-3


def _pd(wn: float, zeta: float) -> float:
    return bandwidth.bandwidth_hz(bandwidth.method_loop("pd", {"kp": wn * wn, "kd": 2 * zeta * wn}, None, T), T)


def _continuous_pd_bandwidth(wn: float, zeta: float) -> float:
    """|T(jw)| = |(kd jw + kp) / (-w^2 + kd jw + kp)| = 1/sqrt(2), solved in w^2 (Hz)."""
    kp, kd = wn * wn, 2 * zeta * wn
    # 2 (kp^2 + kd^2 w^2) = (kp - w^2)^2 + kd^2 w^2  ->  w^4 - (2 kp + kd^2) w^2 - kp^2 = 0
    b = 2 * kp + kd * kd
    w2 = (b + math.sqrt(b * b + 4 * kp * kp)) / 2
    return math.sqrt(w2) / (2 * math.pi)


@pytest.mark.parametrize("wn, zeta", [(10.0, 1.0), (20.0, 0.7), (5.0, 2.0)])
def test_pd_bandwidth_is_the_continuous_one_well_below_nyquist(wn: float, zeta: float) -> None:
    assert _pd(wn, zeta) == pytest.approx(_continuous_pd_bandwidth(wn, zeta), rel=0.02)


def test_bandwidth_grows_with_the_gains_and_is_capped_at_nyquist() -> None:
    bws = [_pd(wn, 1.0) for wn in (5.0, 20.0, 80.0, 320.0)]
    assert bws == sorted(bws) and bws[0] < bws[-1]
    assert _pd(5000.0, 1.0) == 0.5 / T  # the loop answers everything the period can carry


def test_an_estimator_raises_the_bandwidth_to_its_own() -> None:
    """TDE and USDE cancel w through their estimators: a fast estimator makes a fast loop around a
    slow PD, which is why the tuning bounds every method's bandwidth, not its wn."""
    pd = _pd(5.0, 1.0)
    slow = bandwidth.bandwidth_hz(bandwidth.method_loop("tde", {"kp": 25, "kd": 10, "tde_cutoff": 2.0}, None, T), T)
    fast = bandwidth.bandwidth_hz(bandwidth.method_loop("tde", {"kp": 25, "kd": 10, "tde_cutoff": 40.0}, None, T), T)
    assert pd < slow < fast and fast > 20.0
    lam, ks = usde_smc_gains(5.0, 1.0)
    usde = [bandwidth.bandwidth_hz(bandwidth.method_loop("usde-smc", {"smc_lambda": lam, "smc_ks": ks, "smc_eta": 1,
                                                                      "smc_phi": 0.05, "usde_k": k}, None, T), T)
            for k in (0.1, 0.01)]
    assert usde[0] < usde[1]


@pytest.mark.parametrize("method, args", [
    ("pd", {"kp": 400.0, "kd": 40.0}),
    ("tde", {"kp": 400.0, "kd": 40.0, "tde_cutoff": 10.0}),
    ("usde-smc", {"smc_lambda": 10.0, "smc_ks": 10.0, "smc_eta": 1.0, "smc_phi": 0.05, "usde_k": 0.02}),
])
def test_each_loop_is_stable_and_cancels_a_constant_w(method: str, args: dict[str, float]) -> None:
    """Every method holds its joint against a constant disturbance: its loop is stable and, at
    zero frequency, the control answers w with all of it (|T_i(1)| = 1)."""
    sys = bandwidth.method_loop(method, args, None, T)
    assert max(abs(np.linalg.eigvals(sys.A))) < 1.0
    z = 1.0
    dc = sys.C @ np.linalg.solve(z * np.eye(sys.A.shape[0]) - sys.A, sys.B) + sys.D
    assert abs(dc[0, 0]) == pytest.approx(1.0, abs=1e-6)


def test_the_tuning_refuses_a_candidate_above_the_resonance() -> None:
    from tools.study.tuning import TuneSetup, candidate_check
    from tools.study.config import load
    from tools.study import DEFAULT_CONFIG

    setup = TuneSetup(load(DEFAULT_CONFIG), {}, "", [], None, resonance_hz=20.0, period_s=T)  # type: ignore[arg-type]
    why, bw = candidate_check(setup, "pd", {"wn": 100.0, "zeta": 1.0})
    assert bw is not None and bw > 20.0 and "not below the arm's first resonance 20 Hz" in why
    why, bw = candidate_check(setup, "pd", {"wn": 5.0, "zeta": 1.0})
    assert why == "" and bw is not None and bw < 20.0
