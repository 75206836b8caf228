"""Shared LMI machinery of Theorems 1 and 3 (cvxpy + Clarabel).

Both theorems use the same change of variables (Scherer-Gahinet-Chilali): decision variables
X, Y, J, L, M, N and the 'calligraphic' matrices built from them. The theorem-specific
inequalities live in hinf.py and gh2.py. Each problem is built once with gamma as a cvxpy
Parameter, so the back-off ladder re-solves without re-canonicalising.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass

import cvxpy as cp
import numpy as np

from gen.synth.plants import GeneralizedPlant

# Strict LMIs are imposed with this margin; small enough not to move gamma_opt visibly.
STRICT_EPS = 1e-8
_ACCEPTED = ("optimal", "optimal_inaccurate")


class SynthesisError(RuntimeError):
    """The LMI solve or a design step failed; the message says which and why."""


@dataclass(frozen=True)
class Variables:
    X: cp.Variable
    Y: cp.Variable
    J: cp.Variable
    L: cp.Variable
    M: cp.Variable
    N: cp.Variable


@dataclass(frozen=True)
class Calligraphic:
    A: cp.Expression  # 2nx x 2nx
    B: cp.Expression  # 2nx x nw
    C: cp.Expression  # nz x 2nx
    X: cp.Expression  # [[Y, I], [I, X]]
    D: cp.Expression  # closed-loop feedthrough D11 + D12 N D21


@dataclass(frozen=True, eq=False)
class LmiSolution:
    gamma: float
    X: np.ndarray
    Y: np.ndarray
    J: np.ndarray
    L: np.ndarray
    M: np.ndarray
    N: np.ndarray
    status: str
    objective: str
    solve_time_s: float


def make_variables(P: GeneralizedPlant) -> Variables:
    nx, nu, ny = P.nx, P.nu, P.ny
    return Variables(
        X=cp.Variable((nx, nx), symmetric=True),
        Y=cp.Variable((nx, nx), symmetric=True),
        J=cp.Variable((nx, nx)),
        L=cp.Variable((nx, ny)),
        M=cp.Variable((nu, nx)),
        N=cp.Variable((nu, ny)),
    )


def calligraphic(P: GeneralizedPlant, v: Variables) -> Calligraphic:
    """The matrices of Theorem 1 (and, with P_o, Theorem 3) as printed in the paper."""
    A, B1, B2, C1, D12, C2 = P.A, P.B1, P.B2, P.C1, P.D12, P.C2
    I = np.eye(P.nx)
    if P.D21 is None:  # the paper's form
        B = cp.bmat([[B1], [v.X @ B1]])
        D = cp.Constant(P.D11)
    else:  # general D21 (Scherer-Gahinet-Chilali)
        B = cp.bmat([[B1 + B2 @ v.N @ P.D21], [v.X @ B1 + v.L @ P.D21]])
        D = P.D11 + D12 @ v.N @ P.D21
    return Calligraphic(
        A=cp.bmat([[A @ v.Y + B2 @ v.M, A + B2 @ v.N @ C2], [v.J, v.X @ A + v.L @ C2]]),
        B=B,
        C=cp.bmat([[C1 @ v.Y + D12 @ v.M, C1 + D12 @ v.N @ C2]]),
        X=cp.bmat([[v.Y, I], [I, v.X]]),
        D=D,
    )


def sym(M: cp.Expression) -> cp.Expression:
    """cvxpy needs a structurally symmetric argument for PSD constraints."""
    return (M + M.T) / 2


ConstraintBuilder = Callable[[GeneralizedPlant, Calligraphic, cp.Expression], list[cp.Constraint]]


class LmiSynthesis:
    """min gamma, and min trace(X + Y) at a fixed gamma, for one theorem's constraints."""

    def __init__(self, P: GeneralizedPlant, constraints: ConstraintBuilder, name: str) -> None:
        self.P = P
        self.name = name
        self._build = constraints
        self._fixed: tuple[cp.Problem, Variables, cp.Parameter] | None = None

    def _solve(self, prob: cp.Problem) -> float:
        t0 = time.perf_counter()
        try:
            prob.solve(solver=cp.CLARABEL)
        except cp.error.SolverError as exc:
            raise SynthesisError(f"{self.name}: Clarabel failed ({exc})") from None
        return time.perf_counter() - t0

    def _result(self, v: Variables, gamma: float, status: str, objective: str, dt: float) -> LmiSolution:
        vals = [x.value for x in (v.X, v.Y, v.J, v.L, v.M, v.N)]
        if any(x is None or not np.all(np.isfinite(x)) for x in vals):
            raise SynthesisError(f"{self.name}: solver returned no usable point (status {status})")
        X, Y, J, L, M, N = (np.asarray(x, dtype=float) for x in vals)
        return LmiSolution(float(gamma), (X + X.T) / 2, (Y + Y.T) / 2, J, L, M, N, status, objective, dt)

    def min_gamma(self) -> LmiSolution:
        """min gamma; if Clarabel breaks down (the optimum is an unattained infimum, so X and Y
        grow without bound), retry with ||X||, ||Y|| <= 1e6, which keeps the problem compact at the
        price of a slightly larger gamma (the status says so)."""
        for bound in (None, 1e6):
            v = make_variables(self.P)
            g = cp.Variable(nonneg=True)
            cons = self._build(self.P, calligraphic(self.P, v), g)
            if bound is not None:
                cons += [v.X << bound * np.eye(self.P.nx), v.Y << bound * np.eye(self.P.nx)]
            prob = cp.Problem(cp.Minimize(g), cons)
            try:
                dt = self._solve(prob)
            except SynthesisError:
                if bound is None:
                    continue
                raise
            if prob.status in _ACCEPTED and g.value is not None:
                status = prob.status if bound is None else f"{prob.status} (with ||X||, ||Y|| <= {bound:g})"
                return self._result(v, float(g.value), status, "min gamma", dt)
        raise SynthesisError(f"{self.name}: minimising gamma failed (status {prob.status})")

    def at_gamma(self, gamma: float) -> LmiSolution | None:
        """The well-conditioned point at a fixed gamma, or None when that gamma is infeasible."""
        if self._fixed is None:
            v = make_variables(self.P)
            g = cp.Parameter(nonneg=True)
            # Minimising trace(X + Y) keeps X and Y small instead of letting the interior point
            # wander to the analytic centre, whose controllers are orders of magnitude slower.
            prob = cp.Problem(cp.Minimize(cp.trace(v.X + v.Y)), self._build(self.P, calligraphic(self.P, v), g))
            self._fixed = (prob, v, g)
        prob, v, g = self._fixed
        g.value = gamma
        try:
            dt = self._solve(prob)
        except SynthesisError:
            return None  # numerical breakdown this close to the boundary counts as infeasible
        if prob.status not in _ACCEPTED:
            return None
        return self._result(v, gamma, prob.status, "min trace(X+Y) at fixed gamma", dt)
