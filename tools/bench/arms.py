"""The compatibility matrix: every serial arm of the public model sets in tools/bench/model_sets.toml,
each through import, build and a 3 s software-in-the-loop run with its default design, exactly as a
user runs it (`armctl hil --model M --bus sil --duration 3`, its build folder removed first), into
one results file (runs/bench/arms.json) that tools/bench/arms_page.py renders into
docs/arm-compatibility.md.

A set is installed alone (pip --no-deps --target build/model-sets/NAME-VERSION): its model files are
read, its Python is never imported. The finder is structural, not the importer's verdict (an arm
the importer refuses is still an arm, and shows as refused): a file MuJoCo reads on its own whose
fixed-base tree holds a chain of at least MIN_ARM_JOINTS hinges is an arm, run as the file is; a
fixed-base robot that branches into exactly two such chains of TWO_ARM_JOINTS or more (a two-armed
robot) gives two arms, each through an arm file naming its joints, the joints on the way to it held.
Floating bases (legged robots, humanoids, objects) and models of more limbs are left out, counted."""

from __future__ import annotations

import hashlib
import json
import os
import platform
import re
import shutil
import subprocess
import sys
import time
import tomllib
import xml.etree.ElementTree as ET
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

from gen.lib.atomic_output import write_json_atomic
from gen.lib.bounds import DEFAULT_MAX_ERROR_DEG
from gen.lib.paths import BUILD, REPO
from tools.run.run_files import RUN_RECORD

SETS_FILE = REPO / "tools" / "bench" / "model_sets.toml"
CACHE = BUILD / "model-sets"
RESULTS = REPO / "runs" / "bench" / "arms.json"
RUNS = REPO / "runs" / "bench" / "arms"
MIN_ARM_JOINTS = 3   # an arm places its tool in space: fewer hinges is a pendulum or a finger
TWO_ARM_JOINTS = 5   # each arm of a two-armed robot
LEG_WORDS = {"hip", "knee", "ankle", "leg", "foot"}
MAX_HEAD_JOINTS = 2  # what else may branch there: a head's pan and tilt (legs, a torso or fingers: no)
DURATION_S = 3.0
NO_JOINTS = "fewer than 3 hinges in the file itself (objects, grippers, scenes that include an arm's file)"
RUN_TIMEOUT_S = 600
# What a refusal says is wrong with the file (the importer's words: gen/arm), for the page's groups.
# A refusal of none of these kinds names the importer's own limit, not the file's: a bug to fix.
FILE_DEFECTS = (
    ("moves but has no mass and inertia", "a link without mass and inertia"),
    ("not positive definite", "an inertia no body has (not positive definite)"),
    ("leaves it no room to move", "a range too narrow to move in (degrees read as radians?)"),
    ("sits inside the arm", "a hinge inside the arm that nothing drives"),
)


class ArmsError(RuntimeError):
    """A set cannot be installed or read; the message says which and why."""


@dataclass
class ModelSet:
    name: str
    licence: str
    search: list[str]
    requirement: str = ""      # a package the registry serves, pinned (name==version)
    path: Path | None = None   # or a folder of model files (the tests' sets: tests/arms/sets.toml)

    @property
    def version(self) -> str:
        return self.requirement.split("==", 1)[1] if self.requirement else "local"

    @property
    def folder(self) -> Path:
        return self.path if self.path is not None else CACHE / f"{self.name}-{self.version}"


@dataclass
class Candidate:
    id: str                    # set/relative path[#first joint]
    set: str
    model: str                 # relative to the set's folder
    joints: list[str]
    locked: dict[str, float] = field(default_factory=dict)
    arm_file: bool = False     # run through an arm file naming `joints` (one arm of two)


def folder_set(folder: Path) -> ModelSet:
    """A folder of model files (a clone of a model collection) as a set of its own: every MJCF and
    URDF under it (armctl arms --path)."""
    folder = folder.resolve()
    if not folder.is_dir():
        raise ArmsError(f"--path {folder}: not a folder")
    name = re.sub(r"[^A-Za-z0-9_.-]+", "-", folder.name).strip("-") or "models"
    return ModelSet(name=name, licence="the folder's own (see its files)", search=["."], path=folder)


