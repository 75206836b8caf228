"""The emulated drives' sensing and torque path, as configured (the C is host_sim/native/sim_servo.c).

A real servo drive sits between the controller and the joint. Its encoder quantises the position,
its velocity is estimated from encoder differences and filtered, its measurements are noisy, and
its current loop follows the torque command with a lag and a transport latency. The ideal drive
(every field zero, the default) has none of these: it reports the true state and applies the
torque at once. REALISTIC is a documented default that resembles a real joint servo; its sources
are in the README (Realistic drives).
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, fields
from typing import Any


@dataclass(frozen=True)
class DriveModel:
    encoder_bits: int = 0                 # counts per joint turn = 2^bits; 0: the true position
    position_noise_counts: float = 0.0    # Gaussian, sigma in encoder counts
    velocity_filter_hz: float = 0.0       # velocity from encoder differences, first-order low-pass; 0: true velocity
    torque_noise_nm: float = 0.0          # Gaussian noise on the reported torque, sigma
    current_loop_hz: float = 0.0          # first-order torque lag of this bandwidth; 0: immediate
    torque_latency_us: float = 0.0        # command arrival -> current loop
    ripple: float = 0.0                   # relative torque ripple amplitude
    ripple_periods: float = 6.0           # ripple periods per joint turn

    @classmethod
    def from_dict(cls, data: dict[str, Any], where: str = "drives") -> "DriveModel":
        if not isinstance(data, dict):
            raise ValueError(f"{where}: expected a table of fields, got {type(data).__name__}")
        known = {f.name for f in fields(cls)}
        unknown = set(data) - known
        if unknown:
            raise ValueError(f"{where}: unknown field(s) {sorted(unknown)} (known: {', '.join(sorted(known))})")
        limits = {"encoder_bits": (0, 32), "position_noise_counts": (0, 1e6), "velocity_filter_hz": (0, 1e6),
                  "torque_noise_nm": (0, 1e4), "current_loop_hz": (0, 1e7), "torque_latency_us": (0, 1e6),
                  "ripple": (0, 1), "ripple_periods": (0, 1e4)}
        for k, v in data.items():
            lo, hi = limits[k]
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v) or not lo <= v <= hi:
                raise ValueError(f"{where}.{k}: must be a number in [{lo:g}, {hi:g}], got {v!r}")
        if "encoder_bits" in data and data["encoder_bits"] != int(data["encoder_bits"]):
            raise ValueError(f"{where}.encoder_bits: must be a whole number, got {data['encoder_bits']!r}")
        m = cls(**{k: (int(v) if k == "encoder_bits" else float(v)) for k, v in data.items()})
        if m.position_noise_counts > 0 and m.encoder_bits == 0:
            raise ValueError(f"{where}.position_noise_counts: needs encoder_bits (noise in counts of what?)")
        return m

    @property
    def ideal(self) -> bool:
        return self == DriveModel(ripple_periods=self.ripple_periods)

    def args(self) -> list[str]:
        """arm_sim's drive options (nothing for the ideal drive)."""
        if self.ideal:
            return []
        out = []
        for name, opt in (("encoder_bits", "--encoder-bits"), ("position_noise_counts", "--position-noise-counts"),
                          ("velocity_filter_hz", "--velocity-filter-hz"), ("torque_noise_nm", "--torque-noise-nm"),
                          ("current_loop_hz", "--current-loop-hz"), ("torque_latency_us", "--torque-latency-us"),
                          ("ripple", "--ripple"), ("ripple_periods", "--ripple-periods")):
            v = getattr(self, name)
            if v:
                out += [opt, repr(v)]
        return out

    def to_dict(self) -> dict[str, Any]:
        return asdict(self)


# A joint servo as sold for collaborative arms: a 19-bit absolute encoder at the joint, velocity
# from its differences low-passed at 500 Hz, one count of position noise, 0.5 % of a 28 N m
# wrist drive's range as torque-measurement noise, a 1.5 kHz current loop and 100 us from the
# command's arrival to the current loop.
REALISTIC = DriveModel(encoder_bits=19, position_noise_counts=1.0, velocity_filter_hz=500.0, torque_noise_nm=0.14,
                       current_loop_hz=1500.0, torque_latency_us=100.0)
