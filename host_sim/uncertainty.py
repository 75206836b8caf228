"""Model uncertainty of the simulated arm, seeded and combinable.

- paper-style (Kim & Kim 2024, Example 1 / Fig. 1): the true dynamics are
  (M + M~(t)) q_ddot + V + V~(t) = tau with random, time-varying M~, V~ bounded by
  ||M~|| <= r ||M|| and |V~_j| <= r |V_j| (r = 0.05 in the paper): M~ = (D M + M D) / 2 with
  D = diag(d_j(t)), V~_j = d'_j(t) V_j, and every d(t) a random piecewise-linear signal in [-r, r]
  with a new value every `knot_s` seconds (so w has the high-frequency content of the paper's
  Fig. 6). V is MuJoCo's bias force: Coriolis, centrifugal and gravity.
- parametric: link masses, centres of mass and inertias of the simulated arm off from the
  nominal model (uniform in +-error, per link, seeded), plus joint friction the nominal model
  lacks: tau_f = -b qd - c tanh(qd / 0.01).
"""

from __future__ import annotations

import json
from dataclasses import asdict, dataclass, field
from pathlib import Path

import mujoco
import numpy as np


@dataclass
class UncertaintyConfig:
    seed: int = 1
    paper_ratio: float = 0.0  # r; 0 disables the paper-style uncertainty
    paper_knot_s: float = 0.05
    mass_error: float = 0.0  # relative, per link
    inertia_error: float = 0.0  # relative, per link
    com_error_m: float = 0.0  # metres, per link and axis
    viscous: list[float] = field(default_factory=list)  # Nm s/rad per joint
    coulomb: list[float] = field(default_factory=list)  # Nm per joint

    @classmethod
    def from_file(cls, path: Path) -> "UncertaintyConfig":
        data = json.loads(path.read_text())
        unknown = set(data) - set(cls.__dataclass_fields__)
        if unknown:
            raise ValueError(f"{path}: unknown uncertainty field(s) {sorted(unknown)}")
        cfg = cls(**data)
        cfg.validate()
        return cfg

    def validate(self) -> None:
        for name in ("paper_ratio", "mass_error", "inertia_error", "com_error_m"):
            v = getattr(self, name)
            if not (0.0 <= v < 1.0):
                raise ValueError(f"uncertainty.{name}: must be in [0, 1), got {v}")
        if not self.paper_knot_s > 0:
            raise ValueError(f"uncertainty.paper_knot_s: must be > 0, got {self.paper_knot_s}")
        for name in ("viscous", "coulomb"):
            if any(x < 0 for x in getattr(self, name)):
                raise ValueError(f"uncertainty.{name}: friction coefficients must be >= 0")

    def to_dict(self) -> dict:
        return asdict(self)


class RandomSignal:
    """Piecewise-linear random signal in [-amp, amp], one value per knot, per channel."""

    def __init__(self, rng: np.random.Generator, channels: int, amp: float, knot_s: float) -> None:
        self.rng, self.amp, self.knot_s = rng, amp, knot_s
        self.knots = [rng.uniform(-amp, amp, channels), rng.uniform(-amp, amp, channels)]
        self.index = 0

    def __call__(self, t: float) -> np.ndarray:
        k = int(t // self.knot_s)
        while self.index < k:  # time only moves forward in a run
            self.knots = [self.knots[1], self.rng.uniform(-self.amp, self.amp, len(self.knots[1]))]
            self.index += 1
        frac = t / self.knot_s - k
        return (1.0 - frac) * self.knots[0] + frac * self.knots[1]


def perturb_model(model: mujoco.MjModel, cfg: UncertaintyConfig, rng: np.random.Generator) -> None:
    """Parametric error: the simulated arm's links differ from the nominal ones."""
    for b in range(1, model.nbody):
        if cfg.mass_error:
            model.body_mass[b] *= 1.0 + rng.uniform(-cfg.mass_error, cfg.mass_error)
        if cfg.inertia_error:
            model.body_inertia[b] *= 1.0 + rng.uniform(-cfg.inertia_error, cfg.inertia_error)
        if cfg.com_error_m:
            model.body_ipos[b] += rng.uniform(-cfg.com_error_m, cfg.com_error_m, 3)


class Uncertainty:
    def __init__(self, cfg: UncertaintyConfig, n: int) -> None:
        self.cfg = cfg
        self.rng = np.random.default_rng(cfg.seed)
        self.n = n
        r = cfg.paper_ratio
        # One signal of 2n channels: d for M~ (first n) and d' for V~ (last n).
        self.d = RandomSignal(self.rng, 2 * n, r, cfg.paper_knot_s) if r else None
        self.viscous = np.array(cfg.viscous or [0.0] * n)
        self.coulomb = np.array(cfg.coulomb or [0.0] * n)
        if len(self.viscous) != n or len(self.coulomb) != n:
            raise ValueError(f"uncertainty.viscous/coulomb: need {n} values each")
        self.friction = bool(self.viscous.any() or self.coulomb.any())

    @property
    def time_varying(self) -> bool:
        return self.d is not None

    def extra_force(self, t: float, mass: np.ndarray, bias: np.ndarray, tau: np.ndarray,
                    qd: np.ndarray) -> np.ndarray:
        """The generalized force that makes MuJoCo integrate the uncertain dynamics.

        With M, V from MuJoCo for the (parametrically perturbed) arm, the true acceleration is
        qdd = (M + M~)^-1 (tau + tau_f - V - V~); returned is f with M qdd + V = tau + f.
        """
        tau_f = -self.viscous * qd - self.coulomb * np.tanh(qd / 0.01) if self.friction else 0.0
        if self.d is None:
            return tau_f
        dd = self.d(t)
        d, dv = dd[: self.n], dd[self.n:]
        m_true = mass + 0.5 * (d[:, None] * mass + mass * d[None, :])
        qdd = np.linalg.solve(m_true, tau + tau_f - bias * (1.0 + dv))
        return mass @ qdd + bias - tau
