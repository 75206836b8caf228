"""Theorem 1: the H-infinity estimator LMIs (3.14), with the D11 term of (3.16) for a biproper F."""

from __future__ import annotations

import cvxpy as cp
import numpy as np

from gen.synth.lmi import STRICT_EPS, Calligraphic, LmiSynthesis, sym
from gen.synth.plants import GeneralizedPlant


def _constraints(P: GeneralizedPlant, c: Calligraphic, gamma: cp.Expression) -> list[cp.Constraint]:
    n2 = 2 * P.nx
    big = cp.bmat(
        [
            [c.A.T + c.A, c.B, c.C.T],
            [c.B.T, -gamma * np.eye(P.nw), c.D.T],
            [c.C, c.D, -gamma * np.eye(P.nz)],
        ]
    )
    return [
        sym(c.X) >> STRICT_EPS * np.eye(n2),
        sym(big) << -STRICT_EPS * np.eye(n2 + P.nw + P.nz),
    ]


def hinf_synthesis(P: GeneralizedPlant) -> LmiSynthesis:
    return LmiSynthesis(P, _constraints, "H-infinity estimator (Theorem 1)")
