"""armctl identify: measure your arm through the same path as armctl run (docs/identify.md).

It writes a Fourier-series excitation within the joints' limits (checked before anything is
enabled: range, speed, acceleration, and armctl run's own torque check), has the controller follow
it on the arm's buses as `armctl run FILE.csv` does, reads the run's telemetry (q, tau) and fits,
per joint, the rotor inertia, the viscous and the Coulomb friction, and the payload's mass and
centre of mass at the flange, each with its confidence interval (Pinocchio's regressor, SciPy's
least squares: tools/identify/fit.py). It writes an arm file of the arm as measured (--out), which
armctl tune, study and run take; a poor fit is not written. The resonance is not identified (the
arm file keeps the drive train's)."""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path
from typing import Any

from gen.lib.params import param
from gen.lib.paths import REPO
from tools.build.arm import add_arm_arguments
from tools.commands import CommandError, UsageError
from tools.run.arm_session import add_session_arguments
from tools.run.run_files import TELEMETRY_LOG

MOVED_FRACTION = 0.5  # of the excitation's span: a joint that moved less did not follow it


def add_subparser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("identify", help="measure your arm (friction, rotor inertia, payload) through the controller "
                                        "on its buses and write its arm file (docs/identify.md)",
                       description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--out", type=Path, required=True, metavar="FILE.toml",
                   help="the identified arm file (its model beside it: FILE.xml)")
    for name in ("period", "periods", "harmonics", "amplitude", "seed"):
        q = param("identify", name)
        p.add_argument(f"--{name}", type=int if q.type == "int" else float, default=q.default, metavar=q.arg,
                       help=f"{q.help} [{q.default}]")
    add_session_arguments(p)
    p.add_argument("--run-dir", type=Path, default=REPO / "runs" / "identify", metavar="DIR",
                   help="the excitation, the controller's log and telemetry, identification.json [runs/identify]")
    add_arm_arguments(p)
    p.set_defaults(run=run)


def check_moved(q: object, peaks: dict, names: list[str]) -> None:
    """CommandError naming the first joint that covered less than MOVED_FRACTION of the excitation's
    span: the arm did not follow it, and there is nothing to identify from."""
    import numpy as np

    qa = np.asarray(q)
    span = qa.max(axis=0) - qa.min(axis=0)
    want = np.array(peaks["q_max"]) - np.array(peaks["q_min"])
    for j, name in enumerate(names):
        if span[j] < MOVED_FRACTION * want[j]:
            raise CommandError(f"joint {j + 1} ({name}) moved {span[j]:.3g} rad of the excitation's {want[j]:.3g} "
                               "rad: the arm did not follow it (a brake, a drive not enabled, a gear or unit wrong): "
                               "check it with tools/armctl commission; nothing written", 1)


def _check_options(ns: argparse.Namespace) -> None:
    for name in ("period", "periods", "harmonics", "amplitude", "seed"):
        try:
            param("identify", name).check(getattr(ns, name), f"--{name}")
        except ValueError as exc:
            raise UsageError(str(exc)) from None
    if ns.out.suffix != ".toml":
        raise UsageError(f"--out {ns.out}: an arm file's name ends in .toml")


def samples(telemetry: Path, n: int) -> tuple:
    """The controller's periods while it ran (state running): t, q, tau, from its telemetry log."""
    import numpy as np

    from tools.run.telemetry_log import read_log

    ctl = read_log(telemetry, ("ARM_CTL",))["ARM_CTL"].messages
    if len(ctl) == 0:
        raise CommandError(f"{telemetry}: no controller telemetry (ARM_CTL): nothing to identify from")
    ctl = ctl[np.argsort(ctl["step"], kind="stable")]
    ctl = ctl[ctl["state"] == 1]
    _, first = np.unique(ctl["step"], return_index=True)
    ctl = ctl[first]
    if len(ctl) < 100 or np.any(np.diff(ctl["step"]) != 1):
        gaps = int(np.sum(np.diff(ctl["step"]) - 1)) if len(ctl) > 1 else 0
        raise CommandError(f"{telemetry}: {len(ctl)} running periods with {gaps} missing: the telemetry does not cover "
                           "the run (a lost LCM message): run armctl identify again")
    return (ctl["t"].astype(float), np.asarray(ctl["q"], float)[:, :n], np.asarray(ctl["tau"], float)[:, :n])


