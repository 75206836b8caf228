"""Stage 3, chain: which joints the firmware drives. The arm file's `joints`, else the chain of
hinges from the base up to the first branch (a hand with fingers ends it); they must be hinges of
one serial chain, with nothing uncontrolled inside it unless the arm file locks it, and no
equality constraint may close a loop through the arm or couple its joints."""

from __future__ import annotations

import functools
from dataclasses import dataclass
from pathlib import Path

import mujoco

from gen.arm.arm_file import ArmFile
from gen.arm.errors import ArmError
from gen.lib.escape import EscapeError, c_string

MAX_JOINTS = 16  # the firmware's bound (arm/robot_model.h); the DBC's drive slots bound it too


@dataclass
class Chain:
    joints: list[int]   # the controlled joints' ids in the compiled model, base to tip
    names: list[str]
    bodies: list[int]   # the body of each

    @property
    def n(self) -> int:
        return len(self.joints)


def joint_name(m: mujoco.MjModel, j: int) -> str:
    return mujoco.mj_id2name(m, mujoco.mjtObj.mjOBJ_JOINT, j) or f"joint{j}"


def joint_kind(t: int) -> str:
    return {int(mujoco.mjtJoint.mjJNT_HINGE): "hinge", int(mujoco.mjtJoint.mjJNT_BALL): "ball",
            int(mujoco.mjtJoint.mjJNT_SLIDE): "slide (prismatic)"}.get(t, "free")


def find_chain(m0: mujoco.MjModel, af: ArmFile, path: Path) -> Chain:
    tree = _arm_tree(m0, af, path)
    free = [joint_name(m0, j) for j in range(m0.njnt)
            if m0.jnt_type[j] == mujoco.mjtJoint.mjJNT_FREE and _top(m0, int(m0.jnt_bodyid[j])) == tree]
    if free:
        raise ArmError(f"model {path}: joint '{free[0]}' is a free joint (a floating base): this controller needs "
                       "a fixed base; remove the freejoint from the model")
    controlled = _named(m0, af, path) if af.joints is not None else default_chain(m0, tree)
    for j in controlled:
        t = m0.jnt_type[j]
        if t != mujoco.mjtJoint.mjJNT_HINGE:
            raise ArmError(f"model {path}: joint '{joint_name(m0, j)}' is a {joint_kind(int(t))} joint: the firmware "
                           "drives hinge (revolute) joints only; lock it (arm file: leave it out of joints)")
    chain = Chain(controlled, [joint_name(m0, j) for j in controlled], [int(m0.jnt_bodyid[j]) for j in controlled])
    _check_serial(m0, chain, af, path)
    _check_arm_file_names(m0, chain, af, path)
    _check_loops(m0, chain, path)
    _check_representable(chain, path)
    return chain


def _check_representable(chain: Chain, path: Path) -> None:
    """Every controlled joint's name goes into the generated C (gen/robot_model.py, escaped as
    gen/lib/escape.py says): one C cannot hold (a NUL, a literal over C11's limit) is refused here,
    before anything is built, never cut."""
    for i, name in enumerate(chain.names):
        try:
            c_string(name, f"model {path}: joint {i + 1}'s name")
        except EscapeError as exc:
            raise ArmError(f"{exc}: rename the joint") from None


def _top(m: mujoco.MjModel, b: int) -> int:
    """The body's tree: its ancestor that hangs from the world."""
    while b and int(m.body_parentid[b]) != 0:
        b = int(m.body_parentid[b])
    return b


