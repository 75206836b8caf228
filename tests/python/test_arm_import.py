"""gen/arm on what real arm models contain: the public arms vendored in tests/arms, and small
models that each carry one thing the importer must take or refuse by name."""

from __future__ import annotations

import json
import math
from pathlib import Path

import mujoco
import numpy as np
import pytest

from gen import arm as gen_arm
from gen.arm import ArmError, clip_amplitude, inverse_forces, load_arm_file, prepare
from gen.arm.assets import default_classes, strip_meshes
from gen.robot_model import extract, nominal_for_inverse
from tools.build.arm import ArmChoiceError, reference_for

from arm_models import ARMATURE, UR5E, armature_variant, materials_variant

REPO = Path(__file__).resolve().parents[2]
ARMS = REPO / "tests" / "arms"
DESIGN = REPO / "gen" / "configs" / "paper.toml"
IIWA = ARMS / "robosuite" / "iiwa.xml"
PANDA_URDF = ARMS / "example-robot-data" / "panda.urdf"
UR5_URDF = ARMS / "example-robot-data" / "ur5_robot.urdf"


def prep(model: Path, **arm_file: object) -> gen_arm.Prepared:
    af = gen_arm.ArmFile(None, None, model)
    for k, v in arm_file.items():
        setattr(af, k, v)
    return prepare(af, DESIGN)


def chain_mjcf(n: int = 3, *, body_extra: str = "", joint_attrs: list[str] | None = None, tip_mass: float = 1.0,
               actuators: bool = True, extra: str = "", base_fixed_body: bool = True) -> str:
    """A serial chain of n hinge links, each with an explicit inertial (and optionally a fixed
    body in between): the smallest model of the shape real arms have."""
    attrs = joint_attrs or [""] * n
    body = body_extra
    for i in reversed(range(n)):
        mass = tip_mass if i == n - 1 else 1.0
        inertia = max(mass * 0.01, 1e-12)
        axis = "0 0 1" if i % 2 == 0 else "0 1 0"
        body = (f'<body name="l{i}" pos="0 0 0.2"><joint name="j{i}" axis="{axis}" range="-2 2" {attrs[i]}/>'
                f'<inertial pos="0 0 0.1" mass="{mass}" diaginertia="{inertia} {inertia} {inertia}"/>{body}</body>')
    if base_fixed_body:
        body = f'<body name="mount" pos="0 0 0.1" quat="0.924 0 0 0.383"><inertial pos="0 0 0" mass="2" ' \
               f'diaginertia="0.1 0.1 0.1"/>{body}</body>'
    acts = "".join(f'<motor joint="j{i}" ctrlrange="-50 50"/>' for i in range(n)) if actuators else ""
    return (f'<mujoco model="chain"><compiler angle="radian"/><worldbody>{body}</worldbody><actuator>{acts}</actuator>{extra}</mujoco>')


def write(tmp_path: Path, text: str, name: str = "arm.xml") -> Path:
    p = tmp_path / name
    p.write_text(text)
    return p


# ---- the public arms ------------------------------------------------------------------------
@pytest.mark.parametrize("model,n,limits", [
    (UR5E, 6, [150, 150, 150, 28, 28, 28]),
    (IIWA, 7, [176, 176, 110, 110, 110, 40, 40]),
    (PANDA_URDF, 7, [87, 87, 87, 87, 12, 12, 12]),
    (UR5_URDF, 6, [150, 150, 150, 28, 28, 28]),
])
def test_public_arms_are_prepared(model: Path, n: int, limits: list[float]) -> None:
    p = prep(model)
    info = p.info
    assert info["n_joints"] == n
    assert [j["torque_limit"] for j in info["joints"]] == limits
    assert info["timestep_s"] == pytest.approx(0.001) and info["substeps"] == 1
    assert any("timestep" in w for w in info["warnings"])  # the model's 2 ms is replaced, and it says so
    assert any("mesh" in w for w in info["warnings"])  # meshes are not vendored: dropped with a warning
    m = mujoco.MjModel.from_xml_string(p.xml)
    assert m.nq == m.nv == m.nu == n and m.opt.timestep == pytest.approx(0.001)
    assert m.ngeom == 0 and m.opt.disableflags & mujoco.mjtDisableBit.mjDSBL_CONTACT
    assert list(m.actuator_ctrlrange[:, 1]) == limits
    assert mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_KEY, "home") >= 0
    assert sum(len(b["drives"]) for b in info["buses"]) == n
    assert info["written_inverse_dynamics_error"] < 1e-4
    assert int(info["model_hash"], 16) == gen_arm.fnv1a64(p.xml.encode())


