"""The arm's RNEA as straight-line C with its constants folded: `python -m gen.rnea_kernel --mjcf
PREPARED --out DIR` writes arm_rnea_kernel.h and arm_rnea_kernel.c.

It computes what firmware/core/src/rnea.c computes, in the same order of the same recursions,
but the generator knows the arm: a joint axis along z turns the joint rotation into two
products per entry instead of Rodrigues' formula and a 3x3 product; a zero in a link frame, a
centre of mass or an inertia drops every product it would enter; a 1 drops a multiplication;
the base at rest drops the first joint's velocity terms; quantities nothing reads are dropped;
each joint takes one sinf/cosf pair (one sincosf once compiled). What remains is emitted as
one C statement per vector component, named after the recursion's quantity (w2_x: the angular
velocity of link 2, x component), so the code reads as the algorithm. Rotation entries within 1e-7 of 0 or +-1 are taken as exact (quaternions such as
0.707106781 leave 1e-17 residues that would cost a multiplication each). The controller uses
the kernel for the model it was generated from (arm_rnea_kernel_fits: the same hash, links and
gravity) and rnea.c for any other; tests/c/test_rnea.c holds both to MuJoCo's mj_inverse.
"""

from __future__ import annotations

import argparse
import re
import sys
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from gen.lib.atomic_output import exit_on_output_error, write_files_atomically
from gen.lib.escape import c_comment
from gen.lib.one_line import one_line
from gen.robot_model import ModelError, RobotModel, extract, fnv1a64

SNAP = 1e-7


@dataclass(frozen=True)
class X:
    """A scalar of the emitted code: a constant, or a C expression that is a single name."""
    const: float | None = None
    name: str | None = None

    @property
    def zero(self) -> bool:
        return self.const == 0.0


ZERO = X(const=0.0)


def _lit(v: float) -> str:
    s = f"{float(v):.9g}"
    if not any(ch in s for ch in ".en"):
        s += ".0"
    return s + "f"


class Emitter:
    def __init__(self) -> None:
        self.lines: list[str] = []

    def comment(self, text: str) -> None:
        self.lines.append(f"    /* {c_comment(text)} */")

    def sop(self, name: str, terms: list[tuple[float, X, X]]) -> X:
        """sum of sign * a * b, folded: zeros dropped, constants multiplied out, +-1 dropped."""
        const = 0.0
        parts: list[str] = []
        for sign, a, b in terms:
            if a.zero or b.zero:
                continue
            if a.const is not None and b.const is not None:
                const += sign * a.const * b.const
                continue
            if a.const is None and b.const is not None:
                a, b = b, a
            if a.const is not None:  # constant times a name
                k = sign * a.const
                if k == 1.0:
                    parts.append(f"+ {b.name}")
                elif k == -1.0:
                    parts.append(f"- {b.name}")
                else:
                    parts.append(f"{'-' if k < 0 else '+'} {_lit(abs(k))} * {b.name}")
            else:
                parts.append(f"{'-' if sign < 0 else '+'} {a.name} * {b.name}")
        if not parts:
            return X(const=const)
        if len(parts) == 1 and const == 0.0 and parts[0].startswith("+ ") and "*" not in parts[0]:
            return X(name=parts[0][2:])  # a name as it is: no copy
        expr = " ".join(parts)
        expr = expr[2:] if expr.startswith("+ ") else "-" + expr[2:]
        if const != 0.0:
            expr += f" {'-' if const < 0 else '+'} {_lit(abs(const))}"
        self.lines.append(f"    const float {name} = {expr};")
        return X(name=name)

    def lin(self, name: str, terms: list[tuple[float, X]]) -> X:
        return self.sop(name, [(s, x, X(const=1.0)) for s, x in terms])


def _c(v: float) -> X:
    return X(const=float(v))


def _snap(v: float) -> float:
    for target in (0.0, 1.0, -1.0):
        if abs(v - target) < SNAP:
            return target
    return float(v)


def _offset(v: list[float]) -> list[X]:
    """A translation or centre of mass: only residues near 0 are snapped (a length near 1 m is a length)."""
    return [_c(0.0 if abs(x) < SNAP else x) for x in v]


