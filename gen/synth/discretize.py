"""Zero-order-hold discretisation at the loop period."""

from __future__ import annotations

import numpy as np
import scipy.linalg as sla

from gen.synth.ss import StateSpace


def zoh(sys: StateSpace, T: float) -> StateSpace:
    """Exact for inputs held constant over each period; C and D are unchanged."""
    n, m = sys.n_states, sys.n_in
    if n == 0:
        return sys
    M = np.zeros((n + m, n + m))
    M[:n, :n] = sys.A
    M[:n, n:] = sys.B
    E = sla.expm(M * T)
    return StateSpace(E[:n, :n], E[:n, n:], sys.C.copy(), sys.D.copy())


def double_integrator_zoh(m: int, T: float) -> StateSpace:
    """Closed form of zoh() for e_ddot = u (m joints), state [e; e_dot], output the state."""
    Z, I = np.zeros((m, m)), np.eye(m)
    A = np.block([[I, T * I], [Z, I]])
    B = np.vstack([0.5 * T * T * I, T * I])
    return StateSpace(A, B, np.eye(2 * m), np.zeros((2 * m, m)))
