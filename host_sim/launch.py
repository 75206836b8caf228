"""The arm_sim command line (host_sim/native): what Python decides, turned into arguments.

The simulator's per-period work is C (build/<preset>/host_sim/native/arm_sim). Python keeps what
is configuration: the bus specs, the uncertainty (host_sim.uncertainty.UncertaintyConfig), and,
for bus timing, each frame's worst-case length on each bus, computed once by gen/lib/busload.py
(the same bit counts `armctl busload` prints) and handed over as --frame-times.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

from host_sim.drive_model import DriveModel
from host_sim.uncertainty import UncertaintyConfig
from gen.lib.cia402 import PDO_COB, pdo_bytes
from gen.lib import busload
from gen.lib.paths import build_dir

TIMING_MODES = ("off", "virtual", "wallclock")


def sim_binary(preset: str = "release") -> Path:
    return build_dir(preset) / "host_sim" / "native" / "arm_sim"


def parse_phy(text: str) -> tuple[bool, float, float | None]:
    """"fd:1M/5M", "fd:1M" (no bit-rate switch) or "classic:1M" -> (fd, nominal, data)."""
    kind, _, rates = text.partition(":")
    if kind not in ("fd", "classic") or not rates:
        raise busload.ConfigError(f"'{text}': expected fd:NOMINAL[/DATA] or classic:RATE (e.g. fd:1M/5M, classic:1M)")
    nominal, _, data = rates.partition("/")
    if kind == "classic" and data:
        raise busload.ConfigError(f"'{text}': a classic bus has one bit rate")
    return kind == "fd", busload.parse_rate(nominal), busload.parse_rate(data) if data else None


def frame_times(bus: busload.Bus, proto: busload.Protocol) -> str:
    """"ID:US,..." for every message of the DBC: its worst-case time on this bus (all its frames)."""
    out = []
    for msg in proto.db.messages:
        frames, _, _, seconds = busload.frame_time(msg, bus)
        out.append(f"{msg.frame_id}:{frames * seconds * 1e6:.6f}")
    return ",".join(out)


def canopen_frame_times(bus: busload.Bus) -> str:
    """"ID:US,..." for the CiA 402 drives on this bus (node id = drive number; CiA 301's predefined
    COB-IDs): SYNC, and per node TPDO1 0x180+n, RPDO1 0x200+n, TPDO2 0x280+n, EMCY 0x080+n and its
    heartbeat 0x700+n, each its worst-case time (gen/lib/busload.py)."""
    times = {0x080: busload.canopen_frame_s(0, bus)}
    for n in bus.drives:
        for name, cob in PDO_COB.items():
            times[cob + n] = busload.canopen_frame_s(pdo_bytes(name), bus)
        times[0x080 + n] = busload.canopen_frame_s(8, bus)
        times[0x700 + n] = busload.canopen_frame_s(1, bus)
    return ",".join(f"{i}:{t * 1e6:.6f}" for i, t in sorted(times.items()))


PLANT_FILE = "plant.xml"  # beside the prepared arm.xml (gen/arm.py): the arm with flexible joints


def uncertainty_args(unc: dict[str, Any] | UncertaintyConfig | None, model: Path | None = None) -> list[str]:
    """arm_sim's uncertainty options; validated first (the message names the field). model: the
    prepared arm.xml, whose plant.xml a flexible arm runs."""
    if unc is None:
        return []
    cfg = unc if isinstance(unc, UncertaintyConfig) else UncertaintyConfig.from_dict(unc)
    args = ["--seed", str(cfg.seed), "--paper-ratio", repr(cfg.paper_ratio), "--paper-knot-s", repr(cfg.paper_knot_s),
            "--mass-error", repr(cfg.mass_error), "--inertia-error", repr(cfg.inertia_error),
            "--com-error-m", repr(cfg.com_error_m)]
    if cfg.viscous:
        args += ["--viscous", ",".join(repr(float(x)) for x in cfg.viscous)]
    if cfg.coulomb:
        args += ["--coulomb", ",".join(repr(float(x)) for x in cfg.coulomb)]
    if cfg.flexible:
        if model is None:
            raise ValueError("uncertainty.flexible: the simulator's plant comes with the prepared arm (--model)")
        args += ["--plant", str(model.parent / PLANT_FILE)]
        if cfg.gear_stiffness_scale != 1.0:
            args += ["--gear-stiffness-scale", repr(float(cfg.gear_stiffness_scale))]
    if cfg.payload_kg and max(cfg.payload_kg) > 0:
        args += ["--payload-kg", ",".join(repr(float(x)) for x in cfg.payload_kg)]
    return args


def timing_args(mode: str, phys: list[busload.Bus], controller_latency_us: float = 0.0,
                canopen: bool = False) -> list[str]:
    """Bus timing emulation of these buses (one per --bus, in order), or nothing when off; canopen:
    of the CiA 402 drives' frames, else of the DBC's."""
    if mode not in TIMING_MODES:
        raise busload.ConfigError(f"bus timing '{mode}': expected one of {', '.join(TIMING_MODES)}")
    if mode == "off":
        return []
    args = ["--bus-timing", mode, "--controller-latency-us", repr(float(controller_latency_us))]
    for i, b in enumerate(phys):
        times = canopen_frame_times(b) if canopen else frame_times(b, busload.default_protocol())
        args += ["--frame-times", f"{i}={times}", "--bus-label", f"{i}={b.describe()}"]
    return args


def sim_argv(binary: Path, buses: list[str], *, lcm_url: str, summary: Path | None = None,
             uncertainty: dict[str, Any] | None = None, timing: str = "off", phys: list[busload.Bus] | None = None,
             controller_latency_us: float = 0.0, model: Path | None = None, drives: DriveModel | None = None,
             extra: list[str] | None = None, canopen: bool = False) -> list[str]:
    argv = [str(binary), *[a for spec in buses for a in ("--bus", spec)], "--lcm-url", lcm_url]
    if summary is not None:
        argv += ["--summary", str(summary)]
    if model is not None:
        argv += ["--model", str(model)]
    argv += uncertainty_args(uncertainty, model)
    argv += (drives or DriveModel()).args()
    argv += timing_args(timing, phys or [], controller_latency_us, canopen)
    return argv + list(extra or [])