def _unit(v: list[float]) -> list[X]:
    """A joint axis: entries near 0 or +-1 are exact."""
    return [_c(_snap(x)) for x in v]


AX = "xyz"


def _cross(e: Emitter, name: str, a: list[X], b: list[X]) -> list[X]:
    return [e.sop(f"{name}_{AX[k]}", [(1.0, a[(k + 1) % 3], b[(k + 2) % 3]), (-1.0, a[(k + 2) % 3], b[(k + 1) % 3])])
            for k in range(3)]


def _matvec(e: Emitter, name: str, m: list[list[X]], v: list[X], transpose: bool = False) -> list[X]:
    return [e.sop(f"{name}_{AX[i]}", [(1.0, m[k][i] if transpose else m[i][k], v[k]) for k in range(3)])
            for i in range(3)]


def _add(e: Emitter, name: str, *vs: list[X]) -> list[X]:
    return [e.lin(f"{name}_{AX[k]}", [(1.0, v[k]) for v in vs]) for k in range(3)]


def _rotation(e: Emitter, i: int, rot: np.ndarray, axis: np.ndarray) -> list[list[X]]:
    """The link's rotation at q: the fixed part times the joint's rotation about its axis."""
    c, s = X(name=f"c{i}"), X(name=f"s{i}")
    r = [[_c(_snap(rot[a][b])) for b in range(3)] for a in range(3)]
    if np.allclose(axis, [0, 0, 1]):
        # rot * Rz(q): two columns mix, the third is fixed
        return [[e.sop(f"R{i}_{a}0", [(1.0, r[a][0], c), (1.0, r[a][1], s)]),
                 e.sop(f"R{i}_{a}1", [(-1.0, r[a][0], s), (1.0, r[a][1], c)]),
                 r[a][2]] for a in range(3)]
    # any other axis: Rodrigues' formula, with its constants folded
    ax = _unit(axis)
    e.lines.append(f"    const float v{i} = 1.0f - c{i};")
    v = X(name=f"v{i}")
    aa = [[_c(_snap(axis[a] * axis[b])) for b in range(3)] for a in range(3)]
    skew = [[ZERO, (-1.0, ax[2]), (1.0, ax[1])], [(1.0, ax[2]), ZERO, (-1.0, ax[0])], [(-1.0, ax[1]), (1.0, ax[0]), ZERO]]
    rj = []
    for a in range(3):
        row = []
        for b in range(3):
            terms = [(1.0, aa[a][b], v)]
            if a == b:
                terms.append((1.0, X(const=1.0), c))
            if skew[a][b] is not ZERO:
                sign, k = skew[a][b]
                terms.append((sign, k, s))
            row.append(e.sop(f"J{i}_{a}{b}", terms))
        rj.append(row)
    return [[e.sop(f"R{i}_{a}{b}", [(1.0, r[a][k], rj[k][b]) for k in range(3)]) for b in range(3)] for a in range(3)]


DEF = re.compile(r"^    const float (\w+) = (.*);$")
COMMENT = re.compile(r"^\s*/\*")


def _live(lines: list[str]) -> list[str]:
    """The lines without the quantities nothing uses (the recursion computes some that only a
    parent would need, and the base has none: the first joint's force, a moment nobody reads)."""
    while True:
        used: dict[str, int] = {}
        for ln in lines:
            if COMMENT.match(ln):
                continue  # a comment names a joint, whatever its name: it uses nothing
            m = DEF.match(ln)
            for name in re.findall(r"\b[A-Za-z_]\w*\b", m.group(2) if m else ln):
                used[name] = used.get(name, 0) + 1
        keep = [ln for ln in lines if not (m := DEF.match(ln)) or used.get(m.group(1), 0) > 0]
        if len(keep) == len(lines):
            return keep
        lines = keep


@dataclass
class _Frames:
    """Each link's constants in its own frame: joint origin, joint axis, centre of mass."""
    pos: list[list[X]]
    axis: list[list[X]]
    com: list[list[X]]


