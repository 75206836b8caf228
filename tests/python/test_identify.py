"""armctl identify against hidden plants (docs/identify.md): `armctl plant --truth FILE` (a process of
its own; the truth file the controller and identify never read), `armctl commission`, then `armctl
identify` (commissioned bare, then with the payload mounted), over UDP in lockstep, for three plants
drawn per seed: each joint's viscous and Coulomb
friction above the model's, its rotor inertia above the model's armature, and a payload of 0 to the
arm's rated 5 kg at the flange.

- each joint's friction (viscous and Coulomb) within 15 % of the truth, its rotor inertia within
  10 %, the payload's mass within 10 % (or 0.1 kg); each 95 % interval contains the truth;
- the arm file written is one the product takes: it prepares (gen.arm) into the identified values;
- bad input: an excitation the limits cannot hold is one line naming the joint, exit 2, before a
  controller starts; nothing written. (A joint that did not move is named by check_moved, tested
  below on telemetry made up for it: the plant cannot hold an enabled joint still, its friction is
  MuJoCo's soft frictionloss, which a 10 kN m value turns into a damper the joint still moves
  against.)

Fast, no plant (unmarked, at the end): the excitation's limit checks, the fit on synthetic torques,
a poor fit named, a joint that did not move named.
Cost on the 2-core machine: about 1 minute of wall time (three plants, each commissioned bare and
identified with its payload, about 15 s a plant in lockstep; the fast tests a few seconds)."""

from __future__ import annotations

import json
import math
import random
from pathlib import Path

import numpy as np
import pytest

from hil_procs import armctl
from test_run_on_arm import Plant  # `armctl plant` in the background, ended by Ctrl-C
from gen.lib.paths import REPO

SEEDS = (11, 12, 13)
RATED_PAYLOAD_KG = 5.0
NOMINAL = {  # the bundled arm's model (host_sim/models/ur5e_arm.xml): armature, damping, frictionloss
    "armature": [1.73, 1.73, 1.73, 0.1, 0.1, 0.1],
    "damping": [3.6, 4.6, 4.0, 0.89, 0.76, 0.8],
    "frictionloss": [7.0, 7.8, 6.3, 1.7, 1.5, 1.6],
}
NAMES = ["shoulder_pan", "shoulder_lift", "elbow", "wrist_1", "wrist_2", "wrist_3"]
FRICTION_TOL = 0.15
INERTIA_TOL = 0.10
PAYLOAD_TOL, PAYLOAD_ABS_KG = 0.10, 0.1


def draw(seed: int) -> dict:
    """The plant's truth for a seed: what the model lacks, per joint, and the payload."""
    rng = random.Random(seed)
    joints = {}
    for j, name in enumerate(NAMES):
        joints[name] = {"viscous": round(rng.uniform(0.1, 0.6) * NOMINAL["damping"][j], 4),
                        "coulomb": round(rng.uniform(0.1, 0.4) * NOMINAL["frictionloss"][j], 4),
                        "rotor_inertia": round(rng.uniform(0.1, 0.4) * NOMINAL["armature"][j], 4)}
    # the draws span 0 to the rated payload: none, a third to two thirds of it, two thirds to all of it
    k = SEEDS.index(seed)
    payload = 0.0 if k == 0 else round(rng.uniform(k / 3, (k + 1) / 3) * RATED_PAYLOAD_KG, 3)
    return {"payload_kg": payload, "joint": joints}


def truth_toml(t: dict) -> str:
    lines = [f"payload_kg = {t['payload_kg']!r}"]
    for name, v in t["joint"].items():
        lines.append(f"[joint.{name}]")
        lines += [f"{k} = {x!r}" for k, x in v.items()]
    return "\n".join(lines) + "\n"


@pytest.fixture(scope="module")
def port() -> int:
    from tools.run.slots import acquire_slot

    with acquire_slot(quiet_ports=True) as s:
        yield s.can_port


