"""Stage 2, compile: the model as MuJoCo compiles it. Mesh, texture and height-field files that are
not there are dropped with every reference to them (the dynamics come from the bodies' inertials);
a file that is there but that MuJoCo refuses is named with MuJoCo's reason."""

from __future__ import annotations

import re
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
    """The compiled model and the warnings of what was changed to compile it: asset files that are
    not there dropped, inertias that break the triangle inequality (A + B >= C: rounding in a
    vendor's file) balanced. Every body and joint is named (the later stages find them by name)."""
    warnings: list[str] = []
    stripped = False
    _name_everything(spec)
    while True:
        try:
            # a copy: deleting elements from a spec that compiled its meshes takes MuJoCo seconds,
            # and the later stages delete the geometry, the actuators and the locked joints
            m0 = spec.copy().compile()
            if spec.compiler.fusestatic:  # what compiling the spec itself does to it (URDF's default)
                spec.fuse_static()
            break
        except Exception as exc:  # noqa: BLE001 - MuJoCo's compiler raises ValueError with its message
            msg = joined_lines(str(exc))
            if "A + B >= C" in msg and not spec.compiler.balanceinertia:
                spec.compiler.balanceinertia = True
                warnings.append(f"inertia of body '{_element(msg)}' (and any other) breaks the triangle inequality "
                                "A + B >= C: balanced (MuJoCo's balanceinertia); check the link's inertia")
                continue
            if stripped or _physics(msg) or ("file" not in msg.lower() and "mesh" not in msg.lower()):
                raise _refusal(msg, path) from exc
            missing = missing_asset_files(spec, path)
            if not missing:  # the files are there: MuJoCo refuses one, and says why
                raise ArmError(f"model {path}: an asset MuJoCo cannot take (over its limits, or malformed): "
                               f"{msg}") from exc
            if contacts:
                raise ArmError(f"model {path}: {msg}; contacts = true needs the collision meshes") from exc
            n = strip_meshes(spec, default_classes(spec, path), set(missing))
            stripped = True
            warnings.insert(0, f"mesh files not found ({msg[:120]}): {n} mesh geoms dropped; the dynamics "
                               "come from the bodies' inertials")
    check_depth(m0, path)
    return m0, warnings


def _element(msg: str) -> str:
    found = re.search(r"Element name '([^']*)'", msg)
    return found.group(1) if found else "?"


def _physics(msg: str) -> bool:
    return "mass and inertia of moving bodies" in msg or "positive eigenvalues" in msg or "positive definite" in msg


def _refusal(msg: str, path: Path) -> ArmError:
    """MuJoCo's reason, said as what is wrong with which body when it is about the physics."""
    if "mass and inertia of moving bodies" in msg:
        return ArmError(f"model {path}: body '{_element(msg)}' moves but has no mass and inertia (a URDF link "
                        "without <inertial>, or an MJCF body with neither an <inertial> nor geoms): give it its "
                        "mass and inertia")
    if "positive eigenvalues" in msg or "positive definite" in msg:
        return ArmError(f"model {path}: body '{_element(msg)}': its inertia matrix is not positive definite, no "
                        f"physical body has it ({msg}): give the link its real inertia")
    return ArmError(f"model {path}: MuJoCo cannot compile it: {msg}")


def _name_everything(spec: mujoco.MjSpec) -> None:
    for kind, items in (("body", spec.bodies), ("joint", spec.joints)):
        taken = {x.name for x in items if x.name}
        for i, x in enumerate(items):
            if (kind == "joint" or i > 0) and not x.name:
                name = f"{kind}{i}"
                while name in taken:
                    name += "_"
                x.name = name
                taken.add(name)


def missing_asset_files(spec: mujoco.MjSpec, path: Path) -> list[str]:
    """The names of the meshes, textures, height fields and skins whose files are not there (MuJoCo
    looks in meshdir or texturedir, else assetdir, beside the model; a URDF's package:// path and any
    folder are stripped to the file's name when strippath is on, as for URDF by default)."""
    out = []
    for assets, sub in ((spec.meshes, spec.meshdir), (spec.textures, spec.texturedir), (spec.hfields, ""),
                        (spec.skins, "")):
        for a in assets:
            if a.file and not _asset_file(path, sub, a.file, spec.strippath).is_file():
                out.append(a.name or a.file)
    return out


def _asset_file(path: Path, sub: str, file: str, strip: bool) -> Path:
    name = Path(file.replace("package://", "")).name if strip else file
    return Path(file) if Path(file).is_absolute() and not strip else path.parent / (sub or "") / name
