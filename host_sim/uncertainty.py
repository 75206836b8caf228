"""The simulated arm's model uncertainty, as configured (the dynamics are host_sim/native/sim_arm.c).

- paper-style (Kim & Kim 2024, Example 1 / Fig. 1): the true dynamics are
  (M + M~(t)) q_ddot + V + V~(t) = tau with random, time-varying M~, V~ bounded by
  ||M~|| <= r ||M|| and |V~_j| <= r |V_j| (r = 0.05 in the paper): M~ = (D M + M D) / 2 with
  D = diag(d_j(t)), V~_j = d'_j(t) V_j, and every d(t) a random piecewise-linear signal in [-r, r]
  with a new value every `paper_knot_s` seconds (so w has the high-frequency content of the
  paper's Fig. 6). V is MuJoCo's bias force: Coriolis, centrifugal and gravity.
- parametric: link masses, centres of mass and inertias of the simulated arm off from the
  nominal model (uniform in +-error, per link, seeded), plus joint friction the nominal model
  lacks: viscous b and Coulomb c, added to the true model's joint damping and frictionloss
  (MuJoCo integrates damping implicitly and makes frictionloss a constraint that sticks).
- flexible joints (gen/drivetrain.py): the arm's plant, every joint a rotor, a strain-wave gear's
  spring and damper and the link, the gears' stiffness scaled by gear_stiffness_scale;
- a payload at the flange: payload_kg [m] fixed, or [lo, hi] drawn by the seed.

One seed fixes everything: arm_sim draws from numpy's own generator (np.random.default_rng(seed),
reproduced bit for bit in host_sim/native/sim_rng.c), in a fixed order.
"""

from __future__ import annotations

import json
from dataclasses import asdict, dataclass, field, fields
from pathlib import Path
from typing import Any

from gen.lib.params import check_table, param



@dataclass
class UncertaintyConfig:
    seed: int = param("simulator", "seed").default
    paper_ratio: float = 0.0  # r; 0 disables the paper-style uncertainty
    paper_knot_s: float = param("simulator", "paper-knot-s").default
    mass_error: float = 0.0  # relative, per link
    inertia_error: float = 0.0  # relative, per link
    com_error_m: float = 0.0  # metres, per link and axis
    viscous: list[float] = field(default_factory=list)  # Nm s/rad per joint
    coulomb: list[float] = field(default_factory=list)  # Nm per joint
    flexible: bool = False  # the plant with flexible joints (arm.json drivetrain) instead of the rigid arm
    gear_stiffness_scale: float = param("simulator", "gear-stiffness-scale").default
    payload_kg: list[float] = field(default_factory=list)  # [] none, [m] fixed, [lo, hi] drawn by the seed

    @classmethod
    def from_dict(cls, data: dict[str, Any], where: str = "uncertainty") -> "UncertaintyConfig":
        check_table(data, {f.name for f in fields(cls)}, where)
        cfg = cls(**data)
        cfg.validate(where)
        return cfg

    @classmethod
    def from_file(cls, path: Path) -> "UncertaintyConfig":
        return cls.from_dict(json.loads(path.read_text()), str(path))

    def validate(self, where: str = "uncertainty") -> None:
        if isinstance(self.seed, bool) or not isinstance(self.seed, int) or not 0 <= self.seed < 2**64:
            raise ValueError(f"{where}.seed: must be a whole number in 0..2^64-1, got {self.seed!r}")
        for name in ("paper_ratio", "mass_error", "inertia_error", "com_error_m", "paper_knot_s"):
            param("simulator", name.replace("_", "-")).check(getattr(self, name), f"{where}.{name}")
        if not isinstance(self.flexible, bool):
            raise ValueError(f"{where}.flexible: true or false, got {self.flexible!r}")
        param("simulator", "gear-stiffness-scale").check(self.gear_stiffness_scale, f"{where}.gear_stiffness_scale")
        if self.gear_stiffness_scale != 1.0 and not self.flexible:
            raise ValueError(f"{where}.gear_stiffness_scale: scales the gears of a flexible arm (flexible = true)")
        pk = self.payload_kg
        if not isinstance(pk, list) or len(pk) > 2:
            raise ValueError(f"{where}.payload_kg: [m] or [lo, hi] (kg), got {pk!r}")
        for i, x in enumerate(pk):
            param("simulator", "payload-kg").check(x, f"{where}.payload_kg[{i}]")
        if len(pk) == 2 and pk[1] < pk[0]:
            raise ValueError(f"{where}.payload_kg: [lo, hi] with lo <= hi, got {pk!r}")
        for name in ("viscous", "coulomb"):
            vals = getattr(self, name)
            p = param("simulator", name)
            if not isinstance(vals, list):
                raise ValueError(f"{where}.{name}: must be a list of friction coefficients in {p.range_text()}, "
                                 f"got {vals!r}")
            for i, x in enumerate(vals):
                p.check(x, f"{where}.{name}[{i}]")

    def to_dict(self) -> dict[str, Any]:
        return asdict(self)
