"""The identification's excitation (armctl identify): a finite Fourier series per joint (Swevers,
Ganseman, Tukel, De Schutter, Van Brussel, IEEE T-RA 13(5) 1997), periodic, at rest at its start,
within the joints' limits, chosen among seeded candidates for the smallest condition number of the
identification's regressor (tools/identify/fit.py) on the nominal model.

Joint i, harmonics l = 1..L of w = 2 pi / T:
    q_i(t) = q0_i + sum_l a_il / (w l) sin(w l t) - b_il / (w l) (cos(w l t) - 1)
with sum_l a_il = 0 (at rest at t = 0, hence at every period's start) and sum_l l b_il = 0 (no
acceleration there either), scaled so that max |q_i - q0_i| is the joint's amplitude.

check() refuses, before anything is enabled, an excitation the limits cannot hold: a joint leaving
its range (less MARGIN_RAD), or asking more speed or acceleration than a trajectory may
(gen/arm/reference.py: REF_MAX_VELOCITY, REF_MAX_ACCELERATION); one line naming the joint, the value
and what to change (ExcitationError). The torque a trajectory may take is then checked by armctl
run's own trajectory check (tools/run/trajectory.py), on the rows written here."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

MARGIN_RAD = 0.05     # the reference's own margin inside each range (docs/arm.md "The reference")
CANDIDATES = 24       # seeded coefficient sets tried for the regressor's condition number
CHECK_HZ = 200.0      # the limit check's sampling: the series has nothing above L / T Hz
ROW_HZ = 50.0         # the trajectory file's rows (the controller's spline between them)


class ExcitationError(ValueError):
    pass


@dataclass
class Excitation:
    q0: np.ndarray        # (n,) the centre, where each period starts and ends at rest
    a: np.ndarray         # (n, L) the velocity's cosine coefficients, rad/s
    b: np.ndarray         # (n, L) its sine coefficients
    period_s: float
    periods: int

    @property
    def duration_s(self) -> float:
        return self.period_s * self.periods

    def eval(self, t: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Position, velocity, acceleration at the times t: (len(t), n) each."""
        w = 2 * math.pi / self.period_s
        L = self.a.shape[1]
        wl = w * np.arange(1, L + 1)                  # (L,)
        s, c = np.sin(np.outer(t, wl)), np.cos(np.outer(t, wl))  # (T, L)
        q = self.q0 + s @ (self.a / wl).T - (c - 1) @ (self.b / wl).T
        qd = c @ self.a.T + s @ self.b.T
        qdd = -s @ (self.a * wl).T + c @ (self.b * wl).T
        return q, qd, qdd


def shape(rng: np.random.Generator, n: int, harmonics: int) -> tuple[np.ndarray, np.ndarray]:
    """Random coefficients meeting the rest constraints (sum a = 0, sum l b = 0)."""
    if harmonics < 2:
        raise ExcitationError(f"--harmonics {harmonics}: at least 2 (one harmonic cannot start at rest and move)")
    a = rng.standard_normal((n, harmonics))
    b = rng.standard_normal((n, harmonics))
    ls = np.arange(1, harmonics + 1)
    a -= a.mean(axis=1, keepdims=True)
    b -= np.outer(b @ ls, ls) / (ls @ ls)
    return a, b


def scaled(q0: np.ndarray, a: np.ndarray, b: np.ndarray, period_s: float, periods: int,
           amplitude: np.ndarray) -> Excitation:
    """The series with each joint's largest excursion from q0 equal to its amplitude."""
    ex = Excitation(q0, a, b, period_s, periods)
    t = np.arange(0.0, period_s, 1.0 / CHECK_HZ)
    q, _, _ = ex.eval(t)
    peak = np.max(np.abs(q - q0), axis=0)
    k = amplitude / np.where(peak > 0, peak, 1.0)
    return Excitation(q0, a * k[:, None], b * k[:, None], period_s, periods)


