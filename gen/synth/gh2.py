"""Theorem 3: the generalized-H2 (L2 -> L_inf) controller LMIs (3.22), and the degenerate case.

gamma here bounds the generalized-H2 norm itself, not its square (substitute X = gamma X' in the
textbook form to see it).
"""

from __future__ import annotations

from dataclasses import dataclass

import cvxpy as cp
import numpy as np

from gen.synth.lmi import STRICT_EPS, Calligraphic, LmiSynthesis, sym
from gen.synth.plants import GeneralizedPlant


def _constraints(P: GeneralizedPlant, c: Calligraphic, gamma: cp.Expression) -> list[cp.Constraint]:
    if P.D21 is not None or np.any(P.D11):
        raise ValueError("the generalized-H2 norm needs a strictly proper closed loop (D11 = 0, D21 = 0)")
    n2 = 2 * P.nx
    lyap = cp.bmat([[c.A.T + c.A, c.B], [c.B.T, -gamma * np.eye(P.nw)]])
    peak = cp.bmat([[c.X, c.C.T], [c.C, gamma * np.eye(P.nz)]])
    return [
        sym(lyap) << -STRICT_EPS * np.eye(n2 + P.nw),
        sym(peak) >> STRICT_EPS * np.eye(n2 + P.nz),
    ]


def gh2_synthesis(P: GeneralizedPlant) -> LmiSynthesis:
    return LmiSynthesis(P, _constraints, "generalized-H2 controller (Theorem 3)")


@dataclass(frozen=True, eq=False)
class Degeneracy:
    degenerate: bool
    reason: str
    zeroing_gain: np.ndarray | None  # u_o = K0 y makes z_o identically 0 when degenerate
    invariant_zeros: list[complex]


def detect_degenerate(P: GeneralizedPlant) -> Degeneracy:
    """gamma* = 0 when a stabilising static gain makes z_o vanish identically.

    With y = x (C2 invertible) and D12 of full column rank, u_o = -D12^+ C1 C2^-1 y zeroes z_o
    exactly iff C1 lies in the range of D12; it is admissible iff A - B2 D12^+ C1 is Hurwitz, i.e.
    the invariant zeros of (A, B2, C1, D12) are stable. The paper's weights satisfy both.
    """
    C2inv = np.linalg.inv(P.C2)
    pinv = np.linalg.pinv(P.D12)
    K0 = -pinv @ P.C1 @ C2inv
    residual = float(np.linalg.norm(P.C1 + P.D12 @ K0 @ P.C2))
    scale = max(1.0, float(np.linalg.norm(P.C1)))
    zeros = np.linalg.eigvals(P.A + P.B2 @ K0 @ P.C2)
    zlist = [complex(z) for z in sorted(zeros, key=lambda z: (z.real, z.imag))]
    if residual > 1e-9 * scale:
        return Degeneracy(False, f"C1 is not in the range of D12 (residual {residual:.3g}): z_o cannot be zeroed", None, zlist)
    if np.max(zeros.real) >= 0:
        return Degeneracy(False, "the static gain that zeroes z_o would leave unstable zeros", None, zlist)
    zs = ", ".join(f"{z.real:.4g}{z.imag:+.4g}j" for z in zlist)
    return Degeneracy(
        True,
        "D12 has full column rank, C1 is in its range and the invariant zeros of (A, B2, C1, D12) "
        f"are stable ({zs}): the static gain u_o = -D12^+ C1 y makes z_o identically 0, so gamma* = 0 "
        "and the full-order LMI optimum degenerates (huge, meaningless controller poles)",
        K0,
        zlist,
    )
