"""Stages 4b, 6b and 9: the arm's drive train (gen/drivetrain.py): the arm file's rotor inertias as
the joints' armature (the nominal model knows the motor's datasheet), the payload's site at the
flange, and after the prepared model is written, each joint's drive train, the first resonance and
the plant with flexible joints the simulator runs."""

from __future__ import annotations

from typing import Any

import mujoco

from gen import drivetrain
from gen.arm.arm_file import ArmFile
from gen.arm.chain import Chain
from gen.arm.errors import ArmError


def where(af: ArmFile) -> str:
    return f"arm file {af.path}: drivetrain" if af.path else f"{drivetrain.BUNDLED_DRIVETRAIN}: drivetrain"


def rotor_inertia(spec: mujoco.MjSpec, af: ArmFile, chain: Chain) -> None:
    try:
        drivetrain.set_rotor_inertia(spec, af.drivetrain, chain.names, where(af))
    except drivetrain.DrivetrainError as exc:
        raise ArmError(str(exc)) from exc


def payload_site(spec: mujoco.MjSpec, m: mujoco.MjModel, chain: Chain, af: ArmFile) -> str:
    """The site 'payload' on the last link (m: the compiled dynamics, static bodies fused), and
    where it came from."""
    last = int(m.jnt_bodyid[mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_JOINT, chain.names[-1])])
    try:
        body, pos, came_from = drivetrain.flange_site(m, last, af.flange)
    except drivetrain.DrivetrainError as exc:
        raise ArmError(f"arm file {af.path}: {exc}") from exc
    spec.body(mujoco.mj_id2name(m, mujoco.mjtObj.mjOBJ_BODY, body)).add_site(name=drivetrain.PAYLOAD_SITE, pos=pos)
    return came_from


def drive_train(af: ArmFile, m: mujoco.MjModel, xml: str, chain: Chain, home: list[float], limits: list[float],
                dt: float, flange_from: str) -> tuple[dict[str, Any], str]:
    """arm.json's drive train entries, and the plant (plant.xml). m: the prepared rigid arm."""
    try:
        joints = drivetrain.resolve(af.drivetrain, where(af), m, chain.names, home, limits, dt)
    except drivetrain.DrivetrainError as exc:
        raise ArmError(str(exc)) from exc
    info = {"drivetrain": joints, "first_resonance_hz": drivetrain.first_resonance_hz(joints),
            "payload": {"rated_kg": af.rated_payload_kg, "at": flange_from}}
    return info, drivetrain.plant_xml(xml, joints)