def test_robosuite_ur5e_fixed_base_bodies_are_fused_and_the_dynamics_kept() -> None:
    """robosuite's UR5e hangs the chain under two fixed bodies (base, and a rotated link): the
    prepared model has one body per joint, and its inverse dynamics equal the original's."""
    raw = mujoco.MjSpec.from_file(str(UR5E))
    strip_meshes(raw, default_classes(raw, UR5E))
    m0 = raw.compile()
    assert m0.nbody > 7  # world, fixed bodies, six links, the hand's bodies
    p = prep(UR5E)
    m = mujoco.MjModel.from_xml_string(p.xml)
    assert m.nbody == 7
    rng = np.random.default_rng(3)
    for m_ in (m0, m):
        nominal_for_inverse(m_)
    for _ in range(20):
        q, qd, qdd = rng.uniform(-2, 2, 6), rng.uniform(-1, 1, 6), rng.uniform(-3, 3, 6)
        out = inverse_forces((m0, m), q, qd, qdd)
        assert np.allclose(out[0], out[1], rtol=1e-4, atol=1e-4 * np.max(np.abs(out[0])))


def test_urdf_gripper_is_locked_and_its_mass_carried_by_the_last_link() -> None:
    p = prep(PANDA_URDF)
    assert [x["name"] for x in p.info["locked"]] == ["panda_finger_joint1", "panda_finger_joint2"]
    m = mujoco.MjModel.from_xml_string(p.xml)
    raw = mujoco.MjSpec.from_file(str(PANDA_URDF))
    strip_meshes(raw, default_classes(raw, PANDA_URDF))
    m0 = raw.compile()
    assert sum(m.body_mass) == pytest.approx(sum(m0.body_mass), rel=1e-6)  # fingers fused, not dropped


def test_armature_damping_and_gear_are_read_from_a_modified_public_arm(tmp_path: Path) -> None:
    model = armature_variant(tmp_path)
    p = prep(model)
    j = p.info["joints"]
    assert [x["armature"] for x in j] == ARMATURE
    assert all(x["damping"] == 1.0 and x["frictionloss"] == 2.0 for x in j)
    # ctrlrange 1.2 x gear 100 = 120 N m is tighter than forcerange 1.65 x 100 for the big joints
    assert [x["torque_limit"] for x in j] == pytest.approx([120, 120, 120, 30.8, 30.8, 30.8])
    assert "ctrlrange x gear" in j[0]["torque_limit_from"] and "forcerange x gear" in j[3]["torque_limit_from"]
    assert "armature" in p.info["nominal_model"] and "frictionloss" in p.info["nominal_model"]
    robot = extract_from_xml(tmp_path, p.xml)
    assert [ln.armature for ln in robot.links] == ARMATURE
    assert [ln.damping for ln in robot.links] == [1.0] * 6


def extract_from_xml(tmp_path: Path, xml: str):  # noqa: ANN201 - gen.robot_model.RobotModel
    p = tmp_path / "prepared.xml"
    p.write_text(xml)
    return extract(p)


# ---- the home pose and the reference -------------------------------------------------------
def test_home_from_keyframe_arm_file_or_mid_range(tmp_path: Path) -> None:
    bare = write(tmp_path, chain_mjcf())
    p = prep(bare)
    assert [j["home"] for j in p.info["joints"]] == [0, 0, 0]
    assert "mid-range" in p.info["home_from"] and any("home pose" in w for w in p.info["warnings"])
    keyed = write(tmp_path, chain_mjcf(extra='<keyframe><key name="home" qpos="0.1 0.2 0.3"/></keyframe>'), "k.xml")
    assert [j["home"] for j in prep(keyed).info["joints"]] == [0.1, 0.2, 0.3]
    assert [j["home"] for j in prep(keyed, home={"j0": 1, "j1": -1, "j2": 0.5}).info["joints"]] == [1, -1, 0.5]
    with pytest.raises(ArmError, match="joint 'j1' at 1.98 rad is not inside its range"):
        prep(keyed, home=[0, 1.98, 0])


