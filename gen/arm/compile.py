"""Stage 2, compile: the model as MuJoCo compiles it. Mesh, texture and height-field files that are
not there are dropped with every reference to them (the dynamics come from the bodies' inertials);
a file that is there but that MuJoCo refuses is named with MuJoCo's reason."""

from __future__ import annotations

from pathlib import Path

import mujoco

from gen.arm.assets import default_classes, strip_meshes
from gen.arm.errors import ArmError
from gen.arm.load import check_depth
from gen.lib.one_line import joined_lines


def compile_spec(spec: mujoco.MjSpec, path: Path, what: str) -> mujoco.MjModel:
    try:
        return spec.compile()
    except Exception as exc:  # noqa: BLE001 - MuJoCo's compiler raises ValueError with its message
        msg = str(exc)
        hint = ""
        if "mass and inertia" in msg:
            hint = (": a moving body needs mass and inertia (give it an <inertial> or, in URDF, an "
                    "<inertial> element)")
        raise ArmError(f"model {path}: {what}: {joined_lines(msg)}{hint}") from exc


def compile_model(spec: mujoco.MjSpec, path: Path, contacts: bool) -> tuple[mujoco.MjModel, list[str]]:
    """The compiled model and the warnings of what was dropped to compile it. Every body is named
    (the later stages find bodies by name)."""
    warnings: list[str] = []
    try:
        spec.compile()
    except Exception as exc:  # noqa: BLE001
        msg = joined_lines(str(exc))
        if "file" not in msg.lower() and "mesh" not in msg.lower():
            raise ArmError(f"model {path}: MuJoCo cannot compile it: {msg}") from exc
        missing = missing_asset_files(spec, path)
        if not missing:  # the files are there: MuJoCo refuses one of them, and says which and why
            raise ArmError(f"model {path}: an asset MuJoCo cannot take (over its limits, or malformed): {msg}") from exc
        if contacts:
            raise ArmError(f"model {path}: {msg}; contacts = true needs the collision meshes") from exc
        n = strip_meshes(spec, default_classes(spec, path))
        warnings.append(f"mesh files not found ({msg[:120]}): {n} mesh geoms dropped; the dynamics "
                        "come from the bodies' inertials")
    for i, b in enumerate(spec.bodies):
        if i > 0 and not b.name:
            b.name = f"body{i}"
    m0 = compile_spec(spec, path, "compiling it")
    check_depth(m0, path)
    return m0, warnings


def missing_asset_files(spec: mujoco.MjSpec, path: Path) -> list[str]:
    out = []
    for assets, sub in ((spec.meshes, spec.meshdir), (spec.textures, spec.texturedir), (spec.hfields, "")):
        for a in assets:
            if a.file and not (path.parent / (sub or "") / a.file).is_file():
                out.append(a.file)
    return out