MEASURED_FINDINGS = ("gravity torque at the start pose", "it accelerates")  # commission's (tools/run/commissioning.py)


def record_allows(path: Path, setup: object) -> str:
    """armctl run's commissioning record, with one difference: a record whose only findings are a
    gravity torque or an inertia off the model's (a payload, a rotor the model lacks: what
    identification measures) lets identify run, when every joint was tested and turned its way.
    A reversed, stuck or runaway joint is never let through. Returns a note ('' when it passed)."""
    from tools.run.arm_session import table_digest
    from tools.run.commissioning import RecordError, check_record

    try:
        check_record(path, setup.info, setup.table, table_digest(setup.table))  # type: ignore[attr-defined]
        return ""
    except RecordError as exc:
        try:
            rec = json.loads(path.read_text())
        except (OSError, ValueError):
            raise CommandError(str(exc), 1) from None
        if (not isinstance(rec, dict) or rec.get("model_hash") != setup.info["model_hash"]  # type: ignore[attr-defined]
                or rec.get("drive_table_sha256") != table_digest(setup.table)):  # type: ignore[attr-defined]
            raise CommandError(str(exc), 1) from None
        joints = rec.get("joints") or []
        turned = len(joints) == len(setup.info["joints"]) and all(  # type: ignore[attr-defined]
            j.get("tested") and j.get("direction") == "ok" for j in joints)
        findings = [f for f in rec.get("findings") or [] if isinstance(f, str)]
        if not turned or not findings or not all(any(m in f for m in MEASURED_FINDINGS) for f in findings):
            raise CommandError(str(exc), 1) from None
        return (f"commissioning found the arm off its model in {len(findings)} way(s) this identification measures "
                f"(gravity, inertia: a payload or rotor the model lacks), every joint turning its way; first: "
                f"{findings[0]}")


IDENTIFICATION_FILE = "identification.json"


def _excitation(ns: argparse.Namespace, info: dict[str, Any], reg: Any) -> tuple[Any, float, dict[str, Any]]:
    """The excitation about home (its condition of the regressor), checked against the reference's limits."""
    import numpy as np

    from gen.arm.reference import REF_MAX_ACCELERATION, REF_MAX_VELOCITY
    from tools.identify import excitation as exc_mod

    q0 = np.array([j["home"] for j in info["joints"]], float)
    amplitude = np.full(len(info["joints"]), ns.amplitude)
    try:
        ex, cond = exc_mod.design(q0, amplitude, ns.period, ns.periods, ns.harmonics, ns.seed, reg.condition)
        peaks = exc_mod.check(ex, info["joints"], REF_MAX_VELOCITY, REF_MAX_ACCELERATION)
    except exc_mod.ExcitationError as exc:
        raise UsageError(f"the excitation: {exc}") from None
    return ex, cond, peaks


def _run_excitation(ns: argparse.Namespace, setup: Any, ex: Any, cond: float) -> Path:
    """The excitation run on the arm (armctl run's own checks and session): the run folder."""
    from tools.run.arm_task import describe, finish, task_args
    from tools.identify import excitation as exc_mod
    from tools.run.arm_session import run_controller

    run_dir = ns.run_dir
    run_dir.mkdir(parents=True, exist_ok=True)
    (run_dir / IDENTIFICATION_FILE).unlink(missing_ok=True)
    csv = run_dir / "excitation.csv"
    exc_mod.write_csv(ex, setup.joint_names, csv)
    ns.trajectory, ns.hold, ns.jog, ns.stream, ns.duration = csv, False, None, None, None
    ctl, task = task_args(ns, setup, run_dir)  # armctl run's own check (range, speed, acceleration, torque)
    mode = ns.mode or ("lockstep" if setup.rehearsal else "realtime")
    describe(setup, mode, f"identification: {task}; {ns.periods} period(s) of {ns.period:g} s, {ns.harmonics} "
             f"harmonics, amplitude {ns.amplitude:g} rad about home (regressor condition {cond:.3g})",
             "armctl identify")
    res = run_controller(setup, ["--method", "pm", *ctl], run_dir, mode)
    finish(res, setup, task, "armctl identify")
    return run_dir