def _arm_tree(m0: mujoco.MjModel, af: ArmFile, path: Path) -> int:
    """Which of the trees hanging from the world is the arm: the one holding the arm file's joints,
    else the fixed one with the longest chain of hinges. The others (the objects, doors and props of
    a scene) are not the arm: their joints are locked like a gripper's (home.lock_other_joints)."""
    if af.joints:
        named = _named(m0, af, path)
        return _top(m0, int(m0.jnt_bodyid[named[0]]))
    floating = {_top(m0, int(m0.jnt_bodyid[j])) for j in range(m0.njnt) if m0.jnt_type[j] == mujoco.mjtJoint.mjJNT_FREE}
    chains = {}
    for t in sorted({_top(m0, int(m0.jnt_bodyid[j])) for j in range(m0.njnt)}):
        chains[t] = default_chain(m0, t)
    fixed = {t: c for t, c in chains.items() if c and t not in floating}
    if not fixed:
        moving = [t for t, c in chains.items() if c]
        if moving:
            return max(moving, key=lambda t: len(chains[t]))  # a floating arm: find_chain names its free joint
        raise ArmError(f"model {path}: no chain of hinge joints from the base (joints: "
                       f"{', '.join(joint_name(m0, k) for k in range(m0.njnt)) or 'none'})")
    longest = max(len(c) for c in fixed.values())
    best = [t for t, c in fixed.items() if len(c) == longest]
    if len(best) > 1:
        arms = "; ".join(f"'{mujoco.mj_id2name(m0, mujoco.mjtObj.mjOBJ_BODY, t)}' ({', '.join(joint_name(m0, j) for j in fixed[t])})"
                         for t in best)
        raise ArmError(f"model {path}: {len(best)} arms of {longest} joints hang from the world ({arms}): name the "
                       "joints of the one to run in an arm file (joints = [...]); the other is held still")
    return best[0]


def _named(m0: mujoco.MjModel, af: ArmFile, path: Path) -> list[int]:
    out = []
    for name in af.joints or []:
        j = mujoco.mj_name2id(m0, mujoco.mjtObj.mjOBJ_JOINT, name)
        if j < 0:
            raise ArmError(f"arm file {af.path}: joints: no joint '{name}' in {path.name} "
                           f"(it has: {', '.join(joint_name(m0, k) for k in range(m0.njnt))})")
        out.append(j)
    return out


def default_chain(m: mujoco.MjModel, root: int = 0) -> list[int]:
    """Hinge joints of the main serial chain below `root` (the world, or one tree's top body): from
    it, follow the hinges while the rest of the tree below holds hinges in one branch only; a branch
    point (a hand with fingers) ends it."""
    hinge_bodies = {int(m.jnt_bodyid[j]): j for j in range(m.njnt) if m.jnt_type[j] == mujoco.mjtJoint.mjJNT_HINGE}
    children: dict[int, list[int]] = {}
    for b in range(1, m.nbody):
        children.setdefault(int(m.body_parentid[b]), []).append(b)

    has_hinge = [b in hinge_bodies for b in range(m.nbody)]  # in its subtree
    for b in range(m.nbody - 1, 0, -1):  # children come after their parent: no recursion
        if has_hinge[b]:
            has_hinge[int(m.body_parentid[b])] = True

    chain: list[int] = [hinge_bodies[root]] if root in hinge_bodies else []
    b = root
    while True:
        nxt = [c for c in children.get(b, []) if has_hinge[c]]
        if len(nxt) != 1:
            return chain
        b = nxt[0]
        if b in hinge_bodies:
            chain.append(hinge_bodies[b])


def _check_serial(m0: mujoco.MjModel, chain: Chain, af: ArmFile, path: Path) -> None:
    bodies, controlled = chain.bodies, chain.joints
    for k in range(1, len(bodies)):  # a serial chain: each joint's body below the previous one
        b, anc = bodies[k], bodies[k - 1]
        p = int(m0.body_parentid[b])
        while p not in (anc, 0) and p not in bodies:
            p = int(m0.body_parentid[p])
        if p != anc:
            raise ArmError(f"model {path}: joint '{joint_name(m0, controlled[k])}' is not below joint "
                           f"'{joint_name(m0, controlled[k - 1])}': the controlled joints must form one serial "
                           "chain, base to tip, in order (a branch or a joint order the arm file got wrong)")
    for j in _joints_inside_chain(m0, bodies, controlled):
        name = joint_name(m0, j)
        if name not in af.locked:
            raise ArmError(f"model {path}: joint '{name}' ({joint_kind(int(m0.jnt_type[j]))}) sits inside the arm, "
                           f"between the base and joint '{joint_name(m0, controlled[-1])}', and is not controlled: "
                           "the firmware drives hinge joints only; to run the arm with it held, name it in the arm "
                           f"file's locked table (locked = {{ {name} = value }})")
    for b in bodies:
        if sum(1 for j in range(m0.njnt) if m0.jnt_bodyid[j] == b and j in controlled) > 1:
            raise ArmError(f"model {path}: body '{mujoco.mj_id2name(m0, mujoco.mjtObj.mjOBJ_BODY, b)}' has more than "
                           "one controlled joint: one hinge per link")
    n = len(controlled)
    slots = _dbc_drive_slots()
    if n > min(MAX_JOINTS, slots):
        raise ArmError(f"model {path}: {n} controlled joints; the firmware takes at most {MAX_JOINTS} and the "
                       f"protocol (firmware/protocol/arm_drives.dbc) defines {slots} drive slots: lock joints "
                       "(arm file: joints), or add DRIVE_n slots to the DBC")


