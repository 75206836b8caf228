"""The identification's fit (armctl identify): what the arm is, from what it did.

The arm's links are the model's (their masses and inertias, Pinocchio's model of the prepared
arm.xml). Unknown, and linear in the joint torques:
    tau_j = Y_j(q, qd, qdd) pi_links  +  Ia_j qdd_j + fv_j qd_j + fc_j sign(qd_j)  +  Y_j,flange dphi(m, h)
- Ia_j the joint's rotor inertia (the model's armature), fv_j its viscous and fc_j its Coulomb friction;
- m the payload's mass and h = m dc its first moment about the flange (dc: its centre of mass off the
  flange), as the 10 dynamic parameters of a point mass at the flange plus dc, to first order in dc.
Y is Pinocchio's joint torque regressor (computeJointTorqueRegressor), pi_links the model's links'
dynamic parameters (Inertia.toDynamicParameters). The solve is scipy's linear least squares
(scipy.linalg.lstsq), weighted per joint by its residual's spread (two passes). Each value's
interval (CONFIDENCE, two-sided) is the widest of: the Newey-West sandwich over the time samples
(the residuals of filtered signals are correlated in time); a delete-a-block jackknife over BLOCKS
stretches of the run (model error that changes along it); how far the analysis's own choices move
the value (VARIANTS: the low-pass and the slowest rows kept); and MODEL_FLOOR of the value
(PAYLOAD_FLOOR_KG for the payload), for what rigid links with Coulomb and viscous friction cannot
describe of a drive. The first two are statistics; the last two are the model's own error, which
no residual shows.

Rows where a joint moves slower than MIN_SPEED are left out of that joint's equations: its Coulomb
friction's sign is undefined at rest (stiction, not this model).

The fit is poor (never written as an arm file) when a joint's residual RMS exceeds POOR_RESIDUAL of
its torque's RMS, or a rotor inertia or friction is not positive beyond its interval's doubt."""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

MIN_SPEED = 0.05       # rad/s: slower rows are not that joint's equations
DIFF_HZ = 30.0         # the zero-phase low-pass on q before differentiating it
FILTER_HZ = 10.0       # the low-pass on both sides of the equations before the fit
FIT_HZ = 100.0         # the rows' rate after it
POOR_RESIDUAL = 0.10   # of a joint's torque RMS: a residual above it is a poor fit
CONFIDENCE = 0.95
MODEL_FLOOR = 0.02      # of each value: the model's own error, a floor on its interval
PAYLOAD_FLOOR_KG = 0.02  # the same for the payload's mass, which may be 0
VARIANTS = [(f, v) for f in (5.0, 10.0, 20.0) for v in (0.05, 0.1, 0.2)]  # (low-pass Hz, slowest rad/s)
BLOCKS = 10            # contiguous stretches of the run for the jackknife
HAC_LAG_S = 0.5        # the Newey-West window: the residuals' correlation time (filtered, model error)


class FitError(ValueError):
    pass


@dataclass
class Estimate:
    value: float
    lo: float
    hi: float

    def as_dict(self) -> dict[str, float]:
        return {"value": self.value, "lo": self.lo, "hi": self.hi}


@dataclass
class Fit:
    names: list[str]
    rotor_inertia: list[Estimate]
    viscous: list[Estimate]
    coulomb: list[Estimate]
    payload_kg: Estimate
    payload_com: list[Estimate]            # dc, m, in the flange's frame (meaningful only for a payload)
    residual_fraction: list[float]         # per joint: residual RMS / torque RMS
    rows: list[int]                        # per joint: the samples in its equations
    condition: float
    poor: list[str] = field(default_factory=list)

    def as_dict(self) -> dict[str, Any]:
        return {"joints": {n: {"rotor_inertia": a.as_dict(), "viscous": v.as_dict(), "coulomb": c.as_dict(),
                               "residual_fraction": r, "rows": k}
                           for n, a, v, c, r, k in zip(self.names, self.rotor_inertia, self.viscous, self.coulomb,
                                                       self.residual_fraction, self.rows)},
                "payload_kg": self.payload_kg.as_dict(), "payload_com_m": [e.as_dict() for e in self.payload_com],
                "condition": self.condition, "confidence": CONFIDENCE, "poor": self.poor}


