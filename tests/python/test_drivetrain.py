"""The arm's drive train (gen/drivetrain.py): the preset's rule by joint size, the arm file's own
values and their one-line errors, which joints the simulator makes flexible and why not, the plant
it builds (its two-mass mode rings at the frequency the report states), and the payload's site."""

from __future__ import annotations

import json
import math
from pathlib import Path

import mujoco
import numpy as np
import pytest

from gen import drivetrain
from gen.arm import ArmError, load_arm_file, prepare

# One link on one hinge, no gravity: J about the axis from a point mass on an arm of 0.2 m.
PENDULUM = """<mujoco model="pendulum">
  <option timestep="0.001" gravity="0 0 0"/>
  <worldbody>
    <body name="link">
      <joint name="j1" axis="0 0 1" armature="{armature}" actuatorfrcrange="-50 50"/>
      <inertial pos="0.2 0 0" mass="2.0" diaginertia="1e-4 1e-4 1e-4"/>
      <site name="tool_flange" pos="0.3 0 0"/>
    </body>
  </worldbody>
  <actuator><motor joint="j1" ctrlrange="-50 50"/></actuator>
</mujoco>
"""


def _pendulum(tmp_path: Path, armature: float, table: str = "") -> dict:
    model = tmp_path / "pendulum.xml"
    model.write_text(PENDULUM.format(armature=armature))
    arm = tmp_path / "pendulum.toml"
    arm.write_text(f'model = "{model.name}"\nrated_payload_kg = 1.5\n{table}')
    prep = prepare(load_arm_file(arm), None)
    return {"info": prep.info, "plant": prep.plant_xml, "xml": prep.xml}


def test_size_is_the_smallest_whose_peak_torque_holds_the_limit() -> None:
    assert drivetrain.size_for(150.0).size == 25  # the UR5e's base, shoulder and elbow
    assert drivetrain.size_for(28.0).size == 14  # its wrists
    assert drivetrain.size_for(29.0).size == 17
    assert drivetrain.size_for(1e4).size == 40  # beyond the table: its largest
    assert all(a.peak_nm < b.peak_nm and a.k[1] < b.k[1] for a, b in zip(drivetrain.HARMONIC_SIZES,
                                                                          drivetrain.HARMONIC_SIZES[1:]))


def test_the_bundled_arm_is_flexible_where_the_step_resolves_it(tmp_path: Path) -> None:
    from gen.arm import DEFAULT_MODEL

    info = prepare(load_arm_file(None, DEFAULT_MODEL), None).info
    dt = {j["name"]: j for j in info["drivetrain"]}
    assert [j["size"] for j in info["drivetrain"]] == [25, 25, 25, 14, 14, 14]
    assert dt["shoulder_lift"]["stiffness"] == 5.0e4 and dt["wrist_1"]["stiffness"] == 6.1e3
    assert dt["shoulder_pan"]["rotor_inertia"] == pytest.approx(1.73)
    assert [j["flexible"] for j in info["drivetrain"]] == [True, True, True, True, False, False]
    assert "beyond what the 1 ms step resolves" in dt["wrist_3"]["rigid_because"]
    # the first resonance is the shoulder's, motor locked: tens of Hz, as on a real UR-class arm
    assert info["first_resonance_hz"] == pytest.approx(dt["shoulder_lift"]["resonance_locked_hz"])
    assert 15.0 < info["first_resonance_hz"] < 40.0
    assert info["payload"]["rated_kg"] == 5.0 and "flange" in info["payload"]["at"]