def file_defect(reason: str) -> str | None:
    """The kind of defect of the file a refusal names (FILE_DEFECTS), None for any other refusal."""
    return next((kind for words, kind in FILE_DEFECTS if words in reason), None)


def load_sets(path: Path = SETS_FILE) -> tuple[list[ModelSet], list[dict[str, str]]]:
    try:
        doc = tomllib.loads(path.read_text())
        sets = [ModelSet(**{**s, "path": (path.parent / s["path"]).resolve()} if "path" in s else s)
                for s in doc["set"]]
    except (OSError, tomllib.TOMLDecodeError, KeyError, TypeError) as exc:
        raise ArmsError(f"{path}: not a list of model sets ([[set]] name, licence, search, requirement or "
                        f"path): {exc}") from exc
    bad = [s.name for s in sets if bool(s.requirement) == (s.path is not None)]
    if bad:
        raise ArmsError(f"{path}: set {bad[0]}: give a requirement (name==version) or a path, one of them")
    return sets, list(doc.get("left_out", []))


def install(ms: ModelSet) -> Path:
    """The set's files, installed once (a stamp marks a whole install)."""
    if ms.path is not None:
        return ms.path
    stamp = ms.folder / ".installed"
    if stamp.exists():
        return ms.folder
    print(f"armctl arms: installing {ms.requirement} (its model files only: pip --no-deps) into {ms.folder}",
          file=sys.stderr, flush=True)
    tmp = ms.folder.with_name(ms.folder.name + ".partial")
    shutil.rmtree(tmp, ignore_errors=True)
    r = subprocess.run([sys.executable, "-m", "pip", "install", "-q", "--no-deps", "--no-compile", "--target",
                        str(tmp), ms.requirement], capture_output=True, text=True)
    if r.returncode != 0:
        shutil.rmtree(tmp, ignore_errors=True)
        last = (r.stderr.strip().splitlines() or ["no output"])[-1]
        raise ArmsError(f"{ms.name}: pip cannot install {ms.requirement}: {last}")
    shutil.rmtree(ms.folder, ignore_errors=True)
    tmp.rename(ms.folder)
    stamp.write_text(ms.requirement + "\n")
    return ms.folder


# ---- finding the arms ------------------------------------------------------------------------
def _may_hold_an_arm(path: Path) -> bool:
    """A cheap look before MuJoCo reads the file: at least MIN_ARM_JOINTS joints that can be hinges
    in its bodies (its includes counted; not its default classes)."""
    try:
        root = ET.parse(path).getroot()
    except (ET.ParseError, OSError):
        return False
    if root.tag == "robot":
        return sum(el.get("type") in ("revolute", "continuous") for el in root.iter("joint")) >= MIN_ARM_JOINTS
    return root.tag == "mujoco" and _hinges(root, path.parent, 0) >= MIN_ARM_JOINTS


def _hinges(el: ET.Element, base: Path, depth: int) -> int:
    n = 0
    for child in el:
        if child.tag == "default":
            continue
        if child.tag == "joint" and child.get("type", "hinge") == "hinge":
            n += 1
        elif child.tag == "include" and child.get("file") and depth < 8:
            try:
                n += _hinges(ET.parse(base / child.get("file", "")).getroot(), base, depth + 1)
            except (ET.ParseError, OSError):
                pass
        n += _hinges(child, base, depth)
    return n


@dataclass
class _Tree:
    parent: dict[str, str]
    joints: dict[str, list[tuple[str, str]]]  # body -> [(joint, type)]
    children: dict[str, list[str]]
    ranges: dict[str, tuple[float, float]]


