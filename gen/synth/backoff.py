"""The back-off rule: the smallest gamma on a ladder whose sampled-data loop is stable with margin.

gamma_opt is an infimum (the estimator's is not attained), and the closer gamma_design gets to it
the faster the estimator: at the paper's weights its bandwidth grows like 0.5 / (gamma - 0.5).
What limits it is the loop rate, so the rule walks up gamma_opt * (1 + r) for r in the ladder
and takes the first rung whose discretised loops pass `margin_checks`:
  - every continuous closed loop is stable and the verified norm is within the rung's gamma;
  - the synthesised system itself is stable once discretised (needed for finite L1 bounds);
  - the ZOH sampled-data loop of every structure (decoupled and paper) is Schur-stable, and
    stays Schur-stable with `delay` extra periods of actuation latency (the margin).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any, Generic, TypeVar

import numpy as np

from gen.synth.discretize import zoh
from gen.synth.loops import STRUCTURES, combined_loop
from gen.synth.ss import StateSpace
from gen.synth.verify import max_real_part, spectral_radius

RHO_TOL = 1e-9  # a discrete pole must be this far inside the unit circle to count as stable

T_co = TypeVar("T_co")


@dataclass
class Rung:
    relative: float
    gamma: float
    accepted: bool
    reason: str
    checks: dict[str, Any] = field(default_factory=dict)

    def to_json(self) -> dict[str, Any]:
        return {"relative": self.relative, "gamma": self.gamma, "accepted": self.accepted, "reason": self.reason, **self.checks}


@dataclass
class LadderResult(Generic[T_co]):
    chosen: T_co | None
    rung: Rung | None
    rungs: list[Rung]


def margin_checks(
    plant_c: StateSpace, plant_d: StateSpace, C: StateSpace, K: StateSpace | None, T: float, delay: int
) -> tuple[bool, str, dict[str, Any]]:
    """Stability of the continuous and sampled loops (with and without the delay margin)."""
    checks: dict[str, Any] = {}
    Cd = zoh(C, T)
    Kd = zoh(K, T) if K is not None else None
    for name, sysd in (("controller", Cd), ("estimator", Kd)):
        if sysd is not None:
            checks[f"{name}_discrete_spectral_radius"] = spectral_radius(sysd.A)
            if checks[f"{name}_discrete_spectral_radius"] >= 1 - RHO_TOL:
                return False, f"the discretised {name} itself is not stable (no finite fixed-point bound)", checks
    structures = STRUCTURES if K is not None else ("decoupled",)
    for st in structures:
        mr = max_real_part(combined_loop(plant_c, C, K, st).A)
        rho = spectral_radius(combined_loop(plant_d, Cd, Kd, st).A)
        rho_d = spectral_radius(combined_loop(plant_d, Cd, Kd, st, delay=delay).A) if delay else rho
        checks[st] = {"continuous_max_real_part": mr, "sampled_spectral_radius": rho, "sampled_spectral_radius_delayed": rho_d}
        if mr >= 0:
            return False, f"{st} continuous loop unstable (max Re {mr:.4g})", checks
        if rho >= 1 - RHO_TOL:
            return False, f"{st} sampled loop unstable at {1 / T:g} Hz (rho {rho:.6f})", checks
        if rho_d >= 1 - RHO_TOL:
            return False, f"{st} sampled loop unstable with {delay} period(s) of delay (rho {rho_d:.6f})", checks
    return True, "stable with margin", checks


def walk_ladder(
    gamma_opt: float, ladder: tuple[float, ...], attempt: Callable[[float, float], tuple[T_co | None, Rung]]
) -> LadderResult[T_co]:
    """Try gamma_opt * (1 + r) for each r in order; stop at the first accepted rung."""
    rungs: list[Rung] = []
    for r in ladder:
        chosen, rung = attempt(r, gamma_opt * (1.0 + r))
        rungs.append(rung)
        if rung.accepted:
            return LadderResult(chosen, rung, rungs)
    return LadderResult(None, None, rungs)


def finite(x: float) -> float | None:
    """JSON has no inf/nan; the manifest records them as null."""
    return float(x) if np.isfinite(x) else None