def test_the_plant_rings_at_the_two_mass_frequency_it_states(tmp_path: Path) -> None:
    """The plant's mode, measured by letting it ring, against sqrt(K (1/J_link + 1/J_rotor))."""
    p = _pendulum(tmp_path, armature=0.05, table="[drivetrain]\nstiffness = [800.0]\ndamping = [0.0]\n")
    j = p["info"]["drivetrain"][0]
    assert j["flexible"] and j["stiffness"] == 800.0 and j["rotor_inertia"] == 0.05
    m = mujoco.MjModel.from_xml_string(p["plant"])
    assert m.nv == 2 and m.ntendon == 1
    d = mujoco.MjData(m)
    d.qpos[1] = 0.01  # the rotor turned, the link not: the gear's spring rings
    t, link = [], []
    for k in range(4000):
        mujoco.mj_step(m, d)
        t.append(k * m.opt.timestep)
        link.append(d.qpos[0] - d.qpos[1])
    x = np.array(link) - np.mean(link)
    crossings = np.nonzero(np.diff(np.signbit(x)))[0]
    measured = (len(crossings) - 1) / (2.0 * (t[crossings[-1]] - t[crossings[0]]))
    assert measured == pytest.approx(j["resonance_free_hz"], rel=0.03)


def test_a_joint_without_rotor_inertia_is_simulated_rigid_and_says_why(tmp_path: Path) -> None:
    p = _pendulum(tmp_path, armature=0.0)
    j = p["info"]["drivetrain"][0]
    assert not j["flexible"] and "rotor_inertia" in j["rigid_because"]
    assert mujoco.MjModel.from_xml_string(p["plant"]).nv == 1
    given = _pendulum(tmp_path, armature=0.0, table="[drivetrain]\nrotor_inertia = { j1 = 0.02 }\nstiffness = [800.0]\n")
    assert given["info"]["drivetrain"][0]["flexible"]
    assert given["info"]["drivetrain"][0]["rotor_inertia_from"] == "arm file"
    # the nominal model knows it too: the arm file's rotor inertia is the joint's armature in arm.xml
    assert mujoco.MjModel.from_xml_string(given["xml"]).dof_armature[0] == pytest.approx(0.02)


def test_the_payload_hangs_at_the_flange_site(tmp_path: Path) -> None:
    p = _pendulum(tmp_path, armature=0.05)
    m = mujoco.MjModel.from_xml_string(p["xml"])
    s = m.site(drivetrain.PAYLOAD_SITE)
    assert np.allclose(s.pos, [0.3, 0, 0]) and "tool_flange" in p["info"]["payload"]["at"]
    assert p["info"]["payload"]["rated_kg"] == 1.5


@pytest.mark.parametrize("table, words", [
    ("[drivetrain]\nstiffnes = [1.0]\n", "unknown field(s) ['stiffnes']"),
    ("[drivetrain]\nstiffness = [1.0, 2.0]\n", "stiffness: 2 values for 1 joints"),
    ("[drivetrain]\nstiffness = { j9 = 1.0 }\n", "'j9' is not a controlled joint"),
    ("[drivetrain]\nstiffness = [-5.0]\n", "stiffness.j1: must be a number > 0"),
    ("[drivetrain]\nsize = [15]\n", "size.j1: 15 is not a size of the preset"),
    ("[drivetrain]\ndamping_ratio = 3\n", "damping_ratio: a number in (0, 2]"),
    ("flange = \"nowhere\"\n", "flange: no site 'nowhere'"),
])
def test_a_bad_drive_train_is_one_line_naming_the_field(tmp_path: Path, table: str, words: str) -> None:
    with pytest.raises(ArmError) as err:
        _pendulum(tmp_path, armature=0.05, table=table)
    assert words in str(err.value) and "\n" not in str(err.value)


def test_arm_json_of_a_build_carries_the_drive_train(tmp_path: Path) -> None:
    """What the report and the study read (arm.json), as gen.arm writes it."""
    from gen.arm import main

    out = tmp_path / "arm"
    model = tmp_path / "pendulum.xml"
    model.write_text(PENDULUM.format(armature=0.05))
    assert main(["--model", str(model), "--out", str(out)]) == 0
    info = json.loads((out / "arm.json").read_text())
    assert (out / "plant.xml").is_file() and info["drivetrain"][0]["size"] == 17  # 50 N m: size 17 holds 54
    assert math.isfinite(info["first_resonance_hz"]) and info["payload"]["rated_kg"] == 0.0