def _forward(e: Emitter, model: RobotModel, fr: _Frames) -> tuple[list[Any], list[list[X]], list[list[X]]]:
    """The forward pass, base to tip: each link's rotation, net force and net moment."""
    w = [ZERO, ZERO, ZERO]
    dw = [ZERO, ZERO, ZERO]
    acc = [_c(-g) for g in model.gravity]
    rots: list[Any] = []
    force: list[list[X]] = []
    moment: list[list[X]] = []
    for i, ln in enumerate(model.links):
        e.comment(f"link {i + 1} ({ln.name}): forward")
        rot = _rotation(e, i, ln.rot, ln.axis)
        rots.append(rot)
        t1 = _cross(e, f"dwp{i}", dw, fr.pos[i])
        t2 = _cross(e, f"wwp{i}", w, _cross(e, f"wp{i}", w, fr.pos[i]))
        a_parent = _add(e, f"ap{i}", acc, t1, t2)
        acc = _matvec(e, f"a{i}", rot, a_parent, transpose=True)
        w_in = _matvec(e, f"wi{i}", rot, w, transpose=True)
        dw_in = _matvec(e, f"dwi{i}", rot, dw, transpose=True)
        qd, qdd = X(name=f"qd[{i}]"), X(name=f"qdd[{i}]")
        wq = [e.sop(f"wq{i}_{AX[k]}", [(1.0, fr.axis[i][k], qd)]) for k in range(3)]
        cross_wq = _cross(e, f"wxq{i}", w_in, wq)
        w = _add(e, f"w{i}", w_in, wq)
        dw = [e.sop(f"dw{i}_{AX[k]}", [(1.0, dw_in[k], X(const=1.0)), (1.0, fr.axis[i][k], qdd), (1.0, cross_wq[k], X(const=1.0))])
              for k in range(3)]
        ac = _add(e, f"ac{i}", acc, _cross(e, f"dwc{i}", dw, fr.com[i]),
                  _cross(e, f"wwc{i}", w, _cross(e, f"wc{i}", w, fr.com[i])))
        force.append([e.sop(f"F{i}_{AX[k]}", [(1.0, _c(ln.mass), ac[k])]) for k in range(3)])
        inertia = [[_c(ln.inertia[a][b]) for b in range(3)] for a in range(3)]
        iw = _matvec(e, f"Iw{i}", inertia, w)
        moment.append(_add(e, f"N{i}", _matvec(e, f"Idw{i}", inertia, dw), _cross(e, f"wIw{i}", w, iw)))
    return rots, force, moment


def _backward(e: Emitter, model: RobotModel, fr: _Frames, rots: list[Any], force: list[list[X]],
              moment: list[list[X]]) -> None:
    """The backward pass, tip to base: each joint's torque into tau[i]."""
    n = len(model.links)
    f = [ZERO, ZERO, ZERO]
    nm = [ZERO, ZERO, ZERO]
    for i in reversed(range(n)):
        ln = model.links[i]
        e.comment(f"link {i + 1} ({ln.name}): backward")
        if i + 1 < n:
            rc = rots[i + 1]
            f_child = _matvec(e, f"fc{i}", rc, f)
            n_rot = _matvec(e, f"nr{i}", rc, nm)
            n_child = _add(e, f"nc{i}", n_rot, _cross(e, f"pxf{i}", fr.pos[i + 1], f_child))
        else:
            f_child, n_child = [ZERO] * 3, [ZERO] * 3
        cxf = _cross(e, f"cxf{i}", fr.com[i], force[i])
        f = _add(e, f"f{i}", force[i], f_child)
        nm = _add(e, f"n{i}", moment[i], cxf, n_child)
        tau = e.sop(f"tau{i}", [(1.0, fr.axis[i][k], nm[k]) for k in range(3)]
                    + [(1.0, _c(ln.armature), X(name=f"qdd[{i}]")), (1.0, _c(ln.damping), X(name=f"qd[{i}]"))])
        e.lines.append(f"    tau[{i}] = {tau.name if tau.name else _lit(tau.const or 0.0)};")


def _with_trig(lines: list[str], n: int) -> list[str]:
    """The live lines, after one sine and cosine per joint, only those used (the base at rest needs
    neither for the first joint's velocity terms): the compiler makes a pair one sincosf where the
    C library has it (glibc, newlib); C11 itself has no sincos."""
    lines = _live(lines)
    body = "\n".join(ln for ln in lines if not COMMENT.match(ln))
    trig = []
    for i in range(n):
        used = [f"{f} = {fn}(q[{i}])" for f, fn in ((f"s{i}", "sinf"), (f"c{i}", "cosf"))
                if re.search(rf"\b{f}\b", body)]
        if used:
            trig.append(f"    const float {', '.join(used)};")
    return trig + lines


