"""armctl commission's judgement: each joint's measurements (the controller's, arm/commission.h)
against the arm's nominal model, and the record that armctl run asks for.

Per joint, from the controller's summary:
- direction: its torque pulses moved it their way (a reversed motor or encoder moves it the other);
- gravity: the mean of the torques that drove it across its start pose going up and going down
  (friction and damping change sign with the motion and cancel) against the model's gravity
  torque there; off by more than GRAVITY_TOLERANCE of it (or GRAVITY_FLOOR of the joint's limit):
  a zero offset (the angle that would explain it is given) or a payload the model lacks;
- scale: its acceleration under each pulse, with the measured gravity and friction taken out,
  gives its inertia; against the model's (rigid bodies and armature, M_jj at the start pose) off by
  more than SCALE_TOLERANCE either way: a gear or torque unit wrong (a gear wrong by g scales it by
  g^2, a torque unit by its factor), or the model's inertia.

The record ties the verdict to the arm (its model's hash) and to the drive table's content (the
table and its EDS/DCF, sha256): armctl run refuses an arm that did not pass, or whose table
changed since (check_record)."""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, field
from datetime import datetime, timezone
from pathlib import Path
from typing import Any

GRAVITY_TOLERANCE = 0.10   # of the model's gravity torque at the start pose
GRAVITY_FLOOR = 0.02       # of the joint's torque limit: below it, noise and the torque's resolution
SCALE_TOLERANCE = 1.5      # measured over model inertia outside [1/1.5, 1.5]: named
PULSE_FRACTION = 0.05      # of the joint's limit: the smallest pulse
PULSE_FRICTION = 4.0       # times the model's friction: a pulse that surely moves it, even at half its torque
PULSE_MAX_FRACTION = 0.25  # of the joint's limit: the largest
DEG = 180.0 / math.pi


class RecordError(ValueError):
    """armctl run: the arm has no commissioning record that lets it run (the message says why)."""


def pulses(info: dict[str, Any]) -> list[float]:
    """Each joint's pulse, N m: above its friction (the model's), a few % of its limit."""
    out = []
    for j in info["joints"]:
        lim = j["torque_limit"]
        out.append(round(min(max(PULSE_FRACTION * lim, PULSE_FRICTION * j.get("frictionloss", 0.0)),
                             PULSE_MAX_FRACTION * lim), 6))
    return out


@dataclass
class JointVerdict:
    name: str
    tested: bool
    direction: str = "not tested"
    gravity_nm: float | None = None
    gravity_model_nm: float | None = None
    offset_deg_if_zero: float | None = None  # the zero offset that would explain the gravity error
    friction_nm: float | None = None
    inertia: float | None = None
    inertia_model: float | None = None
    findings: list[str] = field(default_factory=list)