def _structure(path: Path) -> _Tree | str:
    import mujoco

    try:
        spec = mujoco.MjSpec.from_file(str(path))
    except Exception as exc:  # noqa: BLE001 - a fragment that only another file includes
        return "not a model on its own: " + str(exc).splitlines()[0][:80]
    from gen.arm.compile import _name_everything

    _name_everything(spec)
    world = spec.worldbody.name or "world"
    tree = _Tree({}, {}, {}, {})
    kinds = {mujoco.mjtJoint.mjJNT_HINGE: "hinge", mujoco.mjtJoint.mjJNT_SLIDE: "slide",
             mujoco.mjtJoint.mjJNT_BALL: "ball", mujoco.mjtJoint.mjJNT_FREE: "free"}
    for b in spec.bodies[1:]:
        parent = b.parent.name or world
        tree.parent[b.name] = parent
        tree.children.setdefault(parent, []).append(b.name)
        tree.joints[b.name] = [(j.name, kinds[j.type]) for j in b.joints]
        for j in b.joints:
            tree.ranges[j.name] = (float(j.range[0]), float(j.range[1]))
    tree.parent["__world__"] = world
    return tree


def _chain(t: _Tree, root: str) -> tuple[list[str], str]:
    """The hinges from root down while one branch holds hinges (gen/arm/chain.py default_chain), and
    the body where it stopped."""
    def has_hinge(b: str) -> bool:
        todo = [b]
        while todo:
            x = todo.pop()
            if any(k == "hinge" for _, k in t.joints.get(x, [])):
                return True
            todo += t.children.get(x, [])
        return False

    chain = [j for j, k in t.joints.get(root, []) if k == "hinge"][:1]
    b = root
    while True:
        nxt = [c for c in t.children.get(b, []) if has_hinge(c)]
        if len(nxt) != 1:
            return chain, b
        b = nxt[0]
        chain += [j for j, k in t.joints.get(b, []) if k == "hinge"][:1]


def _floating(t: _Tree, root: str) -> bool:
    todo = [root]
    while todo:
        x = todo.pop()
        if any(k == "free" for _, k in t.joints.get(x, [])):
            return True
        todo += t.children.get(x, [])
    return False


def _held(t: _Tree, body: str) -> dict[str, float]:
    """The joints between the tree's top and body (a torso lift, a waist): held at 0, or inside
    their range."""
    out = {}
    while body in t.parent and body != t.parent["__world__"]:
        for j, k in t.joints.get(body, []):
            if k in ("hinge", "slide"):
                lo, hi = t.ranges.get(j, (0.0, 0.0))
                out[j] = 0.0 if lo == hi or lo <= 0.0 <= hi else 0.5 * (lo + hi)
        body = t.parent[body]
    return out


def arms_in(path: Path) -> list[tuple[list[str], dict[str, float], bool]] | str:
    """The arms of one file: [(joints, held joints, needs an arm file)], or why it holds none."""
    t = _structure(path)
    if isinstance(t, str):
        return t
    tops = t.children.get(t.parent["__world__"], [])
    fixed = {b: _chain(t, b) for b in tops if not _floating(t, b)}
    two = [arms for _, stop in fixed.values() if (arms := _two_arms(t, stop))]
    if len(two) == 1:  # a two-armed robot: each arm through an arm file
        return two[0]
    chains = {b: c for b, c in fixed.items() if len(c[0]) >= MIN_ARM_JOINTS and not _slides_on_the_way(t, b, c[0])}
    if not chains:
        if any(_floating(t, b) and len(_chain(t, b)[0]) >= MIN_ARM_JOINTS for b in tops):
            return "a floating base (a legged or mobile robot)"
        return "no fixed chain of 3 or more hinges alone (a hand, a legged robot, a humanoid, a cart or walker)"
    longest = max(len(c[0]) for c in chains.values())
    best = [b for b, c in chains.items() if len(c[0]) == longest]
    if len(best) == 1:  # the model as a user gives it: the importer takes the longest fixed chain
        return [(chains[best[0]][0], {}, False)]
    if len(best) == 2 and longest >= TWO_ARM_JOINTS:  # two arms, each its own tree
        return [(chains[b][0], {}, True) for b in best]
    return f"{len(best)} chains of {longest} hinges: not one serial arm"