class ArmRegressor:
    """The model's known part and the unknowns' columns, from Pinocchio (the prepared arm.xml)."""

    def __init__(self, model_xml: Path, payload_frame: str = "payload") -> None:
        import pinocchio as pin

        self.pin = pin
        self.model = pin.buildModelFromMJCF(str(model_xml))
        self.data = self.model.createData()
        self.n = self.model.nv
        self.links = np.concatenate([self.model.inertias[i].toDynamicParameters() for i in range(1, self.model.njoints)])
        fid = self.model.getFrameId(payload_frame)
        if fid >= len(self.model.frames):
            raise FitError(f"the model has no site '{payload_frame}' to hang a payload on")
        frame = self.model.frames[fid]
        self.payload_joint = int(frame.parentJoint)
        s = np.asarray(frame.placement.translation, dtype=float)
        self.flange = s
        # d(dynamic parameters)/d(m, h): a point mass m at s + h/m, to first order in h
        # [m, m c, I about the joint frame's origin (xx, xy, yy, xz, yz, zz)] (Pinocchio's order)
        def inertia6(mat: np.ndarray) -> np.ndarray:
            return np.array([mat[0, 0], mat[0, 1], mat[1, 1], mat[0, 2], mat[1, 2], mat[2, 2]])
        eye = np.eye(3)
        dphi = np.zeros((10, 4))
        dphi[0, 0] = 1.0
        dphi[1:4, 0] = s
        dphi[4:, 0] = inertia6((s @ s) * eye - np.outer(s, s))
        for k in range(3):
            h = eye[k]
            dphi[1 + k, 1 + k] = 1.0
            dphi[4:, 1 + k] = inertia6(2 * (s @ h) * eye - np.outer(s, h) - np.outer(h, s))
        self.dphi = dphi

    @property
    def n_params(self) -> int:
        return 3 * self.n + 4

    def rows(self, q: np.ndarray, qd: np.ndarray, qdd: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """For each sample: the known torques (n,) and the unknowns' columns (n, 3n + 4)."""
        pin, n = self.pin, self.n
        T = q.shape[0]
        known = np.zeros((T, n))
        cols = np.zeros((T, n, self.n_params))
        j0 = 10 * (self.payload_joint - 1)
        idx = np.arange(n)
        for k in range(T):
            Y = pin.computeJointTorqueRegressor(self.model, self.data, q[k], qd[k], qdd[k])
            known[k] = Y @ self.links
            cols[k, idx, idx] = qdd[k]
            cols[k, idx, n + idx] = qd[k]
            cols[k, idx, 2 * n + idx] = np.sign(qd[k])
            cols[k, :, 3 * n:] = Y[:, j0:j0 + 10] @ self.dphi
        return known, cols

    def condition(self, q: np.ndarray, qd: np.ndarray, qdd: np.ndarray) -> float:
        """The condition number of the stacked unknowns' columns, each scaled to unit norm."""
        _, cols = self.rows(q, qd, qdd)
        A = cols.reshape(-1, self.n_params)
        norms = np.linalg.norm(A, axis=0)
        return float(np.linalg.cond(A / np.where(norms > 0, norms, 1.0)))


def prepare(t: np.ndarray, q: np.ndarray, tau: np.ndarray) -> tuple[np.ndarray, ...]:
    """Positions, velocities and accelerations at the log's rate (t uniform, at the loop rate; q
    smoothed by a zero-phase Butterworth low-pass at DIFF_HZ, then central differences), and the
    torques as logged: fit() filters both sides of the equations alike."""
    from scipy.signal import butter, sosfiltfilt

    dt = float(np.median(np.diff(t)))
    sos = butter(4, DIFF_HZ / (0.5 / dt), output="sos")
    qf = sosfiltfilt(sos, q, axis=0)
    qd = np.gradient(qf, dt, axis=0)
    qdd = np.gradient(qd, dt, axis=0)
    return t, qf, qd, qdd, tau


def _parallel_filter(t: np.ndarray, filter_hz: float, *arrays: np.ndarray) -> tuple[np.ndarray, ...]:
    """The same zero-phase low-pass at filter_hz on each array (along time), then every FIT_HZ-th
    sample without the filter's ends: the equations are linear in the unknowns, so filtering the
    torques and every column alike keeps them exact (a Coulomb term's step included)."""
    from scipy.signal import butter, sosfiltfilt

    dt = float(np.median(np.diff(t)))
    fs = 1.0 / dt
    sos = butter(4, filter_hz / (fs / 2), output="sos")
    step = max(1, int(round(fs / FIT_HZ)))
    edge = int(round(fs / min(FILTER_HZ, filter_hz))) * 2  # the same rows whatever the variant
    sl = slice(edge, len(t) - edge, step)
    return (t[sl], *[sosfiltfilt(sos, a, axis=0)[sl] for a in arrays])


def _solve(A: np.ndarray, b: np.ndarray) -> np.ndarray:
    from scipy.linalg import lstsq

    x, *_ = lstsq(A, b, lapack_driver="gelsd")
    return x


def _weighted(y: np.ndarray, cols: np.ndarray, use: np.ndarray) -> tuple[np.ndarray, ...]:
    """The least-squares solution weighted by 1 / each joint's residual spread (two passes): the
    unknowns, the residuals, each joint's residual spread and its weight."""
    n, P = cols.shape[1], cols.shape[2]
    w = np.ones(n)
    for _ in range(2):
        A = (cols * (w[None, :, None] * use[:, :, None])).reshape(-1, P)
        b = (y * w[None, :] * use).reshape(-1)
        norms = np.linalg.norm(A, axis=0)
        norms = np.where(norms > 0, norms, 1.0)
        x = _solve(A / norms, b) / norms
        r = y - np.einsum("tjp,p->tj", cols, x)
        sd = np.array([np.sqrt(np.mean(r[use[:, j], j] ** 2)) if use[:, j].any() else 0.0 for j in range(n)])
        w = 1.0 / np.maximum(sd, 1e-9)
    return x, r, sd, w


def _sandwich_variance(t: np.ndarray, Aw: np.ndarray, rw: np.ndarray) -> np.ndarray:
    """Each parameter's variance by the Newey-West sandwich over time samples: g_k = sum_j a_kj r_kj
    (the weighted rows of sample k)."""
    g = np.einsum("tjp,tj->tp", Aw, rw)                # (T, P)
    H = np.einsum("tjp,tjq->pq", Aw, Aw)
    lag = max(1, int(round(HAC_LAG_S / float(np.median(np.diff(t))))))
    S = g.T @ g
    for l in range(1, lag + 1):
        G = g[l:].T @ g[:-l]
        S += (1 - l / (lag + 1)) * (G + G.T)
    Hi = np.linalg.pinv(H)
    return np.maximum(np.diag(Hi @ S @ Hi), 0.0)


def _jackknife_variance(t: np.ndarray, Aw: np.ndarray, yw: np.ndarray, P: int) -> np.ndarray:
    """The delete-a-block jackknife over BLOCKS contiguous stretches: model error that changes along
    the trajectory (the drives' torque path, the friction's shape) shows as spread between them."""
    K = BLOCKS
    edges = np.linspace(0, len(t), K + 1).astype(int)
    thetas = []
    for k in range(K):
        keep = np.ones(len(t), bool)
        keep[edges[k]:edges[k + 1]] = False
        A_k = Aw[keep].reshape(-1, P)
        b_k = yw[keep].reshape(-1)
        nk = np.linalg.norm(A_k, axis=0)
        nk = np.where(nk > 0, nk, 1.0)
        thetas.append(_solve(A_k / nk, b_k) / nk)
    th = np.asarray(thetas)
    return (K - 1) / K * np.sum((th - th.mean(axis=0)) ** 2, axis=0)


def _analysis_spread(x: np.ndarray, n: int, t_all: np.ndarray, y_all: np.ndarray, cols_all: np.ndarray,
                     qd_all: np.ndarray) -> list[np.ndarray]:
    """Floors on each half-interval: the model's own error (Type B: what rigid links with Coulomb and
    viscous friction cannot capture of a drive), and how far the analysis's own choices (the
    low-pass, the slowest rows kept) move each value."""
    floor = MODEL_FLOOR * np.abs(x)
    floor[3 * n] = max(floor[3 * n], PAYLOAD_FLOOR_KG)
    moved = np.zeros(len(x))
    for filter_hz, min_speed in VARIANTS:
        _, yv, cv, qdv = _parallel_filter(t_all, filter_hz, y_all, cols_all, qd_all)
        moved = np.maximum(moved, np.abs(_weighted(yv, cv, np.abs(qdv) >= min_speed)[0] - x))
    return [floor, moved]


def _poor(f: Fit, names: list[str]) -> None:
    """What makes a fit too poor to write: a joint's torque the model leaves unexplained, or a value
    that is not positive."""
    for j, name in enumerate(names):
        if f.residual_fraction[j] > POOR_RESIDUAL:
            f.poor.append(f"joint {j + 1} ({name}): the model leaves {100 * f.residual_fraction[j]:.0f} % of its "
                          f"torque unexplained (at most {100 * POOR_RESIDUAL:.0f} %)")
        for what, e in (("rotor inertia", f.rotor_inertia[j]), ("viscous friction", f.viscous[j]),
                        ("Coulomb friction", f.coulomb[j])):
            if not e.hi > 0 or not math.isfinite(e.value):
                f.poor.append(f"joint {j + 1} ({name}): its {what} comes out {e.value:.3g}, not positive")


def fit(reg: ArmRegressor, t: np.ndarray, q: np.ndarray, qd: np.ndarray, qdd: np.ndarray, tau: np.ndarray,
        names: list[str]) -> Fit:
    from scipy.stats import norm
    from scipy.stats import t as student_t

    n, P = reg.n, reg.n_params
    known, cols_all = reg.rows(q, qd, qdd)
    y_all, t_all, qd_all = tau - known, t, qd
    t, y, cols, qd, tau = _parallel_filter(t_all, FILTER_HZ, y_all, cols_all, qd_all, tau)
    use = np.abs(qd) >= MIN_SPEED                      # (T, n)
    counts = use.sum(axis=0)
    for j, c in enumerate(counts):
        if c < 10 * 3:
            raise FitError(f"joint {j + 1} ({names[j]}) moved faster than {MIN_SPEED:g} rad/s in {int(c)} samples: "
                           "the arm did not follow the excitation (did it move? is a brake closed?)")
    x, r, sd, w = _weighted(y, cols, use)
    Aw = cols * (w[None, :, None] * use[:, :, None])   # (T, n, P)
    var = _sandwich_variance(t, Aw, r * w[None, :] * use)
    jack = _jackknife_variance(t, Aw, y * w[None, :] * use, P)
    z = float(norm.ppf(0.5 + CONFIDENCE / 2))
    tq = float(student_t.ppf(0.5 + CONFIDENCE / 2, BLOCKS - 1))
    half = np.maximum.reduce([np.maximum(z * np.sqrt(var), tq * np.sqrt(jack)),
                              *_analysis_spread(x, n, t_all, y_all, cols_all, qd_all)])

    def est(i: int) -> Estimate:
        return Estimate(float(x[i]), float(x[i] - half[i]), float(x[i] + half[i]))

    tau_rms = np.array([np.sqrt(np.mean(tau[use[:, j], j] ** 2)) for j in range(n)])
    resid = (sd / np.maximum(tau_rms, 1e-9)).tolist()
    m = est(3 * n)
    com = []
    for k in range(3):  # dc = h / m, its interval from h's (m's own doubt aside): meaningful for a payload
        h = est(3 * n + 1 + k)
        mm = max(m.value, 1e-9)
        com.append(Estimate(h.value / mm, h.lo / mm, h.hi / mm))
    An = (cols * use[:, :, None]).reshape(-1, P)
    norms = np.linalg.norm(An, axis=0)
    cond = float(np.linalg.cond(An / np.where(norms > 0, norms, 1.0)))
    f = Fit(names, [est(j) for j in range(n)], [est(n + j) for j in range(n)], [est(2 * n + j) for j in range(n)],
            m, com, resid, [int(c) for c in counts], cond)
    _poor(f, names)
    return f
