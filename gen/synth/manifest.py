"""The manifest: everything about a design in one JSON document, with a content hash.

The hash is SHA-256 over the canonical JSON (sorted keys, no whitespace, shortest round-trip
floats) of the whole manifest except `content_hash` itself and `run` (wall times and file paths,
which differ between runs of the same design). The headers carry its first 16 hex characters so
a firmware build can check that headers and manifest belong together.
"""

from __future__ import annotations

import hashlib
import json
import math
from typing import TYPE_CHECKING, Any

import numpy as np

if TYPE_CHECKING:  # names in annotations only: whoever just reads a design file does not import cvxpy (1.3 s)
    from gen.synth.design import Synthesised
    from gen.synth.pipeline import Design, Emitted
    from gen.synth.ss import StateSpace

SCHEMA = "armctl-synth-manifest/1"
UNHASHED = ("content_hash", "run")
FLOAT_HEADER = "pm_design_float.h"
FIXED_HEADER = "pm_design_fixed.h"
DESIGN_FILE = "pm_design.txt"  # the headers' numbers as text, for a firmware that loads its design (--design-file)


def clean(obj: Any) -> Any:
    """JSON-safe: numpy -> Python, complex -> [re, im], inf/nan -> None."""
    if isinstance(obj, dict):
        return {str(k): clean(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [clean(v) for v in obj]
    if isinstance(obj, np.ndarray):
        return clean(obj.tolist())
    if isinstance(obj, (complex, np.complexfloating)):
        return [clean(float(obj.real)), clean(float(obj.imag))]
    if isinstance(obj, (bool, np.bool_)):
        return bool(obj)
    if isinstance(obj, (int, np.integer)):
        return int(obj)
    if isinstance(obj, (float, np.floating)):
        return float(obj) if math.isfinite(float(obj)) else None
    return obj


def canonical(obj: Any) -> bytes:
    return json.dumps(obj, sort_keys=True, separators=(",", ":"), allow_nan=False).encode()


def content_hash(manifest: dict[str, Any]) -> str:
    body = {k: v for k, v in manifest.items() if k not in UNHASHED}
    return hashlib.sha256(canonical(body)).hexdigest()


def _ss(s: StateSpace) -> dict[str, Any]:
    return {"A": s.A, "B": s.B, "C": s.C, "D": s.D, "n_states": s.n_states}


def _subproblem(joints: tuple[int, ...], users: list[tuple[int, ...]], s: Synthesised) -> dict[str, Any]:
    out: dict[str, Any] = {
        "joints": list(joints),
        "used_for_joint_sets": [list(u) for u in users],
        "gamma_opt": s.gamma_opt,
        "gamma_opt_solver_status": s.gamma_opt_status,
        "gamma_design": s.gamma_design,
        "backoff": {"rule": s.rule, "ladder": [r.to_json() for r in s.rungs]},
        "plant": s.plant.to_json(),
        "full_order_poles": s.full_order_poles,
        "residualised_poles": s.residualised_poles,
        "i_minus_xy_singular_values": s.i_minus_xy_singular_values,
        "continuous": _ss(s.system),
        "verification": s.verification,
    }
    if s.degeneracy is not None:
        out["degenerate"] = s.degeneracy.degenerate
        out["degenerate_reason"] = s.degeneracy.reason
        out["invariant_zeros"] = s.degeneracy.invariant_zeros
    return out


def _emitted(e: Emitted) -> dict[str, Any]:
    return {
        "continuous": _ss(e.continuous),
        "discrete": _ss(e.discrete),
        "state_scaling": e.state_scaling,
        "padded_states": e.padded_states,
    }


def _system(
    theorem: str,
    signals: str,
    gamma: dict[str, float],
    subproblems: list[dict[str, Any]],
    emitted: Emitted,
    **between: Any,
) -> dict[str, Any]:
    """The manifest's entry for the estimator or the controller (`between` goes after the gammas,
    where readers of earlier manifests find the controller's `degenerate`)."""
    return {
        "theorem": theorem,
        "signals": signals,
        "gamma_opt": gamma["gamma_opt"],
        "gamma_design": gamma["gamma_design"],
        **between,
        "subproblems": subproblems,
        **_emitted(emitted),
    }


def build(d: Design, run: dict[str, Any]) -> dict[str, Any]:
    cfg = d.cfg
    g = d.gamma
    users: dict[str, list[tuple[int, ...]]] = {}
    for c, k in zip(d.comps, d.comp_keys):
        users.setdefault(k, []).append(c.joints)
    est_subs = [_subproblem(cd.joints, users[k], cd.estimator) for k, cd in d.solved.items()]
    ctl_subs = [_subproblem(cd.joints, users[k], cd.controller) for k, cd in d.solved.items()]
    degenerate = any(cd.controller.degeneracy is not None and cd.controller.degeneracy.degenerate for cd in d.solved.values())
    io = (
        "inputs y = [e_j, e_dot_j] of one joint, output of that joint (apply to every joint)"
        if d.per_joint
        else f"inputs y = [e_1..e_{cfg.n_joints}, e_dot_1..e_dot_{cfg.n_joints}], one output per joint"
    )
    m: dict[str, Any] = {
        "schema": SCHEMA,
        "generator": "gen.synth",
        "method": "Kim & Kim, AIMS Mathematics 2024: H-infinity estimator (Theorem 1) and generalized-H2 controller (Theorem 3)",
        "inputs": cfg.to_json(),
        "structure": {
            "mode": d.mode,
            "per_joint": d.per_joint,
            "n_joints": cfg.n_joints,
            "emitted_joints": d.m,
            "components": [
                {"joints": list(c.joints), "z_o_rows": list(c.rows), "subproblem": list(d.solved).index(k)}
                for c, k in zip(d.comps, d.comp_keys)
            ],
            "n_subproblems_solved": len(d.solved),
        },
        "loop_rate_hz": cfg.loop_rate_hz,
        "loop_period_s": cfg.period_s,
        "estimator": _system(
            "Theorem 1, LMIs (3.14) ((3.16) if F is biproper), plant P_f (3.10)",
            io + "; output w_hat",
            g["estimator"],
            est_subs,
            d.estimator,
        ),
        "controller": _system(
            "Theorem 3, LMIs (3.22), plant P_o (3.18)",
            io + "; output u_o",
            g["controller"],
            ctl_subs,
            d.controller,
            degenerate=degenerate,
        ),
        "internal_model": {
            "description": "one joint's double integrator e_ddot = u_o, state [e, e_dot]; the decoupled structure feeds K with y - x_m",
            **_emitted(d.internal_model),
        },
        "verification": d.verification,
        "fixed_point": {
            "Y_FRAC": d.y_frac,
            "declared_ranges": {"e_max": cfg.e_max, "e_dot_max": cfg.e_dot_max},
            "internal_model_state_max": [2 * cfg.e_max, 2 * cfg.e_dot_max],
            "arithmetic": (
                "int32 signals and coefficients; products accumulated in int64 at binary point "
                "A_FRAC+X_FRAC (= B_FRAC+Y_FRAC) for the state update and C_FRAC+X_FRAC (= D_FRAC+Y_FRAC) "
                "for the output; one rounding arithmetic right shift by ACC_X_SHIFT / ACC_U_SHIFT, "
                "then saturation to int32; inputs saturated to the declared ranges"
            ),
            "estimator": d.estimator.fixed.to_json(),
            "controller": d.controller.fixed.to_json(),
            "internal_model": d.internal_model.fixed.to_json(),
        },
        "headers": {"float": FLOAT_HEADER, "fixed": FIXED_HEADER},
        "run": run,
    }
    m = clean(m)
    m["content_hash"] = content_hash(m)
    return m