def _two_arms(t: _Tree, at: str) -> list[tuple[list[str], dict[str, float], bool]] | None:
    """The two arms that branch at body `at`, each with the joints on the way to it held, if exactly
    two chains of TWO_ARM_JOINTS or more start there."""
    arms, rest = [], 0
    for c in t.children.get(at, []):
        ch = _chain(t, c)[0]
        if len(ch) >= TWO_ARM_JOINTS:
            arms.append(ch)
        else:
            rest += _hinge_count(t, c)
    if len(arms) != 2 or rest > MAX_HEAD_JOINTS:  # more limbs (legs and a torso, fingers): no two-armed robot
        return None
    if any(LEG_WORDS & set(re.split(r"[^a-z]+", j.lower())) for ch in arms for j in ch):
        return None  # a pair of legs (a lower body alone) is no pair of arms
    return [(ch, _held(t, at), True) for ch in arms]


def _hinge_count(t: _Tree, b: str) -> int:
    n, todo = 0, [b]
    while todo:
        x = todo.pop()
        n += sum(k == "hinge" for _, k in t.joints.get(x, []))
        todo += t.children.get(x, [])
    return n


def _slides_on_the_way(t: _Tree, top: str, chain: list[str]) -> bool:
    """A slide or ball joint between the tree's top and the chain's last joint (a planar walker's
    root, a cart): not a fixed-base serial arm."""
    last = next(b for b, js in t.joints.items() if any(j == chain[-1] for j, _ in js))
    while True:
        if any(k in ("slide", "ball") for _, k in t.joints.get(last, [])):
            return True
        if last == top:
            return False
        last = t.parent[last]


def find_arms(ms: ModelSet, folder: Path) -> tuple[list[Candidate], dict[str, int], int]:
    """The set's arms (one per distinct arm: a scene that includes an arm already found is the same
    arm), why the other files hold none (counted by reason), and how many files were looked at."""
    files: list[Path] = []
    for sub in ms.search:
        root = (folder / sub).resolve()
        files += [p for p in root.rglob("*") if p.suffix.lower() in (".xml", ".urdf") and p.is_file()]
    files = sorted(set(files), key=lambda p: (len(p.relative_to(folder).parts), str(p)))
    out: list[Candidate] = []
    seen: set[str] = set()
    skipped: dict[str, int] = {}
    for p in files:
        if not _may_hold_an_arm(p):
            skipped[NO_JOINTS] = skipped.get(NO_JOINTS, 0) + 1
            continue
        found = arms_in(p)
        if isinstance(found, str):
            key = found.split(":")[0]
            skipped[key] = skipped.get(key, 0) + 1
            continue
        rel = str(p.relative_to(folder))
        for joints, held, arm_file in found:
            fingerprint = hashlib.sha256(json.dumps([joints, _ranges_of(p, joints)]).encode()).hexdigest()
            if fingerprint in seen:
                continue
            seen.add(fingerprint)
            cid = f"{ms.name}/{rel}" + (f"#{joints[0]}" if arm_file else "")
            out.append(Candidate(cid, ms.name, rel, joints, held, arm_file))
    return out, skipped, len(files)


def _ranges_of(path: Path, joints: list[str]) -> list[list[float]]:
    t = _structure(path)
    assert not isinstance(t, str)
    return [[round(x, 4) for x in t.ranges.get(j, (0.0, 0.0))] for j in joints]


# ---- running them ----------------------------------------------------------------------------
def arm_file_for(c: Candidate, model: Path, folder: Path) -> Path:
    """One arm of a two-armed robot: an arm file naming its joints and holding the others."""
    folder.mkdir(parents=True, exist_ok=True)
    name = c.id.replace("/", "-").replace("#", "-").replace(".", "-")[-60:]
    lines = [f'model = {json.dumps(str(model))}', f'name = {json.dumps(name)}',
             f"joints = {json.dumps(c.joints)}"]
    if c.locked:
        lines.append("locked = { " + ", ".join(f"{json.dumps(k)} = {v!r}" for k, v in c.locked.items()) + " }")
    path = folder / f"{name}.toml"
    path.write_text("\n".join(lines) + "\n")
    return path


