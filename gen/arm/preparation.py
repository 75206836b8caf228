"""The arm's preparation: one call per stage, each in its own module, in the order the data flows."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

from gen.arm.arm_file import ArmFile, arm_name
from gen.arm.assets import default_classes
from gen.arm.chain import find_chain
from gen.arm.compile import compile_model
from gen.arm.design import arm_design, design_config
from gen.arm.drive_train import drive_train, payload_site, rotor_inertia
from gen.arm.home import home_pose, lock_other_joints
from gen.arm.limits import size_drives, torque_limits
from gen.arm.load import load
from gen.arm.reference import arm_reference
from gen.arm.wiring import wiring
from gen.arm.write import dynamics_only, info_joints, write
from gen.lib.model_hash import fnv1a64


@dataclass
class Prepared:
    xml: str
    info: dict[str, Any]
    design_text: str
    plant_xml: str  # the simulator's true arm, with its flexible joints (gen/drivetrain.py)


NOMINAL_MODEL = ("rigid bodies, armature and joint damping are in the firmware's nominal model; joint friction "
                 "(frictionloss), joint limits{contacts} are left out on purpose: the estimator takes them as part of w")


def prepare(af: ArmFile, design: Path | None = None) -> Prepared:
    """design: the design config asked for (--design); None for the arm's default: the paper's weights
    for the bundled arm, for any other arm one whose bandwidth fits it (design.auto_bandwidth)."""
    path = af.model.resolve()
    warnings: list[str] = []
    cfg = design_config(af, design)
    spec = load(path)
    name = arm_name(af, spec)
    classes = default_classes(spec, path)
    m0, dropped = compile_model(spec, path, af.contacts)
    warnings += dropped
    chain = find_chain(m0, af, path)
    pose = home_pose(m0, chain, af, path, warnings, spec_degrees=path.suffix.lower() != ".urdf" and spec.compiler.degree)
    locked = lock_other_joints(spec, m0, chain, pose, af, path, warnings)
    rotor_inertia(spec, af, chain)
    dyn = dynamics_only(spec, m0, af, path, cfg.rate, classes, warnings)
    limits = torque_limits(m0, dyn.model, chain, pose, af, path, warnings)
    flange_from = payload_site(spec, dyn.model, chain, af)
    out = write(spec, dyn, chain, pose.home, limits, name, path, warnings)
    lims = [lim for lim, _ in limits]
    sized, limitations, sized_notes = size_drives(chain.names, lims, out.inertia_at_home, 1.0 / cfg.rate)
    warnings += sized_notes + [x["text"] for x in limitations]
    drive_info, plant = drive_train(af, out.model, out.xml, chain, pose.home, lims, dyn.timestep, flange_from)
    reference = arm_reference(out.model, pose.home, pose.ranges, lims, chain.names, warnings)
    design_info, design_text = arm_design(cfg, af, design, out.inertia_at_home, lims, chain.names)
    info = {
        "name": name,
        "model": str(path),
        "arm_file": str(af.path) if af.path else None,
        "model_format": "urdf" if path.suffix.lower() == ".urdf" else "mjcf",
        "n_joints": chain.n,
        "joints": info_joints(out.model, chain.names, limits, pose.ranges, pose.home, sized),
        "locked": locked,
        "home_from": pose.source,
        "loop_rate_hz": cfg.rate,
        "timestep_s": dyn.timestep,
        "substeps": dyn.substeps,
        "contacts": af.contacts,
        "nominal_model": NOMINAL_MODEL.format(contacts=" and contacts" if af.contacts else ""),
        "reference": reference,
        "buses": wiring(af, chain.n, cfg.rate),
        "model_hash": f"{fnv1a64(out.xml.encode()):016x}",
        "written_inverse_dynamics_error": out.written_error,
        "warnings": warnings,
        "limitations": limitations,
        "design": design_info,
        "design_config": design_info["config"],
        **drive_info,
    }
    return Prepared(out.xml, info, design_text, plant)