def test_reference_stays_inside_the_ranges_with_a_warning_when_clipped() -> None:
    assert clip_amplitude(0.3, 0.0, [-2, 2]) == 0.3
    assert clip_amplitude(0.3, 1.8, [-2, 2]) == -0.3  # no room above: it moves down
    assert clip_amplitude(0.3, 1.8, [-1.9, 2]) == pytest.approx(-0.3)
    assert clip_amplitude(2.0, 0.0, [-2, 2]) == pytest.approx((2 - 0.05) / 2)
    assert clip_amplitude(5.0, 0.0, None) == 5.0
    info = prep(UR5E).info
    amp, freq, warnings = reference_for(info, [0.1, 0.1, 4.0, 0.1, 0.1, 0.1], None)
    assert amp[2] < 4.0 and len(warnings) == 1 and "elbow_joint" in warnings[0] and "clipped" in warnings[0]
    home, r = info["joints"][2]["home"], info["joints"][2]["range"]
    assert r[0] + 0.05 <= home + 2 * amp[2] <= r[1] - 0.05
    assert freq == info["reference"]["freq_hz"]
    for j, a in zip(info["joints"], info["reference"]["amp"]):  # the default reference is inside too
        assert j["range"][0] + 0.05 - 1e-12 <= j["home"] + 2 * a <= j["range"][1] - 0.05 + 1e-12
    with pytest.raises(ArmChoiceError, match="--ref-amp: 2 values for the arm's 6 joints"):
        reference_for(info, [0.1, 0.1], None)


# ---- what it refuses, by name ---------------------------------------------------------------
@pytest.mark.parametrize("text,match", [
    (chain_mjcf().replace('<body name="mount"', '<body name="mount"><freejoint name="float"/><body name="m2"')
     .replace("</worldbody>", "</body></worldbody>"), "joint 'float' is a free joint"),
    (chain_mjcf().replace('<joint name="j1" axis="0 1 0" range="-2 2" ', '<joint name="j1" type="ball" '),
     r"joint 'j1' \(ball\) sits inside the arm.*locked = \{ j1 = value \}"),
    (chain_mjcf().replace('<joint name="j1" axis="0 1 0"', '<joint name="j1" type="slide" axis="0 1 0"'),
     r"joint 'j1' \(slide \(prismatic\)\) sits inside the arm"),
    (chain_mjcf(tip_mass=1e-9), "joint 'j2' moves almost no inertia"),
    (chain_mjcf().replace('<inertial pos="0 0 0.1" mass="1.0" diaginertia="0.01 0.01 0.01"/></body></body></body>',
                          "</body></body></body>"), "mass and inertia"),
    (chain_mjcf(extra='<keyframe><key name="home" qpos="0 1.5 0"/></keyframe>').replace('ctrlrange="-50 50"',
                                                                                         'ctrlrange="-0.5 0.5"'),
     r"joint 'j1': its torque limit 0.5 N m \(actuator actuator1 ctrlrange x gear\) cannot hold the arm at home "
     r"\(keyframe 'home'\) against gravity \(needs 3.9\d N m\)"),
    (chain_mjcf(extra='<equality><connect body1="l2" body2="world" anchor="0 0 0"/></equality>'),
     "closes a loop through the arm"),
    (chain_mjcf(extra='<equality><joint joint1="j0" joint2="j1"/></equality>'), "couples controlled joint"),
    (chain_mjcf(n=9), "9 controlled joints; the firmware takes at most 16 and the protocol.*defines 8 drive slots"),
])
def test_what_the_controller_cannot_use_is_refused_by_name(tmp_path: Path, text: str, match: str) -> None:
    model = write(tmp_path, text)
    with pytest.raises(ArmError, match=match):
        prep(model)
    out = tmp_path / "out"
    assert gen_arm.main(["--model", str(model), "--out", str(out)]) == 2
    assert not out.exists()  # nothing half-written


