"""Each method's closed-loop bandwidth on the nominal arm: the highest frequency at which its
control answers an input disturbance w with at least 1/sqrt(2) of it, |T_i| = |u / w| >= -3 dB.
T_i is the input complementary sensitivity of the loop e_ddot = u + w that inverse dynamics make
of each joint, at the loop period (zero-order hold), in the firmware's own structures:

- pd: u = -(kp e + kd e_dot);
- tde: that PD minus w_hat, the last period's w (known one period later, from velocity
  differences) low-passed at cutoff_hz: w_hat' = a w_hat + (1 - a) w(k - 1);
- usde-smc: its sliding-mode law inside the boundary layer, where it is linear (a PD with
  kp = (eta/phi + ks) lambda, kd = lambda + eta/phi + ks), minus the USDE estimate (w through the
  first-order filter of time constant k, as firmware/core/src/baselines.c computes it);
- pm, pm-paper, gh2: the synthesised C and K in their structure (gen/synth/loops.py).

A gear's first resonance within that bandwidth is excited by the control: the tuning keeps every
pick below the arm's first resonance (tools/study/tuning.py), and the report gives both.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from gen.synth.discretize import double_integrator_zoh
from gen.synth.loops import combined_loop
from gen.synth.ss import StateSpace

HALF_POWER = 1.0 / math.sqrt(2.0)
GRID = 400  # log-spaced frequencies from F_LOW to Nyquist, then the crossing refined
F_LOW = 0.01  # Hz
PM_STRUCTURE = {"pm": "decoupled", "pm-paper": "paper", "gh2": None}  # the firmware's (methods.c)


def _pd_loop(kp: float, kd: float, T: float) -> StateSpace:
    p = double_integrator_zoh(1, T)
    K = np.array([[kp, kd]])
    return StateSpace(p.A - p.B @ K, p.B, K, np.zeros((1, 1)))


def _tde_loop(kp: float, kd: float, cutoff_hz: float, T: float) -> StateSpace:
    """States [e, e_dot, w_hat, w(k-1)]."""
    p = double_integrator_zoh(1, T)
    a = math.exp(-2.0 * math.pi * cutoff_hz * T)
    K = np.array([[kp, kd]])
    A = np.zeros((4, 4))
    A[:2, :2] = p.A - p.B @ K
    A[:2, 2:3] = -p.B
    A[2, 2], A[2, 3] = a, 1.0 - a
    B = np.vstack([p.B, [[0.0]], [[1.0]]])
    C = np.array([[kp, kd, 1.0, 0.0]])
    return StateSpace(A, B, C, np.zeros((1, 1)))


def _usde_smc_loop(lam: float, ks: float, eta: float, phi: float, k: float, T: float) -> StateSpace:
    """States [e, e_dot, x_f, a_f] (q_d held: qd = -e_dot, the commanded acceleration -u)."""
    p = double_integrator_zoh(1, T)
    g = eta / phi + ks
    a = math.exp(-T / k)
    w_hat = np.array([0.0, 1.0 / k, 1.0 / k, 1.0])
    u = np.array([-g * lam, -(lam + g), 0.0, 0.0]) - w_hat
    A = np.zeros((4, 4))
    A[:2, :] = np.hstack([p.A, np.zeros((2, 2))]) + p.B @ u[None, :]
    A[2] = [0.0, -(1.0 - a), a, 0.0]
    A[3] = -(1.0 - a) * u + np.array([0.0, 0.0, 0.0, a])
    B = np.vstack([p.B, [[0.0]], [[0.0]]])
    return StateSpace(A, B, -u[None, :], np.zeros((1, 1)))


def _design_loop(design: Any, method: str, T: float) -> StateSpace:
    structure = PM_STRUCTURE[method]
    plant = double_integrator_zoh(design.m, T)
    K = design.estimator.discrete if structure is not None else None
    return combined_loop(plant, design.controller.discrete, K, structure or "decoupled", output="u")


def _gain(sys: StateSpace, f: float, T: float) -> float:
    z = np.exp(1j * 2.0 * math.pi * f * T)
    n = sys.A.shape[0]
    H = sys.C @ np.linalg.solve(z * np.eye(n) - sys.A, sys.B) + sys.D
    return float(np.linalg.norm(H, 2))


def bandwidth_hz(sys: StateSpace, T: float) -> float:
    """The highest frequency (Hz, up to Nyquist) at which the loop's |T_i| is at least -3 dB."""
    nyquist = 0.5 / T
    grid = np.geomspace(F_LOW, nyquist, GRID)
    above = [_gain(sys, f, T) >= HALF_POWER for f in grid]
    if above[-1]:
        return nyquist
    last = max((i for i, a in enumerate(above) if a), default=None)
    if last is None:
        return 0.0
    lo, hi = grid[last], grid[last + 1]
    for _ in range(40):  # the crossing, to well under the grid's spacing
        mid = math.sqrt(lo * hi)
        lo, hi = (mid, hi) if _gain(sys, mid, T) >= HALF_POWER else (lo, mid)
    return float(math.sqrt(lo * hi))


def method_loop(method: str, controller_args: dict[str, float], design: Any, T: float) -> StateSpace:
    """The loop of a method with its gains (the firmware's options: kp, kd, tde_cutoff, usde_k,
    smc_lambda, smc_ks, smc_eta, smc_phi), or its synthesised design."""
    a = controller_args
    if method in PM_STRUCTURE:
        return _design_loop(design, method, T)
    if method == "pd":
        return _pd_loop(a["kp"], a["kd"], T)
    if method == "tde":
        return _tde_loop(a["kp"], a["kd"], a["tde_cutoff"], T)
    if method == "usde-smc":
        return _usde_smc_loop(a["smc_lambda"], a["smc_ks"], a["smc_eta"], a["smc_phi"], a["usde_k"], T)
    raise ValueError(f"no loop model of method {method}")