def judge(summary: dict[str, Any], info: dict[str, Any]) -> list[JointVerdict]:
    """Every joint's verdict from the controller's summary of a --task commission run: its
    measurements, and its own model's gravity, gravity slope and inertia at them."""
    cm = summary["task"]["commission"]
    model = cm["model"]
    joints = info["joints"]
    names = [j["name"] for j in joints]
    n = len(joints)
    out = []
    status, why_joint = cm["status"], cm["why_joint"]
    for j, (spec, rec) in enumerate(zip(joints, cm["joints"])):
        v = JointVerdict(names[j], bool(rec["tested"]))
        lim = spec["torque_limit"]
        pos, neg, sweep = rec["pulse_pos"], rec["pulse_neg"], rec["sweep"]
        inertia_model = model["inertia"][j]
        if status != "done" and why_joint == j:
            moved = abs(cm["why_value"]) * DEG
            if status == "reversed":
                v.direction = "reversed"
                v.findings.append(f"{names[j]} moved {moved:.2g} deg against a {pos['delta_nm']:+.3g} N m pulse: its "
                                  "motor or its encoder is reversed (the drive's polarity, or its wiring)")
            elif status == "stuck":
                v.direction = "did not move"
                t = cm["config"]["pulse_max_s"]
                net = max(abs(pos["delta_nm"]) - spec.get("frictionloss", 0.0), 0.0)
                expect = 0.5 * net / inertia_model * t * t * DEG
                v.findings.append(f"{names[j]} moved {moved:.2g} deg under a {pos['delta_nm']:+.3g} N m pulse in "
                                  f"{t:g} s, where the model moves it {expect:.2g} deg: a gear or torque unit wrong "
                                  "(the drive table's gear, rated torque, torque_unit), friction above the pulse, a "
                                  "brake that did not open, or no torque reaching it (the drive's enable, its max "
                                  "torque 0x6072)")
            else:
                tested = cm["joint_under_test"]
                v.findings.append(f"{names[j]} left its start pose by {moved:.2g} deg (the bound is "
                                  f"{cm['config']['bound_rad'] * DEG:.2g} deg) during the {cm['step']} of "
                                  f"{names[tested] if 0 <= tested < n else 'the first hold'}: a reversed motor or "
                                  "encoder runs away from the hold; or its gravity is far from the model's")
        if not v.tested:
            out.append(v)
            continue
        v.direction = "ok" if pos["moved"] > 0 > neg["moved"] else "reversed"
        if v.direction != "ok":
            v.findings.append(f"{names[j]} moved {pos['moved'] * DEG:+.2g} and {neg['moved'] * DEG:+.2g} deg under "
                              f"{pos['delta_nm']:+.3g} and {neg['delta_nm']:+.3g} N m: its motor or encoder is "
                              "reversed")
        if sweep["n_up"] and sweep["n_down"]:
            g_meas = 0.5 * (sweep["tau_up"] + sweep["tau_down"])
            g_model, slope = model["gravity_nm"][j], model["gravity_slope_nm_per_rad"][j]
            damping = spec.get("damping", 0.0)  # the model's, which the commanded torque includes
            v.gravity_nm, v.gravity_model_nm = round(g_meas, 4), round(g_model, 4)
            v.friction_nm = round(0.5 * (sweep["tau_up"] - sweep["tau_down"]) - damping * sweep["speed"], 4)
            err = g_meas - g_model
            if abs(err) > max(GRAVITY_TOLERANCE * abs(g_model), GRAVITY_FLOOR * lim):
                offset = ""
                if abs(slope) > GRAVITY_FLOOR * lim:  # gravity changes with this joint's angle: an offset shows
                    v.offset_deg_if_zero = round(-err / slope * DEG, 2)
                    offset = (f"its encoder's zero off by about {v.offset_deg_if_zero:+.3g} deg (the angle it reads "
                              "minus the true one), or ")
                v.findings.append(f"{names[j]}: gravity torque at the start pose {g_meas:.3g} N m, the model's "
                                  f"{g_model:.3g} N m ({err:+.3g} N m): {offset}a payload or masses the model "
                                  "does not have")
            inertias = []
            for p, sign in ((pos, 1.0), (neg, -1.0)):
                if p["samples"] >= 5 and abs(p["accel"]) > 0:
                    net = p["tau_hold_nm"] + p["delta_nm"] - g_meas - sign * v.friction_nm
                    inertias.append(net / p["accel"])
            if inertias and all(x > 0 for x in inertias):
                v.inertia = round(sum(inertias) / len(inertias), 5)
                v.inertia_model = round(inertia_model, 5)
                r = v.inertia / v.inertia_model
                if not 1 / SCALE_TOLERANCE <= r <= SCALE_TOLERANCE:
                    off = r if r > 1 else 1 / r  # a gear wrong by g: g^2 (positions and torques); a unit: itself
                    v.findings.append(f"{names[j]}: it accelerates {1 / r:.2g} x what the model predicts under a known "
                                      f"torque (inertia {v.inertia:.3g} kg m^2, the model's {v.inertia_model:.3g}): a "
                                      f"gear or torque unit wrong by about {math.sqrt(off):.2g} x (gear) or "
                                      f"{off:.2g} x (torque unit): check its gear, encoder_increments, rated torque "
                                      "and torque_unit in the drive table")
        out.append(v)
    return out


def write_record(path: Path, *, passed: bool, info: dict[str, Any], table: Any, digest: str,
                 verdicts: list[JointVerdict], findings: list[str], bus: str, summary_path: Path) -> dict[str, Any]:
    from gen.lib.atomic_output import write_json_atomic
    from tools.run.hil import provenance

    rec = {"passed": passed, "arm": info["name"], "model_hash": info["model_hash"],
           "drive_table": str(table.path), "drive_file": str(table.eds), "drive_table_sha256": digest,
           "date_utc": datetime.now(timezone.utc).isoformat(timespec="seconds"), "bus": bus,
           "findings": findings, "joints": [asdict(v) for v in verdicts], "controller_summary": str(summary_path),
           "provenance": provenance()}
    path.parent.mkdir(parents=True, exist_ok=True)
    write_json_atomic(path, rec)
    return rec


def check_record(path: Path, info: dict[str, Any], table: Any, digest: str) -> dict[str, Any]:
    """The record that lets the arm run, or RecordError saying what is missing or wrong."""
    import json

    try:
        rec = json.loads(path.read_text())
    except FileNotFoundError:
        raise RecordError(f"the arm has not been commissioned (no record at {path}): run tools/armctl commission "
                          "with the same --bus and drive table first") from None
    except (OSError, ValueError) as exc:
        raise RecordError(f"{path}: not a commissioning record ({exc}): run tools/armctl commission again") from None
    if not isinstance(rec, dict) or rec.get("model_hash") != info["model_hash"]:
        theirs = rec.get("model_hash") if isinstance(rec, dict) else "?"
        raise RecordError(f"{path}: made for another arm (model hash {theirs}, this one {info['model_hash']}): run "
                          "tools/armctl commission again")
    if rec.get("drive_table_sha256") != digest:
        raise RecordError(f"the drive table changed since the arm was commissioned ({table.path} or "
                          f"{Path(table.eds).name}, {rec.get('date_utc')}): run tools/armctl commission again")
    if rec.get("passed") is not True:
        first = (rec.get("findings") or ["no finding recorded"])[0]
        raise RecordError(f"the arm did not pass commissioning ({rec.get('date_utc')}: {first}): fix it and run "
                          "tools/armctl commission again")
    return rec


def default_record(info: dict[str, Any]) -> Path:
    from gen.lib.paths import REPO

    return REPO / "runs" / "commission" / f"{info['name']}-{info['model_hash'][:8]}.json"