def test_a_branch_ends_the_default_chain_and_a_wrong_joint_list_is_named(tmp_path: Path) -> None:
    # two fingers on the last link: the chain stops before them and both are locked
    fingers = ''.join(f'<body name="f{k}" pos="0 0 0.1"><joint name="finger{k}" type="slide" axis="1 0 0" '
                      f'range="0 0.04"/><inertial pos="0 0 0" mass="0.1" diaginertia="1e-4 1e-4 1e-4"/></body>'
                      for k in (1, 2))
    model = write(tmp_path, chain_mjcf(body_extra=fingers))
    p = prep(model)
    assert [j["name"] for j in p.info["joints"]] == ["j0", "j1", "j2"]
    assert {x["name"] for x in p.info["locked"]} == {"finger1", "finger2"}
    with pytest.raises(ArmError, match="joint 'j0' is not below joint 'j2'"):
        prep(model, joints=["j2", "j0"])
    with pytest.raises(ArmError, match="no joint 'wrist'"):
        prep(model, joints=["j0", "wrist"])
    with pytest.raises(ArmError, match=r"joint 'finger1' is a slide \(prismatic\) joint"):
        prep(model, joints=["j0", "j1", "j2", "finger1"])


def test_locked_joints_take_the_arm_files_value_and_move_the_links(tmp_path: Path) -> None:
    """Locking j1 at 0.7 rad must put everything beyond it where the joint would have put it."""
    model = write(tmp_path, chain_mjcf())
    p = prep(model, joints=["j0", "j2"], locked={"j1": 0.7})
    m = mujoco.MjModel.from_xml_string(p.xml)
    d = mujoco.MjData(m)
    mujoco.mj_kinematics(m, d)
    m0 = mujoco.MjModel.from_xml_path(str(model))
    d0 = mujoco.MjData(m0)
    d0.qpos[1] = 0.7
    mujoco.mj_kinematics(m0, d0)
    tip, tip0 = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_BODY, "l2"), mujoco.mj_name2id(m0, mujoco.mjtObj.mjOBJ_BODY, "l2")
    assert np.allclose(d.xpos[tip], d0.xpos[tip0], atol=1e-5)
    assert np.allclose(d.xmat[tip], d0.xmat[tip0], atol=1e-5)


def test_timestep_is_the_loop_period_or_an_integer_fraction(tmp_path: Path) -> None:
    half = write(tmp_path, chain_mjcf(extra='<option timestep="0.0005"/>'))
    p = prep(half, timestep="model")
    assert p.info["substeps"] == 2 and p.info["timestep_s"] == 0.0005
    assert mujoco.MjModel.from_xml_string(p.xml).opt.timestep == 0.0005
    odd = write(tmp_path, chain_mjcf(extra='<option timestep="0.0007"/>'), "odd.xml")
    with pytest.raises(ArmError, match="timestep 0.0007 s does not divide the loop period 0.001 s"):
        prep(odd, timestep="model")
    p = prep(odd)
    assert p.info["substeps"] == 1 and p.info["timestep_s"] == 0.001
    assert any("0.0007 s replaced by the loop period" in w for w in p.info["warnings"])


@pytest.mark.parametrize("text,match", [
    ('model = "x.xml"\nspeed = 3\n', "unknown field.*speed"),
    ('model = "x.xml"\ntimestep = "fast"\n', "timestep: expected"),
    ('model = "x.xml"\ntorque_limits = { j0 = -1 }\n', "torque_limits: must be > 0"),
    ('model = "x.xml"\nhome = [0, "a"]\n', r"home\[1\]: expected a number"),
    ('joints = ["j0"]\n', "model: missing"),
    ('model = "x.xml"\nbuses = 3\n', "buses: expected"),
    ('model = "x.xml"\n[locked\n', "not TOML"),
])
def test_arm_file_errors_name_the_field(tmp_path: Path, text: str, match: str) -> None:
    f = write(tmp_path, text, "arm.toml")
    with pytest.raises(ArmError, match=match):
        load_arm_file(f)


