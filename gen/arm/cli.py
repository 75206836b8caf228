"""`python -m gen.arm --model M [--arm-file F] --design CONFIG --out DIR [--depfile F]`: the prepared
arm's three files written into DIR (gen/arm/__init__.py says what each holds)."""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from typing import TYPE_CHECKING

from gen.arm.arm_file import DEFAULT_DESIGN, drivetrain_inputs, load_arm_file
from gen.arm.errors import ArmError
from gen.lib.atomic_output import OutputError, write_files_atomically
from gen.lib.busload import DEFAULT_DBC, DEFAULT_TOPOLOGY
from gen.lib.escape import EscapeError, depfile_path
from gen.lib.one_line import one_line

if TYPE_CHECKING:
    from gen.arm.preparation import Prepared


FILES = ("arm.xml", "arm.json", "design.toml", "plant.xml")
KEY_FILE = ".inputs.sha256"  # beside the three files: what they were prepared from


def inputs_key(model: Path | None, arm_file: Path | None, design: Path | None) -> str:
    """A digest of everything the prepared files come from: the model, the arm file and the design
    config (their bytes), and the importer itself (gen/arm and the registry files it reads). A build
    folder whose files carry the key of the same inputs is not prepared again (tools/build/arm.py
    seeds it with the preparation its check before the build already made)."""
    import hashlib

    from gen.lib.paths import REPO

    h = hashlib.sha256()
    for label, p in (("model", model), ("arm", arm_file), ("design", design)):
        h.update(f"{label}={p}\0".encode())
        if p is not None and p.is_file():
            h.update(p.read_bytes())
    from gen.lib.paths import BUNDLED_DRIVETRAIN

    for src in sorted((REPO / "gen" / "arm").glob("*.py")) + [REPO / "gen" / "drivetrain.py", BUNDLED_DRIVETRAIN,
                                                               REPO / "firmware" / "params" / "params.toml",
                                                               REPO / "firmware" / "protocol" / "buses.toml",
                                                               REPO / "firmware" / "protocol" / "arm_drives.dbc"]:
        h.update(src.read_bytes())
    return h.hexdigest()


def write_prepared(out: Path, prep: Prepared, key: str) -> None:
    write_files_atomically(out, {"arm.xml": prep.xml, "arm.json": json.dumps(prep.info, indent=1) + "\n",
                                 "design.toml": prep.design_text, "plant.xml": prep.plant_xml, KEY_FILE: key + "\n"})


def already_prepared(out: Path, key: str) -> dict | None:
    """arm.json of a folder prepared from these very inputs, else None."""
    try:
        if (out / KEY_FILE).read_text().strip() != key or not all((out / f).is_file() for f in FILES):
            return None
        return json.loads((out / "arm.json").read_text())
    except (OSError, ValueError):
        return None


def main(argv: list[str] | None = None) -> int:
    import gen.arm

    ap = argparse.ArgumentParser(prog="python -m gen.arm", description=gen.arm.__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--model", type=Path, default=None, help="MJCF or URDF [the arm file's, else the bundled UR5e]")
    ap.add_argument("--arm-file", type=Path, default=None, help="arm file (TOML)")
    ap.add_argument("--design", type=Path, default=None,
                    help="design config when the arm file names none [the arm's default: gen/configs/paper.toml "
                         "for the bundled arm, else one whose bandwidth fits the arm (auto_bandwidth)]")
    ap.add_argument("--out", type=Path, required=True)
    ap.add_argument("--depfile", type=Path, default=None, help="write the files read, for the build (Ninja depfile)")
    ns = ap.parse_args(argv)
    try:
        if ns.arm_file is not None and ns.model is not None:
            raise ArmError("--model and --arm-file: give one (the arm file names its model)")
        af = load_arm_file(ns.arm_file.resolve() if ns.arm_file else None, ns.model)
        key = inputs_key(af.model.resolve(), af.path, ns.design.resolve() if ns.design else None)
        info = already_prepared(ns.out, key)
        prep = None
        if info is None:  # imported only now: a folder prepared already is found without MuJoCo
            from gen.arm.preparation import prepare

            prep = prepare(af, ns.design)
    except ArmError as exc:
        print(f"gen.arm: {exc}", file=sys.stderr)
        return 2
    if prep is not None:
        try:
            write_prepared(ns.out, prep, key)
        except OutputError as exc:
            print(f"gen.arm: {exc}", file=sys.stderr)
            return 1
        info = prep.info
    if ns.depfile is not None:
        deps = [str(af.model.resolve()), str((af.design or ns.design or DEFAULT_DESIGN).resolve())]
        if af.path:
            deps.append(str(af.path.resolve()))
        if af.topology:
            deps.append(str(af.topology.resolve()))
        deps += [str(p) for p in drivetrain_inputs(af)]
        deps += [str(DEFAULT_DBC), str(DEFAULT_TOPOLOGY)]  # the drive slots; the six-drive wiring
        target = ns.out / "arm.xml"
        try:
            head, *rest = (depfile_path(str(d), "a file the arm is made of") for d in [str(target), *deps])
        except EscapeError as exc:
            print(f"gen.arm: {exc}", file=sys.stderr)
            return 2
        ns.depfile.write_text(f"{head}: {' '.join(rest)}\n")
    for w in info["warnings"]:
        print(f"gen.arm: {info['name']}: {one_line(w)}", file=sys.stderr)
    return 0
