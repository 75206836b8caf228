"""Which arm a command works on (--model / --arm), and where its build lives.

Every command that builds or runs takes the same arm options. The arm is prepared at build time
(gen/arm, a CMake step), so one build folder holds everything of one arm: the prepared model,
arm.json, the design, the firmware, the simulator. The bundled arm builds in build/<preset>; any
other in build/arms/<name>-<digest>/<preset>, side by side, so switching arms rebuilds nothing that
did not change.
"""

from __future__ import annotations

import argparse
import hashlib
import json
import sys
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from tools.build import build
from gen.lib.paths import BUILD, build_dir

MODEL_SUFFIXES = (".xml", ".urdf", ".mjcf")


class ArmChoiceError(ValueError):
    """--model / --arm / --design cannot be used as given; the message says which and why."""


@dataclass(frozen=True)
class ArmRef:
    model: Path | None = None  # an MJCF or URDF
    arm_file: Path | None = None  # an arm file (TOML), which names its model
    design: Path | None = None  # the design config when the arm file names none

    @property
    def is_default(self) -> bool:
        return self.model is None and self.arm_file is None and self.design is None

    def label(self) -> str:
        return str(self.arm_file or self.model or "the bundled arm")

    def key(self) -> str:
        """The build folder's name, <name>-<digest>: the arm's name (gen/arm: arm_name, the one
        in its reports) and a digest of the files that define it, so two arms of one name differ."""
        from gen.arm import arm_name_of

        digest = hashlib.sha256("\0".join(str(p) for p in (self.model, self.arm_file, self.design)).encode())
        return f"{arm_name_of(self.arm_file, self.model)[:32]}-{digest.hexdigest()[:8]}"

    def cache(self) -> dict[str, str]:
        out: dict[str, str] = {}
        if self.model is not None:
            out["ARM_MODEL"] = str(self.model)
        out["ARM_FILE"] = str(self.arm_file) if self.arm_file is not None else ""
        # always set: empty is the arm's own default design (gen/arm), and a build folder
        # configured before this default existed must not keep another one in its cache
        out["ARM_DESIGN_CONFIG"] = str(self.design) if self.design is not None else ""
        return out


DEFAULT_ARM = ArmRef()


def add_arm_arguments(p: argparse.ArgumentParser) -> None:
    g = p.add_argument_group("the arm (docs/arm.md)")
    g.add_argument("--model", type=Path, default=None, metavar="FILE",
                   help="the arm's MJCF (.xml) or URDF (.urdf) [the bundled UR5e-proportioned arm]")
    g.add_argument("--arm", type=Path, default=None, metavar="FILE",
                   help="an arm file (TOML): its model, the controlled joints, home pose, torque limits, "
                        "bus wiring and design config")
    g.add_argument("--design", type=Path, default=None, metavar="FILE",
                   help="design config when the arm file names none [the bundled arm: gen/configs/paper.toml; "
                        "another arm: its own, with a bandwidth that fits its torque limits and inertia]")


def arm_from_args(ns: argparse.Namespace) -> ArmRef:
    """The arm options checked up front (before anything builds or starts)."""
    model, arm_file, design = getattr(ns, "model", None), getattr(ns, "arm", None), getattr(ns, "design", None)
    if model is not None and arm_file is not None:
        raise ArmChoiceError("--model and --arm: give one (an arm file names its model)")
    for opt, p, suffixes in (("--model", model, MODEL_SUFFIXES), ("--arm", arm_file, (".toml",)),
                             ("--design", design, (".toml",))):
        if p is None:
            continue
        if not p.is_file():
            raise ArmChoiceError(f"{opt} {p}: no such file")
        if p.suffix.lower() not in suffixes:
            raise ArmChoiceError(f"{opt} {p}: expected a {' or '.join(suffixes)} file")
    if arm_file is not None:
        from gen.arm import ArmError, load_arm_file

        try:
            af = load_arm_file(arm_file.resolve())
        except ArmError as exc:
            raise ArmChoiceError(str(exc)) from exc
        model = af.model
        if not model.is_file():
            raise ArmChoiceError(f"arm file {arm_file}: model {model}: no such file")
    ref = ArmRef(model.resolve() if model else None, arm_file.resolve() if arm_file else None,
                 design.resolve() if design else None)
    from gen.lib.escape import EscapeError, cmake_value

    for opt, p in (("--model", ref.model), ("--arm", ref.arm_file), ("--design", ref.design)):
        try:  # the build takes each path as a CMake value (ArmRef.cache)
            cmake_value(str(p or ""), opt)
        except EscapeError as exc:
            raise ArmChoiceError(str(exc)) from None
    if not ref.is_default:
        _check_importable(ref)
    return ref


_PREPARED: dict[ArmRef, Any] = {}  # this process's check of an arm: the build takes it (seed_prepared)


def _check_importable(arm: ArmRef) -> None:
    """The importer's verdict before anything builds: its error (named element, what to change)
    instead of a failed build step, and no build folder for an arm that cannot be used."""
    from gen.arm import ArmError, load_arm_file, prepare

    try:
        _PREPARED[arm] = prepare(load_arm_file(arm.arm_file, None if arm.arm_file else arm.model), arm.design)
    except ArmError as exc:
        raise ArmChoiceError(str(exc)) from exc