def test_arm_file_names_joints_torque_limits_and_wiring(tmp_path: Path) -> None:
    model = write(tmp_path, chain_mjcf())
    f = write(tmp_path, 'model = "arm.xml"\nname = "My Arm"\njoints = ["j0", "j1", "j2"]\n'
                        'torque_limits = { j2 = 7.5 }\n'
                        '[[buses]]\nname = "can0"\nkind = "fd"\nnominal = 1000000\ndata = 5000000\ndrives = [1, 2, 3]\n',
              "arm.toml")
    af = load_arm_file(f)
    assert af.model == model.resolve()
    p = prepare(af, DESIGN)
    assert p.info["name"] == "my-arm"
    assert [j["torque_limit"] for j in p.info["joints"]] == [50, 50, 7.5]
    assert p.info["joints"][2]["torque_limit_from"] == "arm file"
    assert p.info["buses"] == [{"name": "can0", "kind": "fd", "nominal": 1000000, "data": 5000000, "drives": [1, 2, 3]}]
    assert "n_joints = 3" in p.design_text
    bad = write(tmp_path, 'model = "arm.xml"\n[[buses]]\nname = "can0"\nkind = "classic"\nnominal = 250000\n'
                          'drives = [1, 2, 3]\n', "bad.toml")
    with pytest.raises(ArmError, match="bus wiring"):
        prepare(load_arm_file(bad), DESIGN)


def test_cli_writes_the_four_files_and_a_depfile(tmp_path: Path) -> None:
    out = tmp_path / "out"
    dep = tmp_path / "arm.d"
    assert gen_arm.main(["--model", str(UR5E), "--out", str(out), "--depfile", str(dep)]) == 0
    # the four files, and the key of what they were prepared from (gen/arm/cli.py inputs_key)
    assert sorted(x.name for x in out.iterdir()) == [".inputs.sha256", "arm.json", "arm.xml", "design.toml", "plant.xml"]
    info = json.loads((out / "arm.json").read_text())
    assert info["model_hash"] == f"{gen_arm.fnv1a64((out / 'arm.xml').read_bytes()):016x}"
    assert str(UR5E.resolve()) in dep.read_text() and str(DESIGN.resolve()) in dep.read_text()
    assert math.isfinite(info["written_inverse_dynamics_error"])


def test_contacts_are_off_unless_the_arm_file_keeps_them() -> None:
    bundled = REPO / "host_sim" / "models" / "ur5e_arm.xml"
    m = mujoco.MjModel.from_xml_string(prep(bundled).xml)
    assert m.ngeom == 0 and m.opt.disableflags & mujoco.mjtDisableBit.mjDSBL_CONTACT
    p = prep(bundled, contacts=True)
    m = mujoco.MjModel.from_xml_string(p.xml)
    assert m.ngeom > 0 and not m.opt.disableflags & mujoco.mjtDisableBit.mjDSBL_CONTACT
    assert "contacts" in p.info["nominal_model"] and p.info["contacts"] is True
    with pytest.raises(ArmError, match="contacts = true needs the collision meshes"):
        prep(UR5E, contacts=True)


# ---- what MuJoCo compiles, the importer takes ---------------------------------------------------
DRESSED = ('<asset><texture name="grid" type="2d" builtin="checker" rgb1="0.1 0.2 0.3" rgb2="0.2 0.3 0.4" '
           'width="32" height="32"/><material name="reference_site" rgba="1 0 0 1"/>'
           '<material name="grid" texture="grid"/></asset>'
           '<deformable><skin name="cover" material="grid" vertex="0 0 0 0.02 0 0 0 0.02 0" face="0 1 2">'
           '<bone body="l2" bindpos="0 0 0" bindquat="1 0 0 0" vertid="0 1 2" vertweight="1 1 1"/></skin></deformable>')
DRESSED_BODY = ('<site name="wristsite" material="reference_site" size="0.01"/>'
                '<geom name="badge" type="box" size="0.01 0.01 0.01" material="grid" mass="0"/>')


def test_materials_textures_and_skins_go_with_everything_that_uses_them(tmp_path: Path) -> None:
    """A Kinova-Jaco-like model: a site, a geom and a skin use materials, a material a texture.
    MuJoCo compiles it, so the importer must: it drops the materials with the references to them
    (the site stays, without its material), and keeps them with contacts = true."""
    model = write(tmp_path, chain_mjcf(body_extra=DRESSED_BODY, extra=DRESSED))
    mujoco.MjModel.from_xml_path(str(model))  # a valid model
    m = mujoco.MjModel.from_xml_string(prep(model).xml)
    assert m.nmat == m.ntex == m.nskin == m.ngeom == 0
    site = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_SITE, "wristsite")
    assert site >= 0 and m.site_matid[site] == -1
    kept = mujoco.MjModel.from_xml_string(prep(model, contacts=True).xml)
    assert kept.nmat == 2 and kept.site_matid[mujoco.mj_name2id(kept, mujoco.mjtObj.mjOBJ_SITE, "wristsite")] >= 0