@pytest.fixture(scope="module")
def identified(port: int, tmp_path_factory: pytest.TempPathFactory) -> dict:
    """Per seed: the truth, identify's exit and output, its results and the arm file's path."""
    out: dict = {}
    for seed in SEEDS:
        d = tmp_path_factory.mktemp(f"seed{seed}")
        truth = draw(seed)
        (d / "truth.toml").write_text(truth_toml(truth))
        (d / "bare.toml").write_text(truth_toml({**truth, "payload_kg": 0.0}))
        common = ["--bus", f"udp:{port}", "--record", str(d / "record.json")]
        # commissioned bare, as docs/identify.md says (a heavy payload the model lacks stops it), then
        # the payload mounted: the plant again, with it
        plant = Plant(port, d / "bare", d / "bare.toml")
        try:
            cm = armctl("commission", *common, "--out", str(d / "commission"))
        finally:
            plant.stop()
        plant = Plant(port, d / "plant", d / "truth.toml")
        try:
            r = armctl("identify", *common, "--run-dir", str(d / "run"), "--out", str(d / "identified.toml"))
        finally:
            plant.stop()
        res = json.loads((d / "run" / "identification.json").read_text()) if (d / "run" / "identification.json").exists() else None
        out[seed] = {"truth": truth, "commission": cm, "identify": r, "result": res, "dir": d}
    keep = REPO / "runs" / "test_identify"  # the figures, for the record (pytest's folders go)
    keep.mkdir(parents=True, exist_ok=True)
    (keep / "figures.json").write_text(json.dumps(
        {seed: {"truth": e["truth"], "identify_exit": e["identify"].returncode,
                "figures": figures(e) if e["result"] else None} for seed, e in out.items()}, indent=1))
    return out


def figures(entry: dict) -> list[tuple[str, float, dict]]:
    """(what, the truth, the estimate with its interval) for every identified value."""
    fit = entry["result"]["fit"]
    t = entry["truth"]
    rows = []
    for j, name in enumerate(NAMES):
        e = fit["joints"][name]
        rows.append((f"{name} rotor inertia", NOMINAL["armature"][j] + t["joint"][name]["rotor_inertia"],
                     e["rotor_inertia"]))
        rows.append((f"{name} viscous", NOMINAL["damping"][j] + t["joint"][name]["viscous"], e["viscous"]))
        rows.append((f"{name} coulomb", NOMINAL["frictionloss"][j] + t["joint"][name]["coulomb"], e["coulomb"]))
    rows.append(("payload kg", t["payload_kg"], fit["payload_kg"]))
    return rows


@pytest.mark.long
@pytest.mark.parametrize("seed", SEEDS)
def test_identify_finds_the_hidden_plant(seed: int, identified: dict) -> None:
    e = identified[seed]
    r = e["identify"]
    assert r.returncode == 0, r.stdout + r.stderr
    assert "armctl identify: wrote" in r.stdout
    bad = []
    for what, truth, est in figures(e):
        v = est["value"]
        if what.startswith("payload"):
            tol = max(PAYLOAD_TOL * truth, PAYLOAD_ABS_KG)
        else:
            tol = (INERTIA_TOL if "inertia" in what else FRICTION_TOL) * truth
        if abs(v - truth) > tol:
            bad.append(f"{what}: {v:.4g}, the truth {truth:.4g} (bound {tol:.3g})")
        if not est["lo"] <= truth <= est["hi"]:
            bad.append(f"{what}: the interval [{est['lo']:.4g}, {est['hi']:.4g}] misses the truth {truth:.4g}")
    assert not bad, "\n".join(bad)


@pytest.mark.long
def test_the_identified_arm_file_prepares_into_what_was_measured(identified: dict) -> None:
    """The arm file written for the plant with the heaviest payload goes through the product's own
    importer (gen/arm/preparation.py: what armctl build, tune, study and run do with --arm first): its
    joints carry the identified values and its last link the payload."""
    import mujoco

    from gen.arm.arm_file import load_arm_file
    from gen.arm.preparation import prepare

    seed = max(SEEDS, key=lambda s: identified[s]["truth"]["payload_kg"])
    e = identified[seed]
    fit = e["result"]["fit"]
    p = prepare(load_arm_file(e["dir"] / "identified.toml"))
    assert p.info["warnings"] == [] and p.info["payload"]["rated_kg"] == RATED_PAYLOAD_KG
    for j, name in enumerate(NAMES):
        got = p.info["joints"][j]
        want = fit["joints"][name]
        assert got["name"] == name
        assert got["armature"] == pytest.approx(want["rotor_inertia"]["value"], rel=1e-5)
        assert got["damping"] == pytest.approx(want["viscous"]["value"], rel=1e-5)
        assert got["frictionloss"] == pytest.approx(want["coulomb"]["value"], rel=1e-5)
    m = mujoco.MjModel.from_xml_string(p.xml)
    last = m.jnt_bodyid[mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_JOINT, NAMES[-1])]
    assert m.body_subtreemass[last] == pytest.approx(0.365 + fit["payload_kg"]["value"], rel=1e-4)


@pytest.mark.long
def test_an_excitation_the_limits_cannot_hold_is_refused_before_anything_starts(port: int, tmp_path: Path) -> None:
    r = armctl("identify", "--bus", f"udp:{port}", "--amplitude", "2.5", "--run-dir", str(tmp_path / "run"),
               "--out", str(tmp_path / "arm.toml"))
    assert r.returncode == 2, r.stdout + r.stderr
    last = r.stderr.strip().splitlines()[-1]
    assert last.startswith("armctl identify: the excitation: joint ") and "--amplitude" in last, last
    assert not (tmp_path / "arm.toml").exists() and not (tmp_path / "run" / "controller.log").exists()