def seed_prepared(bdir: Path, arm: ArmRef) -> None:
    """The prepared arm this process made when it checked the arm, written where the build's gen.arm
    step writes it, with the key of its inputs: that step then finds it done instead of preparing the
    arm a second time (a second or more of a first build)."""
    prep = _PREPARED.get(arm)
    if prep is None:
        return
    from gen.arm.cli import already_prepared, inputs_key, write_prepared

    out = bdir / "generated" / "arm"
    key = inputs_key(prep_model(arm), arm.arm_file, arm.design)
    if already_prepared(out, key) is None:
        write_prepared(out, prep, key)


def prep_model(arm: ArmRef) -> Path:
    from gen.arm import load_arm_file

    return load_arm_file(arm.arm_file, None if arm.arm_file else arm.model).model.resolve()


def arm_build_dir(preset: str, arm: ArmRef = DEFAULT_ARM) -> Path:
    return build_dir(preset) if arm.is_default else BUILD / "arms" / arm.key() / preset


# what a run needs (HIL or SIL; arm_pil_bridge: a processor-in-the-loop run's controller)
HIL_TARGETS = ["arm_controller", "arm_sim", "arm_lcm_logger", "arm_sil", "arm_pil_bridge"]


def targets_for(bus: str) -> list[str]:
    """What a run on this bus needs built: software in the loop needs arm_sil alone (a tuning
    trial's design is built in about half the time)."""
    return ["arm_sil"] if bus == "sil" else HIL_TARGETS


def build_arm(preset: str, arm: ArmRef = DEFAULT_ARM, quiet: bool = True, targets: list[str] | None = None) -> Path:
    """Configure (when needed) and build the preset for the arm (only `targets`, if given); its
    build folder."""
    bdir = arm_build_dir(preset, arm)
    if not arm.is_default:
        seed_prepared(bdir, arm)
    build(preset, quiet=quiet, bdir=None if arm.is_default else bdir, cache=None if arm.is_default else arm.cache(),
          targets=targets)
    return bdir


def arm_info(bdir: Path) -> dict[str, Any]:
    """arm.json of the arm a build folder was built for (gen/arm)."""
    path = bdir / "generated" / "arm" / "arm.json"
    try:
        return json.loads(path.read_text())
    except (OSError, ValueError) as exc:
        raise ArmChoiceError(f"{path}: the arm's description is missing or unreadable ({exc}): run tools/armctl "
                             "build with the same --model/--arm") from exc


def print_arm_warnings(info: dict[str, Any], prog: str) -> None:
    """The importer's warnings (arm.json): what it assumed or changed (a home pose from mid-range,
    the timestep, dropped meshes, locked joints, a massless link), printed by every command that
    prepared the arm, not only by build."""
    for w in info["warnings"]:
        print(f"{prog}: {info['name']}: {w}", file=sys.stderr)


def prepared_model(bdir: Path) -> Path:
    return bdir / "generated" / "arm" / "arm.xml"


def reference_for(info: dict[str, Any], amp: list[float] | None, freq: list[float] | None,
                  bdir: Path | None = None, friction: dict[str, list[float]] | None = None) -> tuple[
        list[float], list[float], list[str]]:
    """The reference for a run: the arm's default (arm.json), or the one asked for with every
    amplitude clipped so the motion stays inside the joint ranges (gen/arm: RANGE_MARGIN) and,
    given the build folder (its prepared model), so that its inverse dynamics with the friction a
    scenario adds (viscous, coulomb) fit the arm (gen/arm: fit_reference). The warnings say what
    was changed, one line a joint, naming the torque the asked-for amplitude would need."""
    from gen.arm import clip_amplitude, fit_reference

    n = info["n_joints"]
    want_amp = info["reference"]["amp"] if amp is None else amp
    want_freq = info["reference"]["freq_hz"] if freq is None else freq
    for name, vals in (("--ref-amp", want_amp), ("--ref-freq", want_freq)):
        if len(vals) != n:
            raise ArmChoiceError(f"{name}: {len(vals)} values for the arm's {n} joints "
                                 f"({', '.join(j['name'] for j in info['joints'])})")
    out, warnings = [], []
    for j, a in zip(info["joints"], want_amp):
        c = clip_amplitude(a, j["home"], j["range"])
        if c != a:
            warnings.append(f"reference: {j['name']}: amplitude {a:g} rad clipped to {c:g} rad (its range "
                            f"[{j['range'][0]:g}, {j['range'][1]:g}] from home {j['home']:g})")
        out.append(c)
    if bdir is not None and (amp is not None or friction):
        import mujoco

        m = mujoco.MjModel.from_xml_path(str(prepared_model(bdir)))
        fric = friction or {}
        fitted, notes = fit_reference(m, [j["home"] for j in info["joints"]], out, list(want_freq),
                                      [j["torque_limit"] for j in info["joints"]], [j["name"] for j in info["joints"]],
                                      fric.get("viscous"), fric.get("coulomb"))
        warnings += [f"reference: {x}" for x in notes]
        out = fitted
    return out, list(want_freq), warnings