def _print_fit(f: Any, names: list[str]) -> None:
    from tools.identify.fit import CONFIDENCE

    pct = int(round(100 * CONFIDENCE))
    print(f"{'joint':<16}{'rotor inertia kg m^2':>26}{'viscous N m s/rad':>24}{'Coulomb N m':>22}{'residual':>10}")
    for j, name in enumerate(names):
        def iv(e: object) -> str:
            return f"{e.value:.4g} [{e.lo:.3g}, {e.hi:.3g}]"  # type: ignore[attr-defined]
        print(f"{name:<16}{iv(f.rotor_inertia[j]):>26}{iv(f.viscous[j]):>24}{iv(f.coulomb[j]):>22}"
              f"{100 * f.residual_fraction[j]:>9.1f}%")
    m = f.payload_kg
    print(f"payload: {m.value:.3g} kg [{m.lo:.3g}, {m.hi:.3g}]" + (
        ", centre of mass off the flange " + ", ".join(f"{1000 * e.value:.0f} mm" for e in f.payload_com)
        if m.lo > 0 else " (none found: its interval reaches 0)") + f"; intervals {pct} %")


def _identification(ns: argparse.Namespace, info: dict[str, Any], f: Any, cond: float,
                    peaks: dict[str, Any]) -> dict[str, Any]:
    """identification.json: the fit beside the model's values, and the excitation that measured it."""
    return {"arm": info["name"], "model_hash": info["model_hash"], "fit": f.as_dict(),
            "model": {"armature": [j.get("armature", 0.0) for j in info["joints"]],
                      "damping": [j.get("damping", 0.0) for j in info["joints"]],
                      "frictionloss": [j.get("frictionloss", 0.0) for j in info["joints"]]},
            "excitation": {"period_s": ns.period, "periods": ns.periods, "harmonics": ns.harmonics,
                           "amplitude_rad": ns.amplitude, "seed": ns.seed, "condition": cond, **peaks},
            "written": None}


def run(ns: argparse.Namespace) -> int:
    from gen.lib.atomic_output import write_json_atomic
    from tools.build.arm import prepared_model
    from tools.identify.arm_out import write as write_arm
    from tools.identify.fit import ArmRegressor, FitError, fit, prepare
    from tools.run.arm_session import arm_on_bus
    from tools.run.commissioning import default_record

    _check_options(ns)
    setup = arm_on_bus(ns, "armctl identify")
    info = setup.info
    names = setup.joint_names
    model_xml = prepared_model(setup.bdir)
    site = "payload"
    try:
        reg = ArmRegressor(model_xml, site)
    except FitError as exc:
        raise UsageError(str(exc)) from None
    ex, cond, peaks = _excitation(ns, info, reg)
    note = record_allows(ns.record or default_record(info), setup)
    if note:
        print(f"armctl identify: {note}")
    run_dir = _run_excitation(ns, setup, ex, cond)
    t, q, tau = samples(run_dir / TELEMETRY_LOG, len(names))
    check_moved(q, peaks, names)
    print(f"armctl identify: fitting {len(t)} periods of telemetry (Pinocchio's regressor, least squares)")
    sys.stdout.flush()
    try:
        f = fit(reg, *prepare(t, q, tau), names)
    except FitError as exc:
        raise CommandError(f"{exc}; nothing written", 1) from None
    result = _identification(ns, info, f, cond, peaks)
    _print_fit(f, names)
    if f.poor:
        write_json_atomic(run_dir / IDENTIFICATION_FILE, result)
        raise CommandError(f"a poor fit, not written: {f.poor[0]}: run it again with a larger --amplitude or more "
                           f"--periods, or check that joint's drive (details {run_dir / IDENTIFICATION_FILE})", 1)
    header = [f"armctl identify: {info['name']} as measured through its drives ({ns.periods} x {ns.period:g} s of "
              f"excitation, seed {ns.seed}); {run_dir / IDENTIFICATION_FILE} has each value's interval",
              "the links are the model's; each joint's armature, damping and frictionloss, and the payload, identified"]
    model_out = write_arm(ns.out, model_xml, info, setup.table.path, f, header, site)
    result["written"] = {"arm_file": str(ns.out), "model": str(model_out)}
    write_json_atomic(run_dir / IDENTIFICATION_FILE, result)
    print(f"armctl identify: wrote {ns.out} (model {model_out}); results {run_dir / IDENTIFICATION_FILE}")
    return 0