def _kernel_header(model_hash: int) -> str:
    return (
        "/* Generated by gen/rnea_kernel.py. Do not edit. The arm's RNEA with its constants folded\n"
        " * (gen/rnea_kernel.py says how); arm/rnea.h's arm_rnea for any other model. */\n"
        "#ifndef ARM_RNEA_KERNEL_H\n#define ARM_RNEA_KERNEL_H\n\n"
        '#include "arm/robot_model.h"\n\n'
        "/* The model the kernel was generated for (its FNV-1a 64 hash, arm_robot_model_t.model_hash). */\n"
        f"#define ARM_RNEA_KERNEL_HASH 0x{model_hash:016x}ull\n\n"
        "/* 1 when model is the one the kernel was generated from (same hash, links and gravity):\n"
        " * the controller then uses the kernel, else arm_rnea. */\n"
        "int arm_rnea_kernel_fits(const arm_robot_model_t *model);\n\n"
        "/* tau = M(q) qdd + V(q, qd) + G(q) of that model, as arm_rnea computes it. */\n"
        "void arm_rnea_kernel(const float q[ARM_N_JOINTS], const float qd[ARM_N_JOINTS],\n"
        "                     const float qdd[ARM_N_JOINTS], float tau[ARM_N_JOINTS]);\n\n#endif\n"
    )


def _kernel_c(lines: list[str]) -> str:
    return (
        "/* Generated by gen/rnea_kernel.py from the arm's prepared model. Do not edit.\n"
        " * Names: R<i>: link i's rotation; w, dw: angular velocity and acceleration; a: linear\n"
        " * acceleration of the link origin; ac: of its centre of mass; F, N: net force and moment;\n"
        " * f, n: the wrench the parent exerts; _x/_y/_z: components in the link frame. */\n"
        "#include <math.h>\n#include <string.h>\n\n"
        '#include "arm_rnea_kernel.h"\n#include "arm_robot_model_data.h"\n\n'
        "int arm_rnea_kernel_fits(const arm_robot_model_t *model)\n{\n"
        "    return model->model_hash == ARM_RNEA_KERNEL_HASH &&\n"
        "           memcmp(model->link, ARM_ROBOT_MODEL.link, sizeof(model->link)) == 0 &&\n"
        "           memcmp(model->gravity, ARM_ROBOT_MODEL.gravity, sizeof(model->gravity)) == 0;\n}\n\n"
        "void arm_rnea_kernel(const float q[ARM_N_JOINTS], const float qd[ARM_N_JOINTS],\n"
        "                     const float qdd[ARM_N_JOINTS], float tau[ARM_N_JOINTS])\n{\n"
        + "\n".join(lines) + "\n}\n"
    )


def kernel_source(model: RobotModel, model_hash: int) -> tuple[str, str]:
    e = Emitter()
    fr = _Frames(pos=[_offset(ln.pos) for ln in model.links], axis=[_unit(ln.axis) for ln in model.links],
                 com=[_offset(ln.com) for ln in model.links])
    rots, force, moment = _forward(e, model, fr)
    _backward(e, model, fr, rots, force, moment)
    return _kernel_header(model_hash), _kernel_c(_with_trig(e.lines, len(model.links)))


@exit_on_output_error("gen.rnea_kernel")
def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="python -m gen.rnea_kernel", description=__doc__.splitlines()[0])
    p.add_argument("--mjcf", type=Path, required=True, help="the prepared arm (gen/arm)")
    p.add_argument("--out", type=Path, required=True)
    ns = p.parse_args(argv)
    try:
        model = extract(ns.mjcf)
    except (ModelError, ValueError) as exc:
        print(f"rnea kernel: {one_line(str(exc))}", file=sys.stderr)
        return 2
    header, source = kernel_source(model, fnv1a64(ns.mjcf.read_bytes()))
    write_files_atomically(ns.out, {"arm_rnea_kernel.h": header, "arm_rnea_kernel.c": source})
    return 0


if __name__ == "__main__":
    sys.exit(main())
