"""A minimal state-space container used throughout the synthesis (no python-control dependency).

python-control is deliberately not imported here: it adds ~1 s of import time to every synth
run and we only need matrices, not its transfer-function machinery.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True, eq=False)
class StateSpace:
    """x' = A x + B u, y = C x + D u (continuous) or x[k+1] = ... (discrete); shapes are checked."""

    A: np.ndarray
    B: np.ndarray
    C: np.ndarray
    D: np.ndarray

    def __post_init__(self) -> None:
        n = self.A.shape[0]
        if self.A.shape != (n, n) or self.B.shape[0] != n or self.C.shape[1] != n:
            raise ValueError(f"inconsistent state-space shapes A{self.A.shape} B{self.B.shape} C{self.C.shape}")
        if self.D.shape != (self.C.shape[0], self.B.shape[1]):
            raise ValueError(f"D must be {self.C.shape[0]}x{self.B.shape[1]}, got {self.D.shape}")

    @property
    def n_states(self) -> int:
        return int(self.A.shape[0])

    @property
    def n_in(self) -> int:
        return int(self.B.shape[1])

    @property
    def n_out(self) -> int:
        return int(self.C.shape[0])

    def similarity(self, T: np.ndarray) -> StateSpace:
        """Same transfer function in coordinates x = T x_new."""
        Ti = np.linalg.inv(T)
        return StateSpace(Ti @ self.A @ T, Ti @ self.B, self.C @ T, self.D.copy())

    def freqresp(self, omega: float) -> np.ndarray:
        n = self.n_states
        if n == 0:
            return self.D.astype(complex)
        return self.C @ np.linalg.solve(1j * omega * np.eye(n) - self.A, self.B) + self.D

    def freqresp_grid(self, omegas: np.ndarray) -> np.ndarray:
        """freqresp at every frequency, stacked: the same LAPACK and BLAS calls slice by slice, so
        each slice equals freqresp(omega) bit for bit, without a Python call per frequency."""
        n, k = self.n_states, len(omegas)
        if n == 0:
            return np.broadcast_to(self.D.astype(complex), (k, *self.D.shape))
        M = 1j * np.asarray(omegas, dtype=float)[:, None, None] * np.eye(n) - self.A
        return self.C @ np.linalg.solve(M, np.broadcast_to(self.B, (k, *self.B.shape))) + self.D


def static_gain(D: np.ndarray) -> StateSpace:
    """A system with no states (u = D y)."""
    m, p = D.shape
    return StateSpace(np.zeros((0, 0)), np.zeros((0, p)), np.zeros((m, 0)), np.asarray(D, dtype=float))


def block_diag_ss(parts: list[StateSpace]) -> StateSpace:
    """Parallel, non-interacting systems stacked (inputs and outputs concatenated)."""

    # scipy.linalg.block_diag mishandles 0-row blocks (static gains), hence our own.
    def bd(mats: list[np.ndarray]) -> np.ndarray:
        rows = sum(m.shape[0] for m in mats)
        cols = sum(m.shape[1] for m in mats)
        out = np.zeros((rows, cols))
        r = c = 0
        for m in mats:
            out[r : r + m.shape[0], c : c + m.shape[1]] = m
            r += m.shape[0]
            c += m.shape[1]
        return out

    return StateSpace(bd([p.A for p in parts]), bd([p.B for p in parts]), bd([p.C for p in parts]), bd([p.D for p in parts]))
