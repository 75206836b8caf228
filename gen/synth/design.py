"""One independent sub-problem (a set of joints): controller C, then estimator K.

The controller goes first because the estimator's back-off is judged on the combined loop, which
contains C. C's own back-off is judged on the controller loop alone.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass
from typing import Any, TypeVar

import numpy as np

from gen.synth.backoff import LadderResult, Rung, margin_checks, walk_ladder
from gen.synth.config import DesignConfig
from gen.synth.discretize import double_integrator_zoh
from gen.synth.gh2 import Degeneracy, detect_degenerate, gh2_synthesis
from gen.synth.hinf import hinf_synthesis
from gen.synth.lmi import LmiSolution, SynthesisError
from gen.synth.loops import design_loop
from gen.synth.plants import GeneralizedPlant, controller_plant, double_integrator, estimator_plant
from gen.synth.recover import Recovered, recover_and_reduce
from gen.synth.ss import StateSpace, static_gain
from gen.synth.verify import gh2_norm, hinf_norm, sweep_peak

_Chosen = TypeVar("_Chosen")

NORM_RTOL = 1e-6  # the verified norm may exceed the LMI gamma by solver round-off only


class DesignRefused(SynthesisError):
    """No design on the ladder is stable with margin at the loop rate; nothing is emitted."""


@dataclass(eq=False)
class Synthesised:
    """A designed system (K or C) with everything the manifest records about how it was made."""

    kind: str  # "estimator" | "controller"
    plant: GeneralizedPlant
    gamma_opt: float
    gamma_opt_status: str
    gamma_design: float
    rule: str
    system: StateSpace  # continuous, after residualisation
    full_order_poles: list[complex]
    residualised_poles: list[complex]
    i_minus_xy_singular_values: list[float]
    rungs: list[Rung]
    verification: dict[str, Any]
    degeneracy: Degeneracy | None = None


@dataclass(eq=False)
class ComponentDesign:
    joints: tuple[int, ...]
    rows: tuple[int, ...]
    controller: Synthesised
    estimator: Synthesised


def _plants(m: int, T: float) -> tuple[StateSpace, StateSpace]:
    A, B = double_integrator(m)
    return StateSpace(A, B, np.eye(2 * m), np.zeros((2 * m, m))), double_integrator_zoh(m, T)


def _quiet(fn: Any, *args: Any) -> Any:
    # cvxpy warns on 'optimal_inaccurate'; we record the status instead of printing it.
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UserWarning)
        return fn(*args)


def _rule_text(kind: str, res: LadderResult[Any], rate: int, delay: int) -> str:
    assert res.rung is not None
    below = [f"{r.relative:g} ({r.reason})" for r in res.rungs if not r.accepted]
    text = (
        f"gamma_design = gamma_opt * (1 + {res.rung.relative:g}): the smallest rung of design.backoff_ladder whose "
        f"{kind} loops are stable when sampled at {rate} Hz (ZOH) and stay stable with {delay} extra period(s) "
        "of actuation delay"
    )
    return text + (f"; rejected below it: {'; '.join(below)}" if below else "")


def _accepted(kind: str, res: LadderResult[_Chosen], cfg: DesignConfig) -> _Chosen:
    """What the ladder's accepted rung made; no accepted rung refuses the design, naming the last reason."""
    if res.chosen is None:
        raise DesignRefused(
            f"{kind}: no rung of design.backoff_ladder is stable with margin at {cfg.loop_rate_hz} Hz "
            f"(last: {res.rungs[-1].reason}); extend the ladder or raise the loop rate"
        )
    return res.chosen


def _backed_off(
    kind: str,
    plant: GeneralizedPlant,
    opt: LmiSolution,
    res: LadderResult[Any],
    loops: str,
    cfg: DesignConfig,
    rec: Recovered,
    verification: dict[str, Any],
    degeneracy: Degeneracy | None = None,
) -> Synthesised:
    """The record of a full-order LMI design backed off to the ladder's accepted rung; `loops` names the
    loops its rung was judged on, `verification` the verified norms (the rung's gamma is added to it)."""
    assert res.rung is not None
    return Synthesised(
        kind=kind,
        plant=plant,
        gamma_opt=opt.gamma,
        gamma_opt_status=opt.status,
        gamma_design=res.rung.gamma,
        rule=_rule_text(loops, res, cfg.loop_rate_hz, cfg.delay_margin_samples),
        system=rec.reduced,
        full_order_poles=[complex(p) for p in np.linalg.eigvals(rec.full.A)],
        residualised_poles=rec.residualised_poles,
        i_minus_xy_singular_values=rec.i_minus_xy_singular_values,
        rungs=res.rungs,
        verification={**verification, "lmi_gamma": res.rung.gamma, "within_bound": True},
        degeneracy=degeneracy,
    )