def run_one(c: Candidate, model: Path, out: Path, bound_deg: float) -> dict[str, Any]:
    """import, build and a DURATION_S SIL run with the default design, its build folder removed first:
    the time to its first result is what a user who never built the arm waits."""
    from tools.build.arm import ArmRef, arm_build_dir

    out.mkdir(parents=True, exist_ok=True)
    arm = ["--arm", str(arm_file_for(c, model, out))] if c.arm_file else ["--model", str(model)]
    ref = ArmRef(arm_file=Path(arm[1]).resolve()) if c.arm_file else ArmRef(model=model.resolve())
    shutil.rmtree(arm_build_dir("release", ref).parent, ignore_errors=True)
    argv = [str(REPO / "tools" / "armctl"), "hil", *arm, "--bus", "sil", "--duration", f"{DURATION_S:g}",
            "--max-error-deg", f"{bound_deg:g}", "--out", str(out / "run")]
    t0 = time.monotonic()
    try:
        r = subprocess.run(argv, cwd=REPO, capture_output=True, text=True, timeout=RUN_TIMEOUT_S)
    except subprocess.TimeoutExpired:
        return {"result": "failed", "reason": f"no result within {RUN_TIMEOUT_S} s"}
    elapsed = time.monotonic() - t0
    row: dict[str, Any] = {"first_result_s": round(elapsed, 1), "exit": r.returncode}
    run_json = out / "run" / RUN_RECORD
    if r.returncode == 2 and not run_json.exists():
        lines = [ln for ln in r.stderr.splitlines() if ln.startswith("armctl hil: ") and "warning" not in ln]
        row.update(result="refused", reason=(lines[-1] if lines else r.stderr.strip()[-300:]).removeprefix(
            "armctl hil: ").replace(str(model), "MODEL"))
        row["defect"] = file_defect(row["reason"])
        return row
    row["limitations"] = _limitations(arm_build_dir("release", ref))
    try:
        res = json.loads(run_json.read_text())["results"]
    except (OSError, ValueError, KeyError):
        return row | {"result": "failed", "reason": (r.stderr.strip().splitlines() or ["no output"])[-1][:300]}
    if res.get("tracking_max_abs_deg") is None:  # the run ended before the trajectory: no error to give
        return row | {"result": res.get("result", "failed"),
                      "reason": "; ".join(res.get("verdict_reasons") or [])[:300] or "no result"}
    row.update(result=res["result"], max_error_deg=round(max(res["tracking_max_abs_deg"]), 4),
               n_joints=res["arm"]["n_joints"], reason="; ".join(res.get("verdict_reasons") or []) or None,
               design=res["arm"].get("design", {}).get("config") if isinstance(res["arm"].get("design"), dict)
               else None, warnings=len(res["arm"].get("warnings", [])))
    return row


def _limitations(bdir: Path) -> list[str]:
    """What the importer found the arm's physics leaves the controller no way to do (arm.json's
    limitations: a joint whose drive's torque step is too coarse for its link)."""
    try:
        return [x["text"] for x in json.loads((bdir / "generated" / "arm" / "arm.json").read_text())["limitations"]]
    except (OSError, ValueError, KeyError, TypeError):
        return []


def machine() -> dict[str, Any]:
    cpu = ""
    try:
        cpu = next(ln.split(":", 1)[1].strip() for ln in Path("/proc/cpuinfo").read_text().splitlines()
                   if ln.startswith("model name"))
    except (OSError, StopIteration):
        cpu = platform.processor()
    return {"cpu": cpu, "cores": os.cpu_count(), "python": platform.python_version(), "system": platform.platform()}


def commit() -> str:
    r = subprocess.run(["git", "rev-parse", "--short", "HEAD"], cwd=REPO, capture_output=True, text=True)
    return r.stdout.strip() or "unknown"


def write_results(path: Path, doc: dict[str, Any]) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    write_json_atomic(path, doc)


def bound() -> float:
    return DEFAULT_MAX_ERROR_DEG


def as_dict(c: Candidate) -> dict[str, Any]:
    return asdict(c)
