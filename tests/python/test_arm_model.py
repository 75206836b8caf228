"""The MJCF arm is the UR5e of Universal Robots' published DH table, and the nominal model header
is extracted from it faithfully."""

from __future__ import annotations

from pathlib import Path

import mujoco
import numpy as np
import pytest

from gen import robot_model
from gen.robot_model import DEFAULT_MJCF

DH_D = [0.1625, 0, 0, 0.1333, 0.0997, 0.0996]
DH_A = [0, -0.425, -0.3922, 0, 0, 0]
DH_ALPHA = [np.pi / 2, 0, 0, np.pi / 2, -np.pi / 2, 0]
UR5E_MASS = [3.761, 8.058, 2.846, 1.37, 1.3, 0.365]


def dh_flange(q: np.ndarray) -> np.ndarray:
    t = np.eye(4)
    for i in range(6):
        ct, st = np.cos(q[i]), np.sin(q[i])
        ca, sa = np.cos(DH_ALPHA[i]), np.sin(DH_ALPHA[i])
        t = t @ np.array([[ct, -st * ca, st * sa, DH_A[i] * ct], [st, ct * ca, -ct * sa, DH_A[i] * st],
                          [0, sa, ca, DH_D[i]], [0, 0, 0, 1]])
    return t


def test_flange_pose_matches_ur5e_dh_forward_kinematics() -> None:
    m = mujoco.MjModel.from_xml_path(str(DEFAULT_MJCF))
    d = mujoco.MjData(m)
    site = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_SITE, "flange")
    rng = np.random.default_rng(7)
    for _ in range(50):
        q = rng.uniform(-np.pi, np.pi, 6)
        d.qpos[:] = q
        mujoco.mj_kinematics(m, d)
        t = dh_flange(q)
        assert np.allclose(d.site_xpos[site], t[:3, 3], atol=1e-12)
        assert np.allclose(d.site_xmat[site].reshape(3, 3), t[:3, :3], atol=1e-12)


def test_masses_and_torque_limits() -> None:
    m = mujoco.MjModel.from_xml_path(str(DEFAULT_MJCF))
    assert np.allclose(m.body_mass[1:], UR5E_MASS)
    assert list(m.actuator_ctrlrange[:, 1]) == [150, 150, 150, 28, 28, 28]  # the emulated drives' limits
    assert m.opt.timestep == pytest.approx(0.001)


def test_nominal_model_header_matches_mujoco(tmp_path: Path) -> None:
    model = robot_model.extract(DEFAULT_MJCF)
    assert len(model.links) == 6
    assert [ln.torque_limit for ln in model.links] == [150, 150, 150, 28, 28, 28]
    assert np.isclose(sum(ln.mass for ln in model.links), sum(UR5E_MASS))
    for ln in model.links:
        assert np.allclose(ln.rot @ ln.rot.T, np.eye(3), atol=1e-9)
        assert np.all(np.linalg.eigvalsh(ln.inertia) > 0)
    assert robot_model.main(["--out", str(tmp_path), "--golden", "2"]) == 0
    text = (tmp_path / "arm_robot_model_data.h").read_text()
    assert "ARM_ROBOT_MODEL_HASH" in text and '"wrist_3"' in text
    assert "#define ARM_N_JOINTS 6" in (tmp_path / "arm_robot_dims.h").read_text()


def test_nominal_parameter_error_scales_the_model() -> None:
    true = robot_model.extract(DEFAULT_MJCF)
    off = robot_model.extract(DEFAULT_MJCF, mass_scale=1.1, inertia_scale=0.9)
    assert off.links[1].mass == pytest.approx(1.1 * true.links[1].mass)
    assert np.allclose(off.links[1].inertia, 0.9 * true.links[1].inertia)


def test_unprepared_model_is_refused_with_what_to_do(tmp_path: Path) -> None:
    """gen.robot_model reads prepared arms only (gen/arm makes them); anything else is named."""
    bad = tmp_path / "bad.xml"
    bad.write_text(DEFAULT_MJCF.read_text().replace("</actuator>", '<motor joint="wrist_3" ctrlrange="-1 1"/></actuator>'))
    with pytest.raises(robot_model.ModelError, match="prepare|expected a prepared arm"):
        robot_model.extract(bad)
    out = tmp_path / "out"
    assert robot_model.main(["--mjcf", str(bad), "--out", str(out)]) == 2
    assert not out.exists() or not any(out.iterdir())  # nothing half-written


def test_every_joint_has_cited_armature_damping_and_friction() -> None:
    """A real geared joint has rotor inertia and friction: the bundled arm carries them on every
    joint, and the docs' table (docs/simulated-arm.md, The bundled arm) gives the MJCF's own values, with the sources
    the MJCF's comments cite."""
    m = mujoco.MjModel.from_xml_path(str(DEFAULT_MJCF))
    readme = (Path(__file__).resolve().parents[2] / "docs" / "simulated-arm.md").read_text()
    section = readme[readme.index("## The bundled arm: armature and friction"):readme.index("## Realistic drives")]
    xml = DEFAULT_MJCF.read_text()
    for source in ("mujoco_menagerie", "universal_robots_ur5e/ur5e.xml", "INTO-CPS-Association/aurt",
                   "robot_calibration_summary.txt"):
        assert source in xml and source in section, source
    for j in range(m.njnt):
        name = mujoco.mj_id2name(m, mujoco.mjtObj.mjOBJ_JOINT, j)
        dof = m.jnt_dofadr[j]
        values = (m.dof_armature[dof], m.dof_damping[dof], m.dof_frictionloss[dof])
        assert all(v > 0 for v in values), (name, values)
        row = next(line for line in section.splitlines() if line.startswith(f"| {name} |"))
        cells = [float(c) for c in row.strip("|").split("|")[1:]]
        assert np.allclose(cells, values, rtol=1e-12), (name, cells, values)
