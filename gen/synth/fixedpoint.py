"""int32 Q-format realisations whose states and outputs provably cannot overflow.

For x[k+1] = A x + B y, u = C x + D y with |y_j| <= r_j, the worst case of |x_i| over all inputs
is exactly sum_j r_j * sum_k |(A^k B)_ij| (the l1 norm of the impulse response): the input that
attains it is a sign sequence. We compute these sums directly and bound the neglected tail
rigorously with a Lyapunov function, then add the rounding noise the fixed-point arithmetic
injects (also through its l1 gain), and pick the fractional bits from the resulting bounds.

Realisation: states are first rescaled so that every state has the same bound (1.0); one
fractional format then fits all states without wasting bits. The float header uses the same
rescaled realisation, so float32 states are O(1) as well.

Arithmetic the bounds assume (documented in the header too): every product of an int32
coefficient and an int32 signal is accumulated in int64; formats are chosen so that all terms of
one sum share one binary point (A_FRAC + X_FRAC = B_FRAC + Y_FRAC), the accumulator cannot
overflow, and the result is brought to the target format by one rounding right shift, then
saturated to int32 (saturation never triggers for inputs inside the declared ranges).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
import scipy.linalg as sla

from gen.synth.lmi import SynthesisError
from gen.synth.ss import StateSpace

INT32_MAX = 2**31 - 1
ACC_LIMIT = 2**62  # int64 accumulator budget: a factor 2 below overflow
HEADROOM = 2.0  # one guard bit between the proven bound and the int32 limit
_BATCH = 64
_MAX_STEPS = 4_000_000
_ACC_FRAC_CAP = 60  # binary point of an accumulator; only reached by all-zero (padding) matrices


class FixedPointError(SynthesisError):
    """No Q format can hold the design for the declared ranges."""


def l1_gains(A: np.ndarray, B: np.ndarray, C: np.ndarray | None = None, D: np.ndarray | None = None) -> np.ndarray:
    """Entry-wise upper bound on sum_k |h_k| for h_k = A^k B (states) or D, C A^(k-1) B (outputs)."""
    n, m = B.shape
    out_map = np.eye(n) if C is None else C
    total = np.zeros((out_map.shape[0], m)) if D is None else np.abs(D).astype(float)
    if n == 0:
        return total
    rho = float(np.max(np.abs(np.linalg.eigvals(A))))
    if rho >= 1.0:
        raise FixedPointError(f"system not Schur-stable (rho {rho:.9f}): no finite overflow bound")
    # Tail bound: with A^T P A - P = -I, ||A x||_P <= q ||x||_P for q = sqrt(1 - 1/lambda_max(P)).
    P = sla.solve_discrete_lyapunov(A.T, np.eye(n))
    P = (P + P.T) / 2
    w, V = np.linalg.eigh(P)
    P_half = V @ np.diag(np.sqrt(w)) @ V.T
    P_mhalf = V @ np.diag(1 / np.sqrt(w)) @ V.T
    q = math.sqrt(max(0.0, 1.0 - 1.0 / float(w.max())))
    row_norm = np.linalg.norm(out_map @ P_mhalf, axis=1)  # ||P^-1/2 c_i||

    powers = np.empty((_BATCH, n, n))
    powers[0] = np.eye(n)
    for k in range(1, _BATCH):
        powers[k] = A @ powers[k - 1]
    A_batch = A @ powers[-1]
    M = B.copy()  # A^(steps) B
    steps = 0
    while True:
        block = powers @ M  # (batch, n, m): A^(steps..steps+63) B
        total += np.abs(out_map @ block).sum(axis=0)
        M = A_batch @ M
        steps += _BATCH
        tail = np.outer(row_norm, np.linalg.norm(P_half @ M, axis=0)) / (1 - q) if q < 1 else np.full_like(total, np.inf)
        # Stop once the (still added) tail is negligible against the largest gain; a per-entry test
        # would never stop on entries that are exactly zero (block-diagonal designs).
        if float(tail.max()) <= 1e-9 * float(total.max()) or steps >= _MAX_STEPS:
            return total + tail


@dataclass(eq=False)
class FixedSystem:
    name: str
    A_Q: np.ndarray
    B_Q: np.ndarray
    C_Q: np.ndarray
    D_Q: np.ndarray
    a_frac: int
    b_frac: int
    c_frac: int
    d_frac: int
    x_frac: int
    y_frac: int
    u_frac: int
    in_max: np.ndarray  # declared |input| bounds (real units) the proof assumes
    x_bound: np.ndarray  # proven |state| bounds (real units), rounding included
    u_bound: np.ndarray  # proven |output| bounds
    acc_bound: float  # worst |int64 accumulator|
    bound_method: str
    quantised_spectral_radius: float

    @property
    def acc_x_shift(self) -> int:
        return self.a_frac  # (A_FRAC + X_FRAC) - X_FRAC

    @property
    def acc_u_shift(self) -> int:
        return self.c_frac + self.x_frac - self.u_frac

    def to_json(self) -> dict[str, Any]:
        return {
            "A_Q": self.A_Q.tolist(),
            "B_Q": self.B_Q.tolist(),
            "C_Q": self.C_Q.tolist(),
            "D_Q": self.D_Q.tolist(),
            "A_FRAC": self.a_frac,
            "B_FRAC": self.b_frac,
            "C_FRAC": self.c_frac,
            "D_FRAC": self.d_frac,
            "X_FRAC": self.x_frac,
            "Y_FRAC": self.y_frac,
            "U_FRAC": self.u_frac,
            "ACC_X_SHIFT": self.acc_x_shift,
            "ACC_U_SHIFT": self.acc_u_shift,
            "input_max": self.in_max.tolist(),
            "state_bound": self.x_bound.tolist(),
            "output_bound": self.u_bound.tolist(),
            "accumulator_bound_log2": math.log2(self.acc_bound) if self.acc_bound > 0 else None,
            "bound_method": self.bound_method,
            "quantised_spectral_radius": self.quantised_spectral_radius,
        }


def frac_for(bound: float, headroom: float = HEADROOM, cap: int = 30) -> int:
    """Most fractional bits with headroom * bound still inside int32."""
    if bound <= 0 or not math.isfinite(bound):
        return cap
    return min(cap, math.floor(math.log2(INT32_MAX / (headroom * bound))))


def _coef_frac(M: np.ndarray) -> int:
    mx = float(np.max(np.abs(M))) if M.size else 0.0
    return 40 if mx == 0 else math.floor(math.log2(INT32_MAX / mx))


def _q(M: np.ndarray, frac: int) -> np.ndarray:
    return np.clip(np.round(M * 2.0**frac), -INT32_MAX, INT32_MAX).astype(np.int64)


def equalise_states(sys: StateSpace, in_max: np.ndarray) -> tuple[StateSpace, np.ndarray]:
    """Rescale states so each has the same worst-case bound (just under 1.0); returns the scaling.

    The 1% slack keeps the bound, rounding noise included, below 1.0 so that X_FRAC = 30 fits.
    """
    if sys.n_states == 0:
        return sys, np.ones(0)
    xb = l1_gains(sys.A, sys.B) @ in_max
    s = np.where(xb > 0, xb / 0.99, 1.0)
    return sys.similarity(np.diag(s)), s


def quantise(
    name: str,
    sys: StateSpace,
    in_max: np.ndarray,
    y_frac: int,
    x_bound: np.ndarray | None = None,
    x_frac: int | None = None,
) -> FixedSystem:
    """Q-format realisation of a discrete system with inputs in Q(y_frac) bounded by in_max.

    x_bound: a given state bound instead of the l1 one (the internal model is a double integrator,
    which has no finite l1 gain; its bound comes from the declared ranges and is enforced by
    saturation in the firmware). x_frac: a prescribed state format (the internal-model state must
    share the format of y so that the firmware can subtract the two).
    """
    A, B, C, D = sys.A, sys.B, sys.C, sys.D
    n = sys.n_states
    r_q = np.floor(in_max * 2.0**y_frac)  # saturation limits, in Q(y_frac): never above in_max
    r_eff = r_q / 2.0**y_frac
    given = x_bound is not None
    xb0 = x_bound if given else l1_gains(A, B) @ r_eff
    ub0 = l1_gains(A, B, C, D) @ r_eff if not given else np.abs(C) @ xb0 + np.abs(D) @ r_eff
    fixed_x = x_frac is not None
    x_frac = x_frac if x_frac is not None else frac_for(float(np.max(xb0, initial=0.0)))
    u_frac = frac_for(float(np.max(ub0, initial=0.0)))
    for _ in range(8):
        acc_x = min(_coef_frac(A) + x_frac, _coef_frac(B) + y_frac, _ACC_FRAC_CAP)
        worst_x = float(np.max(np.abs(A) @ xb0 + np.abs(B) @ r_eff, initial=0.0))
        if worst_x > 0:
            acc_x = min(acc_x, math.floor(math.log2(ACC_LIMIT / (HEADROOM * worst_x))))
        acc_u = min(_coef_frac(C) + x_frac, _coef_frac(D) + y_frac, _ACC_FRAC_CAP)
        worst_u = float(np.max(np.abs(C) @ xb0 + np.abs(D) @ r_eff, initial=0.0))
        if worst_u > 0:
            acc_u = min(acc_u, math.floor(math.log2(ACC_LIMIT / (HEADROOM * worst_u))))
        u_frac_i = min(u_frac, acc_u)
        a_frac, b_frac = acc_x - x_frac, acc_x - y_frac
        c_frac, d_frac = acc_u - x_frac, acc_u - y_frac
        if a_frac < 0:
            raise FixedPointError(f"{name}: A needs a negative fractional format ({a_frac}); state bound too small for Q31")
        AQ, BQ, CQ, DQ = _q(A, a_frac), _q(B, b_frac), _q(C, c_frac), _q(D, d_frac)
        Ah, Bh = AQ / 2.0**a_frac, BQ / 2.0**b_frac
        Ch, Dh = CQ / 2.0**c_frac, DQ / 2.0**d_frac
        qx, qu = 2.0 ** -(x_frac + 1), 2.0 ** -(u_frac_i + 1)  # rounding of each shift
        rho_q = float(np.max(np.abs(np.linalg.eigvals(Ah)))) if n else 0.0
        if given:
            xb = xb0
            ub = np.abs(Ch) @ xb + np.abs(Dh) @ r_eff + qu
            method = "given state bound (saturated in firmware); outputs by |C| x_max + |D| y_max"
        else:
            # The implemented recursion is x+ = Ah x + Bh y + e, |e_i| <= qx, and u = Ch x + Dh y + e_u.
            xb = l1_gains(Ah, Bh) @ r_eff + l1_gains(Ah, np.eye(n)) @ np.full(n, qx) if n else np.zeros(0)
            ub = l1_gains(Ah, Bh, Ch, Dh) @ r_eff + (l1_gains(Ah, np.eye(n), Ch, np.zeros((Ch.shape[0], n))) @ np.full(n, qx) if n else 0) + qu
            method = "l1 norm of the quantised impulse responses (rigorous tail bound) plus rounding noise"
        x_ok = np.all(xb * 2.0**x_frac <= INT32_MAX / 1.0001) if n else True
        u_ok = np.all(ub * 2.0**u_frac_i <= INT32_MAX / 1.0001)
        xmax_q = np.floor(xb * 2.0**x_frac) if n else np.zeros(0)
        acc = 0.0
        if n:
            acc = float(np.max(np.abs(AQ) @ xmax_q + np.abs(BQ) @ r_q))
        acc = max(acc, float(np.max(np.abs(CQ) @ xmax_q + np.abs(DQ) @ r_q, initial=0.0)))
        if x_ok and u_ok and acc < 2.0**63 - 2.0**40:  # the int64 accumulator cannot overflow
            return FixedSystem(
                name, AQ, BQ, CQ, DQ, a_frac, b_frac, c_frac, d_frac, x_frac, y_frac, u_frac_i,
                r_eff, xb, ub, acc, method, rho_q,
            )
        acc_ok = acc < 2.0**63 - 2.0**40
        if fixed_x and not (x_ok and acc_ok):
            break
        x_frac -= 0 if (x_ok and acc_ok) else 1
        u_frac -= 0 if u_ok else 1
    raise FixedPointError(f"{name}: could not find Q formats without overflow for the declared ranges")
