"""From LMI variables to a controller, and from there to one that a sampled loop can run.

recover(): eq. (3.15) / (3.23), [[A_k, B_k], [C_k, D_k]] = S1^-1 S2 S3^-1, written out explicitly.
I - X Y is nearly singular close to the optimum (condition numbers of 1e14 are normal), so it is
factored as U V^T with an SVD split evenly between U and V, and only U^-1 and V^-T of that
factorisation are ever applied - never a plain inverse of I - X Y.

residualise(): the recovered controller carries modes at 1e7..1e11 rad/s (some unstable) that
belong to the near-singular directions of I - X Y. No sampled loop can run them, and ZOH would turn
them into a spurious one-sample delay. They are replaced by their static contribution
(singular-perturbation residualisation); the verification step then measures the closed loop of
the reduced controller, so nothing rests on this approximation being good.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.linalg as sla

from gen.synth.lmi import LmiSolution, SynthesisError
from gen.synth.plants import GeneralizedPlant
from gen.synth.ss import StateSpace


@dataclass(frozen=True, eq=False)
class Recovered:
    full: StateSpace  # the full-order controller of eq. (3.15)
    reduced: StateSpace  # after residualising modes too fast for the loop rate
    residualised_poles: list[complex]
    i_minus_xy_singular_values: list[float]


def recover(P: GeneralizedPlant, s: LmiSolution) -> tuple[StateSpace, np.ndarray]:
    """(A_k, B_k, C_k, D_k) from (X, Y, J, L, M, N); also returns the singular values of I - XY."""
    A, B2, C2, X, Y = P.A, P.B2, P.C2, s.X, s.Y
    Us, sv, Vt = np.linalg.svd(np.eye(P.nx) - X @ Y)
    if sv[-1] <= 0.0 or not np.all(np.isfinite(sv)):
        raise SynthesisError("I - XY is singular: the LMI point is on the boundary, no controller of full order")
    root = np.sqrt(sv)
    U_inv = (Us / root).T  # (Us diag(root))^-1
    V_invT = Vt.T / root  # (Vs diag(root))^-T
    N = s.N
    Dk = N
    Ck = (s.M - N @ C2 @ Y) @ V_invT
    Bk = U_inv @ (s.L - X @ B2 @ N)
    Ak = U_inv @ (s.J - X @ A @ Y - X @ B2 @ s.M - s.L @ C2 @ Y + X @ B2 @ N @ C2 @ Y) @ V_invT
    return StateSpace(Ak, Bk, Ck, Dk), sv


def residualise(K: StateSpace, omega_max: float) -> tuple[StateSpace, list[complex]]:
    """Drop modes with |lambda| > omega_max, keeping their DC contribution in D."""
    n = K.n_states
    if n == 0:
        return K, []
    T, Z, k = sla.schur(K.A, output="real", sort=lambda re, im: np.hypot(re, im) <= omega_max)
    if k == n:
        return K, []
    Bz, Cz = Z.T @ K.B, K.C @ Z
    A11, A12, A22 = T[:k, :k], T[:k, k:], T[k:, k:]
    fast = [complex(p) for p in np.linalg.eigvals(A22)]
    # Block-diagonalise: with x = [[I, S], [0, I]] x_new and A11 S - S A22 = -A12 the slow and fast
    # parts decouple; the spectra are disjoint by construction, so the Sylvester equation is solvable.
    S = sla.solve_sylvester(A11, -A22, -A12) if k > 0 else np.zeros((0, n - k))
    B_slow = Bz[:k] - S @ Bz[k:]
    B_fast = Bz[k:]
    C_slow = Cz[:, :k]
    C_fast = Cz[:, :k] @ S + Cz[:, k:]
    D = K.D - C_fast @ np.linalg.solve(A22, B_fast)
    return StateSpace(A11.copy(), B_slow, C_slow, D), sorted(fast, key=lambda p: abs(p))


def recover_and_reduce(P: GeneralizedPlant, s: LmiSolution, omega_max: float) -> Recovered:
    full, sv = recover(P, s)
    reduced, fast = residualise(full, omega_max)
    return Recovered(full, reduced, fast, [float(x) for x in sv])