def test_a_public_arm_with_materials_textures_and_sites_is_prepared(tmp_path: Path) -> None:
    """robosuite's UR5e dressed like other vendors' MJCF (arm_models.materials_variant): its mesh
    and texture files are not here, so meshes and textures go, with the materials' references to
    the textures; then the materials go with the sites' and the skin's references."""
    model = materials_variant(tmp_path / "ur5e_materials.xml")
    p = prep(model)
    m = mujoco.MjModel.from_xml_string(p.xml)
    assert p.info["n_joints"] == 6 and m.nmat == m.ntex == m.nskin == m.ngeom == 0
    assert {mujoco.mj_id2name(m, mujoco.mjtObj.mjOBJ_SITE, i) for i in range(m.nsite)} >= {"wristsite", "basesite"}
    assert any("mesh files not found" in w for w in p.info["warnings"])
    same = prep(UR5E)  # the dressing changes nothing the controller uses
    assert [j["torque_limit"] for j in p.info["joints"]] == [j["torque_limit"] for j in same.info["joints"]]
    assert gen_arm.inverse_dynamics_difference(m, mujoco.MjModel.from_xml_string(same.xml)) < 1e-9


def test_build_folder_is_named_after_the_arm_not_its_file(tmp_path: Path) -> None:
    """docs/arm.md: build/arms/<name>-<digest>, the name being the one in the arm's reports."""
    from tools.build.arm import ArmRef, arm_build_dir

    model = materials_variant(tmp_path / "vendor_file_name.xml")  # <mujoco model="ur5e">
    assert prep(model).info["name"] == "ur5e"
    bdir = arm_build_dir("release", ArmRef(model=model))
    assert bdir.parent.name.startswith("ur5e-") and bdir.parent.parent.name == "arms"
    f = write(tmp_path, f'model = "{model}"\nname = "Left Arm"\n', "cell.toml")
    assert ArmRef(arm_file=f).key().startswith("left-arm-")
    assert ArmRef(arm_file=f).key() != ArmRef(model=model).key()


def test_a_massless_link_says_what_carries_its_joints_inertia(tmp_path: Path) -> None:
    """A 1e-9 kg tip link moved only by its rotor's armature (the Jaco's joint 6), and a 1e-9 kg
    link in the middle whose joint moves the links beyond it."""
    tip = write(tmp_path, chain_mjcf(tip_mass=1e-9, joint_attrs=["", "", 'armature="0.5"']))
    w = [x for x in prep(tip).info["warnings"] if "weighs" in x]
    assert len(w) == 1 and "'j2'" in w[0] and "(its rotor armature of 0.5 kg m^2 carries the inertia; no link beyond it)" in w[0]
    middle = write(tmp_path, chain_mjcf().replace('mass="1.0" diaginertia="0.01 0.01 0.01"/><body name="l2"',
                                                  'mass="1e-9" diaginertia="1e-11 1e-11 1e-11"/><body name="l2"'),
                   "middle.xml")
    w = [x for x in prep(middle).info["warnings"] if "weighs" in x]
    assert len(w) == 1 and "'j1'" in w[0] and "(1 kg of links beyond it carries the inertia)" in w[0]


def test_a_joint_without_a_torque_limit_gets_one_sized_from_the_arm_with_a_warning(tmp_path: Path) -> None:
    """dm_control's Jaco carries no actuator: each limit is assumed, 1 / REF_TORQUE_FRACTION times what
    the joint needs to hold the arm anywhere in its ranges while accelerating at REF_MAX_ACCELERATION
    and to follow the default reference, and the warning says so and how to give the drives' own."""
    model = write(tmp_path, chain_mjcf(actuators=False))
    p = prep(model)
    limits = [j["torque_limit"] for j in p.info["joints"]]
    assert all(j["torque_limit_from"] == "assumed: no limit in the model" for j in p.info["joints"])
    # j1 (axis y) holds two 1 kg links 0.1 and 0.3 m out when laid flat (3.9 N m) and accelerates them,
    # M11 = 0.01 + 0.1^2 + 0.01 + 0.3^2 = 0.12 kg m^2, at 20 rad/s^2 (2.4 N m): 6.3 N m, times 2
    assert limits[1] == pytest.approx(2 * (9.81 * 0.4 + 0.12 * gen_arm.REF_MAX_ACCELERATION), rel=0.05)
    # j0 (the vertical axis): gravity never loads it, and still it moves the links beyond it
    assert 0 < limits[0] < limits[1]
    assert limits[0] >= 2 * 0.12 * gen_arm.REF_MAX_ACCELERATION * 0.5
    w = [x for x in p.info["warnings"] if x.startswith("torque limits assumed")]
    assert len(w) == 1 and "j0" in w[0] and "torque_limits" in w[0]
    assert max(p.info["reference"]["peak_torque_fraction"]) <= 0.5 + 1e-6