def check(ex: Excitation, joints: list[dict[str, Any]], max_speed: float, max_accel: float) -> dict[str, list[float]]:
    """ExcitationError naming the first joint the limits cannot hold; else each joint's peaks."""
    t = np.arange(0.0, ex.period_s + 0.5 / CHECK_HZ, 1.0 / CHECK_HZ)
    q, qd, qdd = ex.eval(t)
    for i, j in enumerate(joints):
        lo, hi = j["range"]
        lo, hi = lo + MARGIN_RAD, hi - MARGIN_RAD
        if not lo <= ex.q0[i] <= hi:
            raise ExcitationError(f"joint {i + 1} ({j['name']}): the centre {ex.q0[i]:.4g} rad is not {MARGIN_RAD:g} rad "
                                  f"inside its range [{j['range'][0]:g}, {j['range'][1]:g}]: the arm's home must be")
        qmin, qmax = float(q[:, i].min()), float(q[:, i].max())
        if qmin < lo or qmax > hi:
            room = min(ex.q0[i] - lo, hi - ex.q0[i])
            raise ExcitationError(f"joint {i + 1} ({j['name']}): the excitation spans [{qmin:.4g}, {qmax:.4g}] rad, "
                                  f"beyond its range [{j['range'][0]:g}, {j['range'][1]:g}] less {MARGIN_RAD:g} rad: "
                                  f"an --amplitude of at most {room:.3g} rad for it")
        v = float(np.abs(qd[:, i]).max())
        if v > max_speed:
            raise ExcitationError(f"joint {i + 1} ({j['name']}): the excitation's speed reaches {v:.4g} rad/s, above the "
                                  f"{max_speed:.4g} rad/s a trajectory may ask: a smaller --amplitude or a longer "
                                  "--period")
        acc = float(np.abs(qdd[:, i]).max())
        if acc > max_accel:
            raise ExcitationError(f"joint {i + 1} ({j['name']}): the excitation's acceleration reaches {acc:.4g} rad/s^2, "
                                  f"above the {max_accel:.4g} rad/s^2 a trajectory may ask: a smaller --amplitude, a "
                                  "longer --period or fewer --harmonics")
    return {"peak_speed": np.abs(qd).max(axis=0).tolist(), "peak_accel": np.abs(qdd).max(axis=0).tolist(),
            "q_min": q.min(axis=0).tolist(), "q_max": q.max(axis=0).tolist()}


def design(q0: np.ndarray, amplitude: np.ndarray, period_s: float, periods: int, harmonics: int, seed: int,
           conditioning: Any) -> tuple[Excitation, float]:
    """Among CANDIDATES seeded series, the one whose identification regressor (conditioning(q, qd,
    qdd) -> its condition number) is best conditioned: Swevers's criterion by random search."""
    rng = np.random.default_rng(seed)
    t = np.arange(0.0, period_s, 1.0 / (4 * harmonics / period_s * 10))  # 10 samples a period of the top harmonic, x4
    best: tuple[Excitation, float] | None = None
    for _ in range(CANDIDATES):
        a, b = shape(rng, len(q0), harmonics)
        ex = scaled(q0, a, b, period_s, periods, amplitude)
        cond = float(conditioning(*ex.eval(t)))
        if best is None or cond < best[1]:
            best = (ex, cond)
    assert best is not None
    return best


def rows(ex: Excitation) -> tuple[np.ndarray, np.ndarray]:
    """The trajectory file's rows: times and positions at ROW_HZ over every period, the last at rest."""
    t = np.append(np.arange(0.0, ex.duration_s, 1.0 / ROW_HZ), ex.duration_s)
    q, _, _ = ex.eval(t)
    return t, q


def write_csv(ex: Excitation, names: list[str], path: Any) -> None:
    from gen.lib.atomic_output import write_text_atomic

    t, q = rows(ex)
    lines = ["# armctl identify: a Fourier-series excitation (t, q per joint; s, rad)", "t," + ",".join(names)]
    lines += [",".join(repr(float(x)) for x in (tk, *qk)) for tk, qk in zip(t, q)]
    write_text_atomic(path, "\n".join(lines) + "\n")