def _controller(Po: GeneralizedPlant, cfg: DesignConfig, m: int) -> Synthesised:
    T, delay = cfg.period_s, cfg.delay_margin_samples
    pc, pd = _plants(m, T)
    synth = gh2_synthesis(Po)
    deg = detect_degenerate(Po)
    opt: LmiSolution | None
    try:
        opt, opt_note = _quiet(synth.min_gamma), ""
    except SynthesisError as exc:
        if not deg.degenerate:
            raise
        # gamma* = 0 is already established structurally; the LMI only corroborates it.
        opt, opt_note = None, f"solver failed ({exc}); gamma* = 0 from the structural test"
    if deg.degenerate:
        assert deg.zeroing_gain is not None
        C = static_gain(deg.zeroing_gain)
        ok, reason, checks = margin_checks(pc, pd, C, None, T, delay)
        if not ok:
            raise DesignRefused(
                f"controller: the degenerate case's zeroing gain is not stable with margin at {cfg.loop_rate_hz} Hz "
                f"({reason}); lower E1/E2 relative to D12 or raise the loop rate"
            )
        norm = gh2_norm(design_loop(Po, C))
        return Synthesised(
            kind="controller",
            plant=Po,
            gamma_opt=opt.gamma if opt is not None else 0.0,
            gamma_opt_status=opt.status if opt is not None else opt_note,
            gamma_design=0.0,
            rule=(
                "degenerate generalized-H2 problem (gamma* = 0): emit the static zeroing gain u_o = -D12^+ C1 y, "
                "which attains gamma = 0 with closed-loop poles at the plant's invariant zeros, instead of a "
                "backed-off full-order LMI controller (whose poles are unbounded as gamma -> 0); "
                f"its loop is stable at {cfg.loop_rate_hz} Hz with {delay} period(s) of delay"
            ),
            system=C,
            full_order_poles=[],
            residualised_poles=[],
            i_minus_xy_singular_values=[],
            rungs=[Rung(0.0, 0.0, True, reason, checks)],
            verification={"gh2_norm": norm, "lmi_gamma": 0.0, "within_bound": bool(norm <= 1e-9)},
            degeneracy=deg,
        )

    def attempt(rel: float, gamma: float) -> tuple[tuple[Recovered, float] | None, Rung]:
        sol = _quiet(synth.at_gamma, gamma)
        if sol is None:
            return None, Rung(rel, gamma, False, "LMIs infeasible at this gamma")
        rec = recover_and_reduce(Po, sol, cfg.residualise_above / T)
        norm = gh2_norm(design_loop(Po, rec.reduced))
        if not np.isfinite(norm):
            return None, Rung(rel, gamma, False, "recovered controller does not stabilise P_o (LMI point inaccurate this close to gamma_opt)")
        if not norm <= gamma * (1 + NORM_RTOL):
            return None, Rung(rel, gamma, False, f"verified generalized-H2 norm {norm:.6g} exceeds gamma")
        ok, reason, checks = margin_checks(pc, pd, rec.reduced, None, T, delay)
        checks["gh2_norm"] = norm
        return ((rec, norm) if ok else None), Rung(rel, gamma, ok, reason, checks)

    assert opt is not None  # only the degenerate case tolerates a failed min-gamma solve
    res = walk_ladder(opt.gamma, cfg.backoff_ladder, attempt)
    rec, norm = _accepted("controller", res, cfg)
    return _backed_off("controller", Po, opt, res, "controller", cfg, rec, {"gh2_norm": norm}, deg)


def _estimator(Pf: GeneralizedPlant, C: StateSpace, cfg: DesignConfig, m: int) -> Synthesised:
    T, delay = cfg.period_s, cfg.delay_margin_samples
    pc, pd = _plants(m, T)
    synth = hinf_synthesis(Pf)
    opt: LmiSolution = _quiet(synth.min_gamma)

    def attempt(rel: float, gamma: float) -> tuple[tuple[Recovered, float, float, float] | None, Rung]:
        sol = _quiet(synth.at_gamma, gamma)
        if sol is None:
            return None, Rung(rel, gamma, False, "LMIs infeasible at this gamma")
        rec = recover_and_reduce(Pf, sol, cfg.residualise_above / T)
        loop = design_loop(Pf, rec.reduced)
        norm, w_peak = hinf_norm(loop)
        if not np.isfinite(norm):
            return None, Rung(rel, gamma, False, "recovered estimator does not stabilise P_f (LMI point inaccurate this close to gamma_opt)")
        if not norm <= gamma * (1 + NORM_RTOL):
            return None, Rung(rel, gamma, False, f"verified H-infinity norm {norm:.6g} exceeds gamma", {"hinf_norm": norm})
        ok, reason, checks = margin_checks(pc, pd, C, rec.reduced, T, delay)
        checks["hinf_norm"] = norm
        return ((rec, norm, w_peak, sweep_peak(loop)[0]) if ok else None), Rung(rel, gamma, ok, reason, checks)

    res = walk_ladder(opt.gamma, cfg.backoff_ladder, attempt)
    rec, norm, w_peak, sweep = _accepted("estimator", res, cfg)
    verification = {
        "hinf_norm": norm,
        "hinf_peak_rad_s": w_peak if np.isfinite(w_peak) else None,
        "hinf_sweep_lower_bound": sweep,
    }
    return _backed_off("estimator", Pf, opt, res, "combined (decoupled and paper)", cfg, rec, verification)


def subproblem_plants(cfg: DesignConfig, joints: tuple[int, ...], rows: tuple[int, ...]) -> tuple[GeneralizedPlant, GeneralizedPlant]:
    J, R = list(joints), list(rows)
    Pf = estimator_plant([cfg.F[j] for j in J], cfg.H[np.ix_(J, J)])
    Po = controller_plant(cfg.E1[np.ix_(R, J)], cfg.E2[np.ix_(R, J)], cfg.D12[np.ix_(R, J)])
    return Pf, Po


def design_component(cfg: DesignConfig, joints: tuple[int, ...], rows: tuple[int, ...]) -> ComponentDesign:
    Pf, Po = subproblem_plants(cfg, joints, rows)
    ctl = _controller(Po, cfg, len(joints))
    est = _estimator(Pf, ctl.system, cfg, len(joints))
    return ComponentDesign(joints, rows, ctl, est)