def test_a_folder_prepared_from_the_same_inputs_is_not_prepared_again(tmp_path: Path, monkeypatch) -> None:
    """The build's gen.arm step finds the preparation the check before the build made (tools/build/arm.py
    seed_prepared): same inputs, nothing prepared; another model, prepared again."""
    from gen.arm import preparation as stage  # the CLI imports prepare() from it when it needs it

    model = write(tmp_path, chain_mjcf())
    out = tmp_path / "out"
    assert gen_arm.main(["--model", str(model), "--out", str(out)]) == 0
    calls = []
    monkeypatch.setattr(stage, "prepare", lambda *a: calls.append(a) or prepare(*a))
    assert gen_arm.main(["--model", str(model), "--out", str(out)]) == 0 and calls == []
    model.write_text(chain_mjcf(n=4))
    assert gen_arm.main(["--model", str(model), "--out", str(out)]) == 0 and len(calls) == 1
    assert json.loads((out / "arm.json").read_text())["n_joints"] == 4


# ---- physics the controller must meet as it is -------------------------------------------------
def test_gravity_compensation_is_taken_out_and_said(tmp_path: Path) -> None:
    """dm-robotics' Panda floats: MuJoCo's body gravcomp holds every link up. The prepared arm carries
    its weight on its drives (the controller's model compensates gravity), and the assumed limits
    hold it: the same arm as without gravcomp, with a warning."""
    plain = prep(write(tmp_path, chain_mjcf(actuators=False), "plain.xml"))
    held = prep(write(tmp_path, chain_mjcf(actuators=False).replace("<body name=", '<body gravcomp="1" name='),
                      "held.xml"))
    assert "gravcomp" not in held.xml and not np.any(mujoco.MjModel.from_xml_string(held.xml).body_gravcomp)
    assert [j["torque_limit"] for j in held.info["joints"]] == [j["torque_limit"] for j in plain.info["joints"]]
    w = [x for x in held.info["warnings"] if x.startswith("gravcomp")]
    assert len(w) == 1 and "4 bodies (mount, l0, l1 ..." in w[0]


def test_a_mid_range_home_that_gravity_loads_past_half_a_limit_is_let_down(tmp_path: Path) -> None:
    """Neither the model nor an arm file gives a home, and at mid-range j1 holds the arm out flat with
    4 of its 5 N m: the home moves inside the ranges to where gravity asks at most half of every
    limit. A home the user gave stays where it is."""
    text = chain_mjcf().replace('ctrlrange="-50 50"', 'ctrlrange="-5 5"').replace(
        '<joint name="j1" axis="0 1 0" range="-2 2"', '<joint name="j1" axis="0 1 0" range="0 3.1"')
    p = prep(write(tmp_path, text))
    home = [j["home"] for j in p.info["joints"]]
    assert home[1] != pytest.approx(1.55) and 0.05 <= home[1] <= 3.05, home
    assert max(abs(x) for x in holding(p.xml, home)[:2]) <= 0.5 * 5
    assert p.info["home_from"].startswith("mid-range moved")
    w = [x for x in p.info["warnings"] if "more than the 50%" in x]
    assert len(w) == 1 and "j1's torque limit" in w[0] and "home = [...]" in w[0]
    given = prep(write(tmp_path, text, "given.xml"), home=[0.0, 1.55, 0.0])
    assert [j["home"] for j in given.info["joints"]] == [0.0, 1.55, 0.0]


def holding(xml: str, q: list[float]) -> np.ndarray:
    from gen.arm.limits import holding_torque

    return holding_torque(mujoco.MjModel.from_xml_string(xml), np.asarray(q))


