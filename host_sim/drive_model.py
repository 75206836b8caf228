"""The emulated drives' sensing and torque path, as configured (the C is host_sim/native/sim_servo.c).

A real servo drive sits between the controller and the joint. Its encoders quantise the position:
one at the joint, and on a geared joint one on the motor, gear-ratio times finer at the joint. Its
velocity is estimated from one encoder's differences (a real drive uses the motor's) and filtered, its measurements are noisy, and
its current loop follows the torque command with a lag and a transport latency. The ideal drive
(every field zero, the default) has none of these: it reports the true state and applies the
torque at once. REALISTIC is a documented default that resembles a real geared joint servo; its
sources are in docs/simulated-arm.md (Realistic drives).
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, fields
from typing import Any

from gen.lib.params import check_table, param

# Each field's arm_sim option: its range, unit and default are the registry's (firmware/params/params.toml).
OPTIONS = {"encoder_bits": "encoder-bits", "position_noise_counts": "position-noise-counts",
           "motor_encoder_bits": "motor-encoder-bits", "gear_ratio": "gear-ratio", "velocity_filter_hz": "velocity-filter-hz", "torque_noise_nm": "torque-noise-nm",
           "current_loop_hz": "current-loop-hz", "torque_latency_us": "torque-latency-us", "ripple": "ripple",
           "ripple_periods": "ripple-periods"}
SOURCES = param("simulator", "position-source").choices  # ("joint", "motor"), as arm_sim takes them
SOURCE_FIELDS = ("position_source", "velocity_source")  # --position-source, --velocity-source


@dataclass(frozen=True)
class DriveModel:
    encoder_bits: int = 0                 # counts per joint turn = 2^bits; 0: the true position
    position_noise_counts: float = 0.0    # Gaussian, sigma in each encoder's own counts
    motor_encoder_bits: int = 0           # counts per motor turn = 2^bits; 0: no motor encoder
    gear_ratio: float = 0.0               # motor turns per joint turn (with motor_encoder_bits)
    position_source: str = "joint"        # the encoder the reported position comes from: joint | motor
    velocity_source: str = "joint"        # the encoder whose differences give the velocity: joint | motor
    velocity_filter_hz: float = 0.0       # velocity from encoder differences, first-order low-pass; 0: true velocity
    torque_noise_nm: float = 0.0          # Gaussian noise on the reported torque, sigma
    current_loop_hz: float = 0.0          # first-order torque lag of this bandwidth; 0: immediate
    torque_latency_us: float = 0.0        # command arrival -> current loop
    ripple: float = 0.0                   # relative torque ripple amplitude
    ripple_periods: float = param("simulator", "ripple-periods").default  # per joint turn

    @classmethod
    def from_dict(cls, data: dict[str, Any], where: str = "drives") -> "DriveModel":
        check_table(data, {f.name for f in fields(cls)}, where)
        for k, v in data.items():
            if k in SOURCE_FIELDS:
                if v not in SOURCES:
                    raise ValueError(f"{where}.{k}: must be one of {', '.join(SOURCES)}, got {v!r}")
                continue
            # a field's range holds its default too: 0 bits, ratio 0, ... is the drive without it
            param("simulator", OPTIONS[k]).check(v, f"{where}.{k}", with_default=True)
        m = cls(**{k: (v if k in SOURCE_FIELDS else int(v) if param("simulator", OPTIONS[k]).type == "int" else float(v))
                   for k, v in data.items()})
        if m.position_noise_counts > 0 and m.encoder_bits == 0:
            raise ValueError(f"{where}.position_noise_counts: needs encoder_bits (noise in counts of what?)")
        if m.motor_encoder_bits > 0 and not m.gear_ratio >= 1:
            raise ValueError(f"{where}.gear_ratio: a motor encoder needs the gear ratio (>= 1), got {m.gear_ratio!r}")
        if m.gear_ratio > 0 and m.motor_encoder_bits == 0:
            raise ValueError(f"{where}.gear_ratio: only with motor_encoder_bits (the ratio of which encoder?)")
        for k in SOURCE_FIELDS:
            if getattr(m, k) == "motor" and m.motor_encoder_bits == 0:
                raise ValueError(f"{where}.{k}: 'motor' needs motor_encoder_bits and gear_ratio")
        if m.velocity_source == "motor" and m.velocity_filter_hz == 0:
            raise ValueError(f"{where}.velocity_source: 'motor' needs velocity_filter_hz (without it the velocity is the true one)")
        return m

    @property
    def ideal(self) -> bool:
        return self == DriveModel(ripple_periods=self.ripple_periods)

    def args(self) -> list[str]:
        """arm_sim's drive options (nothing for the ideal drive)."""
        if self.ideal:
            return []
        out = []
        for name, opt in OPTIONS.items():
            v = getattr(self, name)
            if v:
                out += [f"--{opt}", repr(v)]
        for name in SOURCE_FIELDS:
            if getattr(self, name) != "joint":
                out += [f"--{name.replace('_', '-')}", getattr(self, name)]
        return out

    def to_dict(self) -> dict[str, Any]:
        return asdict(self)


# A geared joint servo as sold for collaborative arms, with two encoders: a 19-bit absolute encoder
# at the joint reports the position, a 17-bit one on the motor, through the UR5e's 101:1 gear,
# gives the velocity (its differences low-passed at 500 Hz); one count of noise on each, 0.5 % of
# a 28 N m wrist drive's range as torque-measurement noise, a 1.5 kHz current loop and 100 us from
# the command's arrival to the current loop. Every figure's source or assumption: docs/simulated-arm.md,
# Realistic drives.
REALISTIC = DriveModel(encoder_bits=19, position_noise_counts=1.0, motor_encoder_bits=17, gear_ratio=101.0,
                       velocity_source="motor", velocity_filter_hz=500.0, torque_noise_nm=0.14,
                       current_loop_hz=1500.0, torque_latency_us=100.0)
