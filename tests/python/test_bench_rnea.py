"""Our inverse dynamics agrees with Pinocchio's on the bundled arm: the general arm_rnea and the
arm's generated kernel against Pinocchio's rnea given the arm's armature (model.armature) and joint
damping, on the 200 states `armctl bench step` checks before it counts anything.

Our torques come from tests/c/rnea_torques.c (the debug build's core and kernel; it prints the
model it ran, from the generated header, and the states of tests/bench/rnea_states.h); Pinocchio's
from its Python bindings (pinocchio 4.1, the library bench_rnea links), on a model built from those
printed numbers as bench_rnea.cpp builds its own. bench_rnea's compiled check of the same comparison
(about 2 minutes and 4.7 GB to compile Pinocchio's headers) runs in `armctl bench step` alone."""

from __future__ import annotations

import subprocess
from pathlib import Path

import numpy as np
import pinocchio as pin  # requirements.lock's pin wheel: a plain import, never a skip

STATES = 200
REL_TOL = 1e-5  # bench_rnea check's bound: the largest difference over the state's largest torque (or 1 N m)


def _f32(words: list[str]) -> np.ndarray:
    """The printed floats as the floats C had (9 digits read back as float32, then widened)."""
    return np.array([float(w) for w in words], dtype=np.float32).astype(np.float64)


def _ours(build_dir: Path) -> tuple[np.ndarray, list[np.ndarray], list[np.ndarray]]:
    exe = build_dir / "tests" / "c" / "rnea_torques"
    assert exe.exists(), f"{exe} not built (the debug build's tests/c)"
    out = subprocess.run([str(exe)], capture_output=True, text=True, check=True).stdout.splitlines()
    rows: dict[str, list[np.ndarray]] = {"gravity": [], "link": [], "state": []}
    for line in out:
        kind, *words = line.split()
        rows[kind].append(_f32(words))
    (gravity,) = rows["gravity"]
    return gravity, rows["link"], rows["state"]


def _pinocchio_model(gravity: np.ndarray, links: list[np.ndarray]):
    """bench_rnea.cpp's build_model, in Python: each link's frame, axis, inertia, armature, damping."""
    model = pin.Model()
    model.gravity = pin.Motion(gravity, np.zeros(3))
    parent = 0
    for i, l in enumerate(links):
        pos, rot, axis, mass, com, inertia = l[0:3], l[3:12].reshape(3, 3), l[12:15], l[15], l[16:19], l[19:28]
        joint = (pin.JointModelRZ() if tuple(axis) == (0.0, 0.0, 1.0) else pin.JointModelRevoluteUnaligned(axis))
        jid = model.addJoint(parent, joint, pin.SE3(rot, pos), f"joint{i + 1}")
        model.appendBodyToJoint(jid, pin.Inertia(float(mass), com, inertia.reshape(3, 3)), pin.SE3.Identity())
        parent = jid
    model.armature = np.array([l[28] for l in links])
    model.damping = np.array([l[29] for l in links])
    return model


def test_pinocchio_and_our_rnea_agree_on_the_bundled_arm(build_dir: Path) -> None:
    gravity, links, states = _ours(build_dir)
    n = len(links)
    assert n >= 1 and len(states) == STATES and all(len(s) == 5 * n for s in states)
    model = _pinocchio_model(gravity, links)
    assert model.nq == n and np.all(model.armature > 0), model.armature  # compared with armature, not without
    data = model.createData()
    worst, where = 0.0, ""
    for k, s in enumerate(states):
        q, qd, qdd, tau, tau_kernel = (s[i * n:(i + 1) * n] for i in range(5))
        # Pinocchio's rnea adds armature * qdd but leaves the joint damping out: ours adds damping * qd
        want = pin.rnea(model, data, q, qd, qdd) + model.damping * qd
        scale = max(1.0, float(np.max(np.abs(want))))
        for name, got in (("arm_rnea", tau), ("arm_rnea_kernel", tau_kernel)):
            rel = float(np.max(np.abs(got - want))) / scale
            if rel > worst:
                worst, where = rel, f"{name}, state {k}: ours {got.tolist()}, Pinocchio's {want.tolist()}"
    assert worst < REL_TOL, f"worst relative difference {worst:.3g} ({where})"
