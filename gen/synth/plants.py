"""The two generalized plants of the paper, for any set of joints.

P_f (eq. 3.10), estimator design: states [e; e_dot; x_F], inputs w and w_hat, z_e = F(w - w_hat) + H w_hat,
y = [e; e_dot]. The estimator is designed as if u_o = 0: in the 'decoupled' structure the internal
model removes u_o from what K sees, so this is exactly the plant K faces.
P_o (eq. 3.18), controller design: states [e; e_dot], inputs d = w - w_hat and u_o,
z_o = E1 e + E2 e_dot + D12 u_o, y = [e; e_dot].
In both, y is noise-free (D21 = 0) and there is no feedthrough to y (D22 = 0). D21 is still
supported (the benchmark needs it to meet python-control's hinfsyn on a regularised plant).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.linalg as sla
from gen.synth.config import TransferFunction


@dataclass(frozen=True, eq=False)
class GeneralizedPlant:
    A: np.ndarray
    B1: np.ndarray  # exogenous input (w or d)
    B2: np.ndarray  # the input the synthesised system drives (w_hat or u_o)
    C1: np.ndarray  # performance output
    D11: np.ndarray
    D12: np.ndarray
    C2: np.ndarray  # measurement
    D21: np.ndarray | None = None  # exogenous input -> measurement; None = 0 (the paper's plants)

    @property
    def d21(self) -> np.ndarray:
        return np.zeros((self.ny, self.nw)) if self.D21 is None else self.D21

    @property
    def nx(self) -> int:
        return int(self.A.shape[0])

    @property
    def nw(self) -> int:
        return int(self.B1.shape[1])

    @property
    def nu(self) -> int:
        return int(self.B2.shape[1])

    @property
    def nz(self) -> int:
        return int(self.C1.shape[0])

    @property
    def ny(self) -> int:
        return int(self.C2.shape[0])

    def to_json(self) -> dict[str, list[list[float]]]:
        out = {k: getattr(self, k).tolist() for k in ("A", "B1", "B2", "C1", "D11", "D12", "C2")}
        if self.D21 is not None:
            out["D21"] = self.D21.tolist()
        return out


def double_integrator(m: int) -> tuple[np.ndarray, np.ndarray]:
    """e_ddot = u for m joints, state [e; e_dot]."""
    Z, I = np.zeros((m, m)), np.eye(m)
    return np.block([[Z, I], [Z, Z]]), np.vstack([Z, I])


def realise(tf: TransferFunction) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Controllable canonical realisation of a SISO num/den (proper).

    Written out rather than scipy.signal.tf2ss: importing scipy.signal costs ~0.5 s per run.
    """
    den = np.array(tf.den, dtype=float)
    num = np.array(tf.num, dtype=float)
    den, num = den / den[0], num / den[0]
    r = len(den) - 1
    num = np.concatenate([np.zeros(r + 1 - len(num)), num])  # pad to degree r
    d = num[0]
    c = num[1:] - d * den[1:]  # strictly proper remainder, coefficients of s^(r-1) .. s^0
    A = np.zeros((r, r))
    if r:
        A[0, :] = -den[1:]
        A[1:, :-1] = np.eye(r - 1)
    B = np.zeros((r, 1))
    if r:
        B[0, 0] = 1.0
    return A, B, c.reshape(1, r), np.array([[d]])


def balance(A: np.ndarray, B: np.ndarray, C: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Balanced realisation of a stable minimal SISO system (equal, diagonal Gramians).

    The LMI solver is sensitive to how F is realised: for F = 100/(s + 100) the canonical form
    (B = 1, C = 100) makes Clarabel fail near gamma_opt where the balanced one (B = C = 10) solves.
    Non-minimal F (singular Gramians) keeps the canonical form.
    """
    if A.shape[0] == 0:
        return A, B, C
    Wc = sla.solve_continuous_lyapunov(A, -B @ B.T)
    Wo = sla.solve_continuous_lyapunov(A.T, -C.T @ C)
    try:
        Lc = np.linalg.cholesky((Wc + Wc.T) / 2)
    except np.linalg.LinAlgError:
        return A, B, C
    U, s2, _ = np.linalg.svd(Lc.T @ ((Wo + Wo.T) / 2) @ Lc)
    if s2[-1] <= 1e-12 * s2[0]:
        return A, B, C
    T = Lc @ U @ np.diag(s2**-0.25)
    Ti = np.linalg.inv(T)
    return Ti @ A @ T, Ti @ B, C @ T


def estimator_plant(F: list[TransferFunction], H: np.ndarray) -> GeneralizedPlant:
    """P_f for len(F) joints; F(s) = diag(F), H is len(F) x len(F)."""
    m = len(F)
    Ad, Bd = double_integrator(m)
    parts = []
    for f in F:
        a, b, c, d = realise(f)
        parts.append((*balance(a, b, c), d))
    nf = sum(p[0].shape[0] for p in parts)
    AF, BF, CF = np.zeros((nf, nf)), np.zeros((nf, m)), np.zeros((m, nf))
    DF = np.zeros((m, m))
    k = 0
    for j, (a, b, c, d) in enumerate(parts):
        r = a.shape[0]
        AF[k : k + r, k : k + r] = a
        BF[k : k + r, j : j + 1] = b
        CF[j : j + 1, k : k + r] = c
        DF[j, j] = d[0, 0]
        k += r
    A = np.block([[Ad, np.zeros((2 * m, nf))], [np.zeros((nf, 2 * m)), AF]])
    B1 = np.vstack([Bd, BF])  # w drives e_ddot and F
    B2 = -B1  # w_hat enters wherever w does, with the opposite sign
    C1 = np.hstack([np.zeros((m, 2 * m)), CF])
    C2 = np.hstack([np.eye(2 * m), np.zeros((2 * m, nf))])
    return GeneralizedPlant(A=A, B1=B1, B2=B2, C1=C1, D11=DF, D12=H - DF, C2=C2)


def controller_plant(E1: np.ndarray, E2: np.ndarray, D12: np.ndarray) -> GeneralizedPlant:
    """P_o for the joints that E1, E2, D12 (p x m) act on."""
    m = E1.shape[1]
    A, B = double_integrator(m)
    C1 = np.hstack([E1, E2])
    return GeneralizedPlant(A=A, B1=B, B2=B.copy(), C1=C1, D11=np.zeros((C1.shape[0], m)), D12=D12, C2=np.eye(2 * m))
