"""The identified arm file (armctl identify --out FILE.toml): the arm as measured, in the product's
arm file format (docs/arm.md), which armctl tune, study and run take.

It is the prepared model (the build's arm.xml: the arm's links as its model has them) with each
controlled joint's armature (rotor inertia), damping (viscous friction) and frictionloss (Coulomb
friction) the identified ones, and the payload, where one was found (its mass's interval above
zero), as a point mass fixed to the link that carries the flange. Beside it, FILE.toml names that
model and keeps the arm's home, wiring, drive table, design, drive train and rated payload. Both
are written atomically, the model first, so no arm file names a model that is not there."""

from __future__ import annotations

import math
import xml.etree.ElementTree as ET
from pathlib import Path
from typing import Any

from tools.identify.fit import Fit

PAYLOAD_BODY = "identified_payload"
POINT_INERTIA = 1e-6  # kg m^2 on each axis: MuJoCo wants a positive inertia, a point mass has none


def _toml_value(v: Any) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, (int, float)):
        return repr(float(v)) if isinstance(v, float) else str(v)
    if isinstance(v, str):
        return '"' + v.replace("\\", "\\\\").replace('"', '\\"') + '"'
    if isinstance(v, list):
        return "[" + ", ".join(_toml_value(x) for x in v) + "]"
    if isinstance(v, dict):
        return "{ " + ", ".join(f"{_toml_value(k)} = {_toml_value(x)}" for k, x in v.items()) + " }"
    raise TypeError(type(v))


def model_text(prepared_xml: Path, fit: Fit, payload_site: str) -> str:
    """The prepared arm.xml with the identified joints and payload."""
    tree = ET.parse(prepared_xml)
    root = tree.getroot()
    parent = {c: p for p in root.iter() for c in p}
    joints = {j.get("name"): j for j in root.iter("joint")}
    for j, name in enumerate(fit.names):
        el = joints[name]
        el.set("armature", f"{fit.rotor_inertia[j].value:.6g}")
        el.set("damping", f"{max(fit.viscous[j].value, 0.0):.6g}")
        el.set("frictionloss", f"{max(fit.coulomb[j].value, 0.0):.6g}")
    if fit.payload_kg.lo > 0:
        site = next(s for s in root.iter("site") if s.get("name") == payload_site)
        pos = [float(x) for x in (site.get("pos") or "0 0 0").split()]
        dc = [e.value for e in fit.payload_com]
        body = ET.SubElement(parent[site], "body", {"name": PAYLOAD_BODY,
                                                    "pos": " ".join(f"{p + d:.6g}" for p, d in zip(pos, dc))})
        ET.SubElement(body, "inertial", {"pos": "0 0 0", "mass": f"{fit.payload_kg.value:.6g}",
                                         "diaginertia": " ".join([f"{POINT_INERTIA:g}"] * 3)})
    for el in [s for s in root.iter("site") if s.get("name") == payload_site]:
        parent[el].remove(el)  # the importer hangs its own payload site at the flange (gen/arm/drive_train.py)
    ET.indent(tree)
    return ET.tostring(root, encoding="unicode") + "\n"


def arm_text(model_name: str, info: dict[str, Any], table_path: Path, fit: Fit, header: list[str]) -> str:
    lines = [f"# {h}" for h in header]
    lines += [f"model = {_toml_value(model_name)}", f"name = {_toml_value(info['name'])}",
              f"joints = {_toml_value([j['name'] for j in info['joints']])}",
              f"home = {_toml_value([float(j['home']) for j in info['joints']])}",
              f"drives = {_toml_value(str(Path(table_path).resolve()))}"]
    if info.get("design_config"):
        lines.append(f"design = {_toml_value(str(Path(info['design_config']).resolve()))}")
    payload = info.get("payload") or {}
    if payload.get("rated_kg"):
        lines.append(f"rated_payload_kg = {_toml_value(float(payload['rated_kg']))}")
    lines.append("")
    for bus in info.get("buses") or []:
        lines.append("[[buses]]")
        lines += [f"{k} = {_toml_value(v)}" for k, v in bus.items()]
        lines.append("")
    dt = info.get("drivetrain") or []
    if dt:
        lines.append("[drivetrain]  # the arm's, as its build resolved them (not identified)")
        lines.append(f"size = {_toml_value([int(d['size']) for d in dt])}")
        lines.append(f"stiffness = {_toml_value([float(d['stiffness']) for d in dt])}")
        lines.append("")
    return "\n".join(lines)


def write(out: Path, prepared_xml: Path, info: dict[str, Any], table_path: Path, fit: Fit, header: list[str],
          payload_site: str) -> Path:
    """Write OUT (the arm file) and its model beside it (OUT's stem + .xml); the model's path."""
    from gen.lib.atomic_output import write_text_atomic

    model = out.with_suffix(".xml")
    assert all(math.isfinite(e.value) for e in fit.rotor_inertia + fit.viscous + fit.coulomb)
    write_text_atomic(model, model_text(prepared_xml, fit, payload_site))
    write_text_atomic(out, arm_text(model.name, info, table_path, fit, header))
    return model
