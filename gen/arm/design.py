"""Stage 9, design: the design config the arm is built with. The one asked for (--design, or the arm
file's), the paper's weights for the bundled arm, else the default design: the paper's estimator with
a critically damped static controller u_o = -(wn^2 e + 2 wn e_dot) (gen/configs/wn40.toml's form),
wn the largest at which a tracking error at the bound asks no joint at home for more than the
torque the reference leaves it ((1 - REF_TORQUE_FRACTION) of its limit), within
[AUTO_WN_MIN, AUTO_WN_MAX] rad/s (the top: tracked by the 1 kHz loop in every arm tested). The
paper's own weights make a 4.5 rad/s loop, which leaves light wrists 20-27 deg behind."""

from __future__ import annotations

import math
import re
import tomllib
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from gen.arm.arm_file import DEFAULT_DESIGN, DEFAULT_MODEL, ArmFile
from gen.arm.errors import ArmError
from gen.arm.reference import REF_TORQUE_FRACTION
from gen.arm.write import MIN_JOINT_INERTIA
from gen.lib import toml_input
from gen.lib.bounds import DEFAULT_MAX_ERROR_DEG

AUTO_WN_MIN, AUTO_WN_MAX = 5.0, 40.0


@dataclass
class DesignConfig:
    path: Path          # the config file the design starts from
    text: str
    rate: float         # arm.loop_rate_hz: the loop period is the simulator's timestep


def design_config(af: ArmFile, design: Path | None) -> DesignConfig:
    """Stage 0: the design config's file and loop rate (the timestep of the prepared model)."""
    path = af.design or design or DEFAULT_DESIGN
    try:
        text = path.read_text()
        doc = toml_input.loads(text)
    except (OSError, UnicodeDecodeError, tomllib.TOMLDecodeError) as exc:
        raise ArmError(f"design config {path}: {exc}") from exc
    rate = doc.get("arm", {}).get("loop_rate_hz") if isinstance(doc.get("arm"), dict) else None
    if isinstance(rate, bool) or not isinstance(rate, (int, float)) or not 10 <= rate <= 20000:
        raise ArmError(f"design config {path}: arm.loop_rate_hz: expected a number in [10, 20000], got {rate!r}")
    return DesignConfig(path, text, float(rate))


def arm_design(cfg: DesignConfig, af: ArmFile, design: Path | None, inertia_at_home: np.ndarray,
               limits: list[float], names: list[str]) -> tuple[dict[str, Any], str]:
    """arm.json's design (which config, and why) and design.toml's text (n_joints the arm's)."""
    path = af.model.resolve()
    text = cfg.text
    bundled = path == DEFAULT_MODEL.resolve() and not af.design and (
        design is None or design.resolve() == DEFAULT_DESIGN.resolve())
    if af.design or design or bundled:
        why = ("the bundled arm's default, the paper's weights (its kept study tuning is keyed by them)" if bundled
               else f"the arm file's ({af.path})" if af.design else "asked for (--design)")
        info: dict[str, Any] = {"config": str(cfg.path), "why": why}
    else:
        wn, limiting = auto_bandwidth(inertia_at_home, limits)
        text = with_static_controller(text, wn)
        info = {"config": f"{cfg.path} with a critically damped {wn:.3g} rad/s controller", "wn_rad_s": wn,
                "why": (f"no design given: the largest bandwidth (in [{AUTO_WN_MIN:g}, {AUTO_WN_MAX:g}] rad/s) "
                        f"at which a {DEFAULT_MAX_ERROR_DEG:g} deg tracking error asks no joint at home for "
                        f"more than the {1 - REF_TORQUE_FRACTION:.0%} of its torque limit the reference "
                        f"leaves it (the tightest: {names[limiting]}); --design gen/configs/paper.toml "
                        "for the paper's weights")}
    return info, design_for(text, len(names), cfg.path)


def auto_bandwidth(inertia_at_home: Any, torque_limits: list[float]) -> tuple[float, int]:
    """The default design's wn (AUTO_WN_MIN..AUTO_WN_MAX), and the joint that bounds it: the feedback
    M_jj wn^2 e of an error e at the tracking bound within the torque the reference leaves."""
    e = math.radians(DEFAULT_MAX_ERROR_DEG)
    room = [(1.0 - REF_TORQUE_FRACTION) * lim / (max(float(mjj), MIN_JOINT_INERTIA) * e)
            for mjj, lim in zip(inertia_at_home, torque_limits)]
    j = int(np.argmin(room))
    return float(min(AUTO_WN_MAX, max(AUTO_WN_MIN, math.sqrt(room[j])))), j


def with_static_controller(design_text: str, wn: float) -> str:
    """The design config with its [controller] replaced by u_o = -(wn^2 e + 2 wn e_dot): z_o = E1 e +
    E2 e_dot + D12 u_o with E1 = wn^2, E2 = 2 wn, D12 = 1 (one row: the static zeroing gain)."""
    table = f"[controller]\nE1 = [[{wn * wn!r}]]\nE2 = [[{2.0 * wn!r}]]\nD12 = [[1.0]]\n"
    out, count = re.subn(r"(?ms)^\[controller\].*?(?=^\[|\Z)", table + "\n", design_text, count=1)
    if count != 1:
        raise ArmError("design config: no [controller] table to set the default bandwidth in")
    return re.sub(r'(?m)^(\s*description\s*=\s*")', lambda mm: f"{mm.group(1)}default for the arm: {wn:.3g} rad/s "
                  "controller; ", out, count=1)


def design_for(text: str, n: int, path: Path) -> str:
    """The design config with arm.n_joints = n (its weights are one joint's, applied to every joint)."""
    out, count = re.subn(r"(?m)^(\s*n_joints\s*=\s*)\d+", lambda mm: f"{mm.group(1)}{n}", text, count=1)
    if count != 1:
        raise ArmError(f"design config {path}: arm.n_joints: missing")
    # a description that counts joints ("..., 6 joints, ...") counts the arm's
    out = re.sub(r'(?m)^(\s*description\s*=\s*".*?)\b\d+ joints\b', lambda mm: f"{mm.group(1)}{n} joints", out, count=1)
    return f"# {path} with n_joints from the arm model (gen/arm)\n" + out