def test_a_light_last_link_gets_a_motor_sized_for_it(tmp_path: Path) -> None:
    """SO-100's gripper: a 35 N m limit on a 2e-5 kg m^2 link. One step of a CiA 402 drive rated at the
    limit (1 per mille: 0.035 N m) would change its speed by 1.6 rad/s in a period (the run cycles
    between steps up to the safety layer's stop). The importer sizes the emulated drive's motor as an
    integrator would: rated so that a step changes the speed by a quarter rad/s, and its max torque
    0x6072 (per-mille of that rating, above 1000) gives the joint's limit, in CiA 402 units: per-mille
    of the motor's rated torque, times the gear. A joint the limit's motor serves keeps it."""
    from gen import drives

    text = chain_mjcf(tip_mass=2e-3).replace('<motor joint="j2" ctrlrange="-50 50"/>',
                                             '<motor joint="j2" ctrlrange="-35 35"/>')
    p = prep(write(tmp_path, text))
    assert p.info["limitations"] == []
    j0, j1, j2 = p.info["joints"]
    assert "motor_rated_torque_at_joint_nm" not in j0 and "motor_rated_torque_at_joint_nm" not in j1
    w = [x for x in p.info["warnings"] if x.startswith("joint 'j2': a motor rated at its 35 N m limit is too coarse")]
    assert len(w) == 1 and "0x6072" in w[0]
    cfg = drives.load(p.info)
    d0, d2 = cfg.drives[0], cfg.drives[2]
    assert d0.max_torque_permille == 1000 and "max=" not in d0.node_spec(sim=True)
    assert d0.joint_rated_torque_nm == pytest.approx(j0["torque_limit"], rel=1e-2)
    # the sized motor: a step well under the limit's thousandth, and its 0x6072 still gives the limit
    step = d2.joint_rated_torque_nm / 1000
    assert step < 0.035 / 4 and d2.joint_rated_torque_nm == pytest.approx(d2.rated_torque_mnm / 1000 * 101)
    assert 1000 < d2.max_torque_permille <= 32767 and "0x6072" in d2.given
    assert d2.max_torque_permille * step >= 35.0 > (d2.max_torque_permille - 1) * step
    assert f"max={d2.max_torque_permille}" in d2.node_spec(sim=True) and "max=" not in d2.node_spec()
    assert prep(write(tmp_path, chain_mjcf(), "heavy.xml")).info["limitations"] == []


def test_a_link_no_motor_can_serve_is_named_in_the_limitations(tmp_path: Path) -> None:
    """A link so light that even a motor whose 0x6072 is an INTEGER16's 32767 per-mille steps too
    coarsely for it: named, with what to change, and its drive stays rated at the limit."""
    text = chain_mjcf(tip_mass=2e-3).replace('<motor joint="j2" ctrlrange="-50 50"/>',
                                             '<motor joint="j2" ctrlrange="-5000 5000"/>')
    p = prep(write(tmp_path, text))
    [lim] = p.info["limitations"]
    assert lim["joint"] == "j2" and lim["kind"] == "torque-step"
    assert "32767" in lim["text"] and "rated_torque_nm" in lim["text"] and lim["text"] in p.info["warnings"]
    assert "motor_rated_torque_at_joint_nm" not in p.info["joints"][2]


def test_a_build_that_finds_its_arm_prepared_does_not_load_mujoco(tmp_path: Path) -> None:
    """The build's gen.arm step on a folder the check before the build prepared (every first build of
    an arm: tools/build/arm.py seed_prepared) reads the key, not MuJoCo and the importer: it sits
    before the synthesis on the first build's critical path."""
    import subprocess
    import sys

    model = write(tmp_path, chain_mjcf())
    out = tmp_path / "out"
    assert gen_arm.main(["--model", str(model), "--out", str(out)]) == 0
    probe = ("import sys; from gen.arm.cli import main; rc = main(['--model', sys.argv[1], '--out', sys.argv[2]]); "
             "print(rc, sorted(m for m in ('mujoco', 'numpy', 'gen.arm.preparation') if m in sys.modules))")
    r = subprocess.run([sys.executable, "-c", probe, str(model), str(out)], cwd=REPO, capture_output=True, text=True,
                       env={**__import__("os").environ, "PYTHONPATH": str(REPO)}, timeout=120)
    assert r.stdout.strip() == "0 []", (r.stdout, r.stderr)
