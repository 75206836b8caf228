"""The study configuration (tools/studies/*.toml), validated field by field."""

from __future__ import annotations

import itertools
import tomllib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from host_sim.uncertainty import UncertaintyConfig

METHODS = ("pm", "pm-paper", "pd", "gh2", "tde", "usde-smc")
TUNED = ("pd", "tde", "usde-smc")  # pm, pm-paper and gh2 take their gains from the LMI design
MAX_JOINTS = 16


class StudyConfigError(ValueError):
    pass


@dataclass
class Trajectory:
    amp: list[float]
    freq_hz: list[float]

    def args(self) -> list[str]:
        return ["--ref-amp", ",".join(f"{a:g}" for a in self.amp), "--ref-freq", ",".join(f"{f:g}" for f in self.freq_hz)]


@dataclass
class StudyConfig:
    path: Path
    description: str
    duration_s: float
    hold_s: float
    seed: int
    methods: list[str]
    uncertainty: dict[str, Any]
    trajectory: Trajectory
    tuning_seed: int
    tuning_duration_s: float
    tuning_trajectory: Trajectory
    tuning_objective: str
    gains_file: Path
    grid: dict[str, dict[str, list[float]]] = field(default_factory=dict)
    bus_timing: bool = False  # emulate the buses' bit timing in every run (tools/hil.py)

    def uncertainty_for(self, seed: int) -> dict[str, Any]:
        return {**self.uncertainty, "seed": seed}


def _get(d: dict[str, Any], key: str, where: str, kind: type | tuple[type, ...]) -> Any:
    if key not in d:
        raise StudyConfigError(f"{where}.{key}: missing")
    v = d[key]
    if not isinstance(v, kind) or isinstance(v, bool):
        raise StudyConfigError(f"{where}.{key}: expected {getattr(kind, '__name__', kind)}, got {v!r}")
    return v


def _positive(v: float, name: str) -> float:
    if not v > 0:
        raise StudyConfigError(f"{name}: must be > 0, got {v}")
    return float(v)


def _trajectory(d: dict[str, Any], where: str) -> Trajectory:
    amp = _get(d, "amp", where, list)
    freq = _get(d, "freq_hz", where, list)
    for name, vals, lo, hi in (("amp", amp, -3.2, 3.2), ("freq_hz", freq, 0.0, 50.0)):
        if not 1 <= len(vals) <= MAX_JOINTS or not all(
                isinstance(x, (int, float)) and not isinstance(x, bool) and lo <= x <= hi for x in vals):
            raise StudyConfigError(f"{where}.{name}: need one number per joint, each in [{lo:g}, {hi:g}], "
                                   f"got {vals!r}")
    if len(amp) != len(freq):
        raise StudyConfigError(f"{where}.amp: {len(amp)} values, but freq_hz has {len(freq)} (one of each per joint)")
    return Trajectory([float(a) for a in amp], [float(f) for f in freq])


def load(path: Path) -> StudyConfig:
    try:
        data = tomllib.loads(path.read_text())
    except (OSError, tomllib.TOMLDecodeError) as exc:
        raise StudyConfigError(f"{path}: {exc}") from exc
    methods = _get(data, "methods", "study", list)
    bad = [m for m in methods if m not in METHODS]
    if bad or not methods:
        raise StudyConfigError(f"study.methods: unknown {bad} (known: {', '.join(METHODS)})")
    unc = dict(_get(data, "uncertainty", "study", dict))
    try:
        UncertaintyConfig(**{**unc, "seed": 0}).validate()
    except TypeError as exc:
        raise StudyConfigError(f"uncertainty: {exc}") from exc
    except ValueError as exc:
        raise StudyConfigError(str(exc)) from exc
    bus_timing = data.get("bus_timing", False)
    if not isinstance(bus_timing, bool):
        raise StudyConfigError(f"study.bus_timing: expected true or false, got {bus_timing!r}")
    tuning = _get(data, "tuning", "study", dict)
    grid = tuning.get("grid", {})
    for m, g in grid.items():
        if m not in TUNED:
            raise StudyConfigError(f"tuning.grid.{m}: only {', '.join(TUNED)} are tuned")
        for k, vals in g.items():
            if not isinstance(vals, list) or not vals or not all(isinstance(x, (int, float)) and x > 0 for x in vals):
                raise StudyConfigError(f"tuning.grid.{m}.{k}: need a list of positive numbers")
    return StudyConfig(
        path=path,
        description=str(data.get("description", "")),
        duration_s=_positive(_get(data, "duration_s", "study", (int, float)), "study.duration_s"),
        hold_s=float(_get(data, "hold_s", "study", (int, float))),
        seed=_get(data, "seed", "study", int),
        methods=list(methods),
        uncertainty=unc,
        trajectory=_trajectory(_get(data, "trajectory", "study", dict), "trajectory"),
        tuning_seed=_get(tuning, "seed", "tuning", int),
        tuning_duration_s=_positive(_get(tuning, "duration_s", "tuning", (int, float)), "tuning.duration_s"),
        tuning_trajectory=_trajectory(tuning, "tuning"),
        tuning_objective=str(tuning.get("objective", "")),
        gains_file=path.parent / _get(tuning, "gains_file", "tuning", str),
        grid=grid,
        bus_timing=bus_timing,
    )


def gain_args(method: str, gains: dict[str, float]) -> list[str]:
    """Controller arguments for one method's gains (the grid's parameter names)."""
    if method in ("pd", "tde"):
        wn = gains["wn"]
        args = ["--kp", f"{wn * wn:g}", "--kd", f"{2 * wn:g}"]
        if method == "tde":
            args += ["--tde-cutoff", f"{gains['cutoff_hz']:g}"]
        return args
    if method == "usde-smc":
        lam = gains["lambda"]
        return ["--usde-k", f"{gains['k']:g}", "--smc-lambda", f"{lam:g}", "--smc-ks", f"{lam:g}",
                "--smc-eta", "1", "--smc-phi", "0.05"]
    return []


def grid_points(grid: dict[str, list[float]]) -> list[dict[str, float]]:
    keys = sorted(grid)
    return [dict(zip(keys, combo)) for combo in itertools.product(*(grid[k] for k in keys))]
