"""Independent norms: nothing here looks at an LMI value.

hinf_norm: Boyd-Balakrishnan/Bruinsma-Steinbuch level-set iteration on the Hamiltonian matrix,
checked against a logarithmic frequency sweep (which can only underestimate).
gh2_norm: the generalized-H2 (L2 -> L_inf, Euclidean in space) norm is
sqrt(lambda_max(C W C^T)) with W the controllability Gramian.
"""

from __future__ import annotations

import numpy as np
import scipy.linalg as sla

from gen.synth.ss import StateSpace


def spectral_radius(A: np.ndarray) -> float:
    return float(np.max(np.abs(np.linalg.eigvals(A)))) if A.size else 0.0


def max_real_part(A: np.ndarray) -> float:
    return float(np.max(np.linalg.eigvals(A).real)) if A.size else -np.inf


def _sigma_max(sys: StateSpace, omega: float) -> float:
    return float(np.linalg.norm(sys.freqresp(omega), 2))


def sweep_peak(sys: StateSpace, n_points: int = 400) -> tuple[float, float]:
    """Largest singular value over a log grid spanning the system's poles (a lower bound)."""
    poles = np.abs(np.linalg.eigvals(sys.A)) if sys.n_states else np.array([1.0])
    poles = poles[poles > 0] if np.any(poles > 0) else np.array([1.0])
    lo, hi = np.log10(poles.min()) - 3, np.log10(poles.max()) + 3
    grid = np.concatenate([[0.0], np.logspace(lo, hi, n_points)])
    vals = np.linalg.svd(sys.freqresp_grid(grid), compute_uv=False).max(axis=-1)  # norm(., 2) of each
    i = int(np.argmax(vals))
    return float(vals[i]), float(grid[i])


def hinf_norm(sys: StateSpace, rtol: float = 1e-7) -> tuple[float, float]:
    """(||G||_inf, peak frequency in rad/s) of a stable continuous system."""
    A, B, C, D = sys.A, sys.B, sys.C, sys.D
    if sys.n_states == 0:
        return float(np.linalg.norm(D, 2)), 0.0
    if max_real_part(A) >= 0:
        return float("inf"), 0.0
    lb, w_peak = sweep_peak(sys, 60)
    d = float(np.linalg.norm(D, 2))
    if d > lb:
        lb, w_peak = d, float("inf")
    if lb == 0.0:  # G(jw) = 0 on the whole grid: only the zero system gets here
        return 0.0, 0.0
    for _ in range(100):
        g = lb * (1.0 + 2.0 * rtol)
        # Hamiltonian of ||G|| < g: imaginary-axis eigenvalues are exactly the frequencies where
        # some singular value of G(jw) equals g.
        R = g * g * np.eye(D.shape[1]) - D.T @ D
        Ri = np.linalg.inv(R)
        Ah = A + B @ Ri @ D.T @ C
        Ham = np.block([[Ah, B @ Ri @ B.T], [-C.T @ (np.eye(C.shape[0]) + D @ Ri @ D.T) @ C, -Ah.T]])
        ev = np.linalg.eigvals(Ham)
        scale = max(1.0, float(np.max(np.abs(ev))))
        imag = np.sort(np.abs(ev[np.abs(ev.real) <= 1e-9 * scale].imag))
        imag = np.unique(np.round(imag, 12))
        if imag.size == 0:
            return lb, w_peak
        # Evaluate between consecutive crossings (and at a single one): the peak lies in between.
        if imag.size == 1:
            cands = [float(imag[0])]
        else:
            cands = [float(np.sqrt(a * b)) if a > 0 else float(b) / 2 for a, b in zip(imag[:-1], imag[1:])]
        best = max(cands, key=lambda w: _sigma_max(sys, w))
        val = _sigma_max(sys, best)
        if val <= lb * (1.0 + rtol):
            return lb, w_peak
        lb, w_peak = val, best
    return lb, w_peak


def gh2_norm(sys: StateSpace) -> float:
    """sup ||z||_inf / ||d||_2 of a stable strictly proper system."""
    if np.any(sys.D != 0):
        return float("inf")
    if sys.n_states == 0:
        return 0.0
    if max_real_part(sys.A) >= 0:
        return float("inf")
    W = sla.solve_continuous_lyapunov(sys.A, -sys.B @ sys.B.T)
    return float(np.sqrt(max(0.0, float(np.max(np.linalg.eigvalsh((sys.C @ W @ sys.C.T + (sys.C @ W @ sys.C.T).T) / 2))))))
