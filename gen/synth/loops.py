"""Closed loops: each design loop, and the combined loop the firmware runs (both structures).

Combined loop, per set of joints, with e_ddot = u + w, u = u_o - w_hat, y = [e; e_dot]:
  'decoupled': x_m' = A x_m + B u_o (internal model) and K is fed y - x_m, so K sees exactly
               its design plant and the closed-loop poles are those of the two design loops;
  'paper':     K is fed y directly, as printed (K then also 'estimates' u_o and cancels it).
The same builder serves continuous and discrete (ZOH) loops; in a discrete loop `delay` extra
periods of actuation latency can be inserted between the computed u and the plant. The internal
model keeps receiving the undelayed u_o, as the firmware would, which is what makes the delayed
check a real robustness test.
"""

from __future__ import annotations

import numpy as np

from gen.synth.plants import GeneralizedPlant
from gen.synth.ss import StateSpace

STRUCTURES = ("decoupled", "paper")


def design_loop(P: GeneralizedPlant, K: StateSpace) -> StateSpace:
    """Exogenous input -> performance output of P closed by K (D22 = 0)."""
    D21 = P.d21
    A = np.block([[P.A + P.B2 @ K.D @ P.C2, P.B2 @ K.C], [K.B @ P.C2, K.A]])
    B = np.vstack([P.B1 + P.B2 @ K.D @ D21, K.B @ D21])
    C = np.hstack([P.C1 + P.D12 @ K.D @ P.C2, P.D12 @ K.C])
    return StateSpace(A, B, C, P.D11 + P.D12 @ K.D @ D21)


def combined_loop(
    plant: StateSpace, C: StateSpace, K: StateSpace | None, structure: str = "decoupled", delay: int = 0,
    output: str = "e",
) -> StateSpace:
    """w -> e of the whole loop (output "e"), or w -> -u, the control's answer to w (output "u": the
    input's complementary sensitivity, whose bandwidth is the loop's). plant: [e; e_dot] driven by u
    (the same model serves as the internal model). K = None closes the controller alone (w_hat = 0)."""
    if structure not in STRUCTURES:
        raise ValueError(f"structure must be one of {STRUCTURES}")
    m = plant.n_in
    npl = plant.n_states
    nk = K.n_states if K is not None else 0
    nm = npl if (K is not None and structure == "decoupled") else 0
    sizes = [npl, C.n_states, nk, nm] + [m] * delay
    offs = np.concatenate([[0], np.cumsum(sizes)]).astype(int)
    N = int(offs[-1])

    def sel(i: int) -> np.ndarray:
        S = np.zeros((sizes[i], N))
        S[:, offs[i] : offs[i + 1]] = np.eye(sizes[i])
        return S

    Sp, Sc, Sk, Sm = sel(0), sel(1), sel(2), sel(3)
    Suo = C.C @ Sc + C.D @ Sp
    if K is not None:
        Sin = Sp - Sm if nm else Sp
        Swh = K.C @ Sk + K.D @ Sin
    else:
        Sin = np.zeros((2 * m, N))
        Swh = np.zeros((m, N))
    Su = Suo - Swh
    Sapplied = sel(4 + delay - 1) if delay else Su

    rows = [plant.A @ Sp + plant.B @ Sapplied, C.A @ Sc + C.B @ Sp]
    if nk:
        rows.append(K.A @ Sk + K.B @ Sin)  # type: ignore[union-attr]
    if nm:
        rows.append(plant.A @ Sm + plant.B @ Suo)
    for i in range(delay):
        rows.append(Su if i == 0 else sel(4 + i - 1))
    A = np.vstack([r for r in rows if r.shape[0]]) if N else np.zeros((0, 0))
    Bw = np.zeros((N, m))
    Bw[: npl] = plant.B  # w is a physical torque error: it is never delayed
    Cout = -Su if output == "u" else Sp[:m]
    return StateSpace(A, Bw, Cout, np.zeros((m, m)))