def _joints_inside_chain(m: mujoco.MjModel, bodies: list[int], controlled: list[int]) -> list[int]:
    """Uncontrolled joints on the bodies from the base to the last controlled joint's body: locking
    one of those changes the arm itself (unlike a gripper's fingers beyond it), so only the arm
    file may do it."""
    on_path: set[int] = set()
    b = bodies[-1]
    while b != 0:
        on_path.add(b)
        b = int(m.body_parentid[b])
    return [j for j in range(m.njnt) if j not in controlled and int(m.jnt_bodyid[j]) in on_path]


def _dbc_drive_slots() -> int:
    from gen.lib.busload import DEFAULT_DBC

    return _drive_slots(DEFAULT_DBC, DEFAULT_DBC.stat().st_mtime_ns)


@functools.lru_cache(maxsize=4)
def _drive_slots(dbc: Path, mtime_ns: int) -> int:
    """Read once per version of the file (cantools parses a DBC in a tenth of a second)."""
    from gen.drive_ids import drive_slots

    return len(drive_slots(dbc)["STATE"])


def _check_arm_file_names(m0: mujoco.MjModel, chain: Chain, af: ArmFile, path: Path) -> None:
    for k in af.locked:
        if k in chain.names:
            raise ArmError(f"arm file {af.path}: locked: '{k}' is also a controlled joint")
        if mujoco.mj_name2id(m0, mujoco.mjtObj.mjOBJ_JOINT, k) < 0:
            raise ArmError(f"arm file {af.path}: locked: no joint '{k}' in {path.name}")
    for k in af.torque_limits:
        if k not in chain.names:
            raise ArmError(f"arm file {af.path}: torque_limits: '{k}' is not a controlled joint "
                           f"({', '.join(chain.names)})")


def _check_loops(m0: mujoco.MjModel, chain: Chain, path: Path) -> None:
    """Closed chains: an equality constraint that couples controlled joints, or that connects or welds
    a link of the arm to anything but a mocap body (a handle to drag the arm by, dropped with the
    model's other equalities)."""
    for e in range(m0.neq):
        et = int(m0.eq_type[e])
        objs = (int(m0.eq_obj1id[e]), int(m0.eq_obj2id[e]))
        if et == int(mujoco.mjtEq.mjEQ_JOINT) and any(o in chain.joints for o in objs):
            raise ArmError(f"model {path}: equality constraint {e} couples controlled joint(s): a closed or coupled "
                           "chain the firmware's serial-chain model cannot represent")
        if et in (int(mujoco.mjtEq.mjEQ_CONNECT), int(mujoco.mjtEq.mjEQ_WELD)):
            if int(m0.eq_objtype[e]) == int(mujoco.mjtObj.mjOBJ_SITE):
                objs = tuple(int(m0.site_bodyid[o]) if o >= 0 else 0 for o in objs)
            if any(o in chain.bodies for o in objs) and not any(o > 0 and m0.body_mocapid[o] >= 0 for o in objs):
                raise ArmError(f"model {path}: equality constraint {e} closes a loop through the arm (connect/weld): "
                               "closed chains are not supported")