# ----------------------------------------------------------------------------- fast: no plant

def _prepared_xml() -> Path:
    from gen.lib.paths import build_dir

    for preset in ("release", "debug"):
        p = build_dir(preset) / "generated" / "arm" / "arm.xml"
        if p.exists():
            return p
    raise AssertionError("no build's generated/arm/arm.xml: tools/armctl build first")


def test_excitation_starts_at_rest_and_its_limit_checks_name_the_joint() -> None:
    from tools.identify import excitation as ex

    joints = [{"name": n, "range": [-math.pi, math.pi]} for n in ("a", "b")]
    q0 = np.array([0.0, 0.5])
    a, b = ex.shape(np.random.default_rng(0), 2, 5)
    e = ex.scaled(q0, a, b, 10.0, 2, np.array([0.5, 0.5]))
    q, qd, qdd = e.eval(np.array([0.0, 10.0, 20.0]))
    assert np.allclose(q, q0) and np.allclose(qd, 0, atol=1e-12) and np.allclose(qdd, 0, atol=1e-12)
    peaks = ex.check(e, joints, math.pi, 20.0)
    assert max(abs(x - c) for x, c in zip(peaks["q_max"] + peaks["q_min"], [0, 0.5, 0, 0.5])) <= 0.5 + 1e-9
    with pytest.raises(ex.ExcitationError, match=r"^joint 2 \(b\): the excitation spans"):
        ex.check(ex.scaled(q0, a, b, 10.0, 2, np.array([0.5, 6.0])), joints, 100.0, 100.0)
    with pytest.raises(ex.ExcitationError, match=r"^joint 1 \(a\): the excitation's speed"):
        ex.check(ex.scaled(q0, a, b, 10.0, 2, np.array([0.5, 0.5])), joints, 0.1, 20.0)
    with pytest.raises(ex.ExcitationError, match=r"acceleration reaches .* a longer --period"):
        ex.check(ex.scaled(q0, a, b, 2.0, 2, np.array([0.5, 0.5])), joints, 100.0, 2.0)


def _synthetic(theta: np.ndarray, extra: float = 0.0) -> tuple:
    from tools.identify import excitation as ex
    from tools.identify.fit import ArmRegressor

    reg = ArmRegressor(_prepared_xml())
    q0 = np.array([0.0, -1.3, 1.6, -1.87, -1.5708, 0.0])
    e, _ = ex.design(q0, np.full(6, 0.5), 10.0, 1, 5, 3, reg.condition)
    t = np.arange(0.0, e.duration_s, 0.002)
    q, qd, qdd = e.eval(t)
    known, cols = reg.rows(q, qd, qdd)
    tau = known + np.einsum("tjp,p->tj", cols, theta) + extra * np.sin(7 * t)[:, None] * 20
    return reg, t, q, tau


THETA = np.concatenate([[1.9, 2.0, 1.8, 0.13, 0.12, 0.11], [4.0, 5.0, 4.5, 1.0, 0.9, 1.0],
                        [8.0, 9.0, 7.0, 2.0, 1.8, 1.9], [3.0, 0.0, 0.0, 0.01]])


def test_fit_recovers_synthetic_torques() -> None:
    from tools.identify.fit import fit, prepare

    reg, t, q, tau = _synthetic(THETA)
    f = fit(reg, *prepare(t, q, tau), NAMES)
    est = [e.value for e in f.rotor_inertia + f.viscous + f.coulomb] + [f.payload_kg.value]
    assert np.allclose(est, THETA[:19], rtol=0.02), est
    assert not f.poor


def test_a_torque_the_model_cannot_explain_is_a_poor_fit() -> None:
    from tools.identify.fit import fit, prepare

    reg, t, q, tau = _synthetic(THETA, extra=1.0)
    f = fit(reg, *prepare(t, q, tau), NAMES)
    assert f.poor and "unexplained" in f.poor[0], f.poor


def test_a_joint_that_did_not_move_is_named() -> None:
    from tools.commands import CommandError
    from tools.commands.identify import check_moved

    peaks = {"q_min": [-0.5, -0.4], "q_max": [0.5, 0.4]}
    t = np.linspace(0, 10, 1000)
    moving = 0.5 * np.sin(t)
    check_moved(np.c_[moving, 0.8 * moving], peaks, ["a", "b"])
    with pytest.raises(CommandError, match=r"^joint 2 \(b\) moved 0.0\d* rad of the excitation's 0.8 rad"):
        check_moved(np.c_[moving, 0.01 * moving], peaks, ["a", "b"])
