"""config -> designs per sub-problem -> assembled, verified, discretised, quantised Design."""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from gen.synth.backoff import RHO_TOL
from gen.synth.config import DesignConfig
from gen.synth.design import ComponentDesign, DesignRefused, design_component, subproblem_plants
from gen.synth.discretize import double_integrator_zoh, zoh
from gen.synth.lmi import SynthesisError
from gen.synth.fixedpoint import FixedSystem, equalise_states, frac_for, quantise
from gen.synth.loops import STRUCTURES, combined_loop, design_loop
from gen.synth.plants import GeneralizedPlant, double_integrator
from gen.synth.ss import StateSpace, block_diag_ss
from gen.synth.structure import Component, components, subproblem_key
from gen.synth.verify import gh2_norm, hinf_norm, max_real_part, spectral_radius, sweep_peak


@dataclass(eq=False)
class Emitted:
    """One system as the headers carry it."""

    continuous: StateSpace  # residualised, states rescaled like the discrete one (0 states if static)
    discrete: StateSpace  # ZOH at the loop period, padded to >= 1 state
    state_scaling: list[float]
    padded_states: int
    fixed: FixedSystem


@dataclass(eq=False)
class Design:
    cfg: DesignConfig
    mode: str  # "per_joint" | "block_diagonal" | "coupled"
    per_joint: bool
    m: int  # joints the emitted matrices cover (1 when per joint, else n)
    comps: list[Component]
    solved: dict[str, ComponentDesign]  # sub-problem key -> design
    comp_keys: list[str]
    estimator: Emitted
    controller: Emitted
    internal_model: Emitted
    y_frac: int
    verification: dict[str, Any]
    timings: dict[str, float] = field(default_factory=dict)

    @property
    def gamma(self) -> dict[str, dict[str, float]]:
        """The arm's gammas: the maximum over independent sub-problems (block-diagonal loops)."""
        ds = list(self.solved.values())
        return {
            "estimator": {
                "gamma_opt": max(d.estimator.gamma_opt for d in ds),
                "gamma_design": max(d.estimator.gamma_design for d in ds),
            },
            "controller": {
                "gamma_opt": max(d.controller.gamma_opt for d in ds),
                "gamma_design": max(d.controller.gamma_design for d in ds),
            },
        }


def _assemble(parts: list[tuple[StateSpace, tuple[int, ...]]], n: int) -> StateSpace:
    """Block-diagonal n-joint system with inputs [e; e_dot] (2n) and one output per joint."""
    bd = block_diag_ss([p for p, _ in parts])
    in_idx: list[int] = []
    out_idx: list[int] = []
    for _, J in parts:
        in_idx += list(J) + [n + j for j in J]
        out_idx += list(J)
    B = np.zeros((bd.n_states, 2 * n))
    B[:, in_idx] = bd.B
    C = np.zeros((n, bd.n_states))
    C[out_idx, :] = bd.C
    D = np.zeros((n, 2 * n))
    D[np.ix_(out_idx, in_idx)] = bd.D
    return StateSpace(bd.A, B, C, D)


def _pad(sys: StateSpace) -> tuple[StateSpace, int]:
    """C forbids zero-size arrays: give a static gain one inert state (A = 0, B = 0, C = 0)."""
    if sys.n_states:
        return sys, 0
    return StateSpace(np.zeros((1, 1)), np.zeros((1, sys.n_in)), np.zeros((sys.n_out, 1)), sys.D), 1


def _emit_system(name: str, cont: StateSpace, T: float, in_max: np.ndarray, y_frac: int) -> Emitted:
    disc = zoh(cont, T)
    disc_eq, scale = equalise_states(disc, in_max)
    cont_eq = cont.similarity(np.diag(scale)) if cont.n_states else cont
    padded, npad = _pad(disc_eq)
    return Emitted(cont_eq, padded, scale.tolist(), npad, quantise(name, padded, in_max, y_frac))


def _poles(A: np.ndarray) -> list[complex]:
    ev = np.linalg.eigvals(A) if A.size else np.zeros(0)
    return sorted((complex(p) for p in ev), key=lambda p: (p.real, p.imag))


def _dequantised(f: FixedSystem) -> StateSpace:
    return StateSpace(f.A_Q / 2.0**f.a_frac, f.B_Q / 2.0**f.b_frac, f.C_Q / 2.0**f.c_frac, f.D_Q / 2.0**f.d_frac)


def _f32(s: StateSpace) -> StateSpace:
    c = lambda M: M.astype(np.float32).astype(np.float64)  # noqa: E731
    return StateSpace(c(s.A), c(s.B), c(s.C), c(s.D))


def _verify(d: Design, Pf: GeneralizedPlant, Po: GeneralizedPlant, T: float, delay: int) -> dict[str, Any]:
    """Independent checks of exactly what is emitted (continuous, sampled, float32 and fixed-point)."""
    m = d.m
    K, C = d.estimator.continuous, d.controller.continuous
    est_loop = design_loop(Pf, K)
    nrm, w_pk = hinf_norm(est_loop)
    g = d.gamma
    ctl_norm = gh2_norm(design_loop(Po, C))
    A, B = double_integrator(m)
    plant_c = StateSpace(A, B, np.eye(2 * m), np.zeros((2 * m, m)))
    plant_d = double_integrator_zoh(m, T)
    im_q = _dequantised(d.internal_model.fixed)
    # The internal model is emitted per joint; [e; e_dot] ordering makes the m-joint one a kron.
    plant_dq = StateSpace(np.kron(im_q.A, np.eye(m)), np.kron(im_q.B, np.eye(m)), plant_d.C, plant_d.D)
    out: dict[str, Any] = {
        "estimator_loop": {
            "hinf_norm": nrm,
            "hinf_peak_rad_s": w_pk if np.isfinite(w_pk) else None,
            "hinf_sweep_lower_bound": sweep_peak(est_loop)[0],
            "gamma_design": g["estimator"]["gamma_design"],
            "within_bound": bool(nrm <= g["estimator"]["gamma_design"] * (1 + 1e-6)),
            "method": "Hamiltonian level-set iteration on the closed loop P_f + K (continuous); log sweep as a lower bound",
        },
        "controller_loop": {
            "gh2_norm": ctl_norm,
            "gamma_design": g["controller"]["gamma_design"],
            "within_bound": bool(ctl_norm <= g["controller"]["gamma_design"] * (1 + 1e-6) + 1e-9),
            "method": "sqrt(lambda_max(C W C^T)), W the controllability Gramian of the closed loop P_o + C",
        },
        "sampled_data": {
            "method": "ZOH double integrator and ZOH-discretised K, C and internal model at the loop period",
            "loop_rate_hz": d.cfg.loop_rate_hz,
            "delay_margin_samples": delay,
            "rho_tol": RHO_TOL,
        },
        "combined_loop": {},
    }
    ok = True
    for st in STRUCTURES:
        cl = combined_loop(plant_c, C, K, st)
        Kd, Cd = d.estimator.discrete, d.controller.discrete
        dl = combined_loop(plant_d, Cd, Kd, st)
        rho = spectral_radius(dl.A)
        rho_d = spectral_radius(combined_loop(plant_d, Cd, Kd, st, delay=delay).A) if delay else rho
        rho_f32 = spectral_radius(combined_loop(plant_d, _f32(Cd), _f32(Kd), st).A)
        rho_fx = spectral_radius(
            combined_loop(plant_dq, _dequantised(d.controller.fixed), _dequantised(d.estimator.fixed), st).A
        )
        cont_poles = _poles(cl.A)
        stable = max_real_part(cl.A) < 0 and max(rho, rho_d, rho_f32, rho_fx) < 1 - RHO_TOL
        ok &= stable
        out["combined_loop"][st] = {
            "continuous_poles": [[p.real, p.imag] for p in cont_poles],
            "continuous_max_real_part": max_real_part(cl.A),
            "w_to_e_hinf_norm": hinf_norm(cl)[0] if max_real_part(cl.A) < 0 else None,
            "sampled_poles": [[p.real, p.imag] for p in _poles(dl.A)],
            "sampled_spectral_radius": rho,
            "sampled_spectral_radius_delayed": rho_d,
            "float32_sampled_spectral_radius": rho_f32,
            "fixed_point_sampled_spectral_radius": rho_fx,
            "stable_with_margin": bool(stable),
        }
    if not ok:
        bad = [s for s in STRUCTURES if not out["combined_loop"][s]["stable_with_margin"]]
        raise DesignRefused(f"the emitted combined loop ({', '.join(bad)}) is not stable with margin at {d.cfg.loop_rate_hz} Hz")
    return out


# Peak memory of a coupled problem beyond the Python process itself, from two measurements: n = 4
# joints 57 MB above the 115 MB baseline (this machine, /usr/bin/time), n = 60 joints 23.7 GB (a
# report that the kernel's OOM killer ended). Between them it grows as n^2.2.
COUPLED_BYTES_N4 = 57e6
COUPLED_EXPONENT = 2.22


def coupled_bytes(joints: int) -> float:
    return COUPLED_BYTES_N4 * (joints / 4.0) ** COUPLED_EXPONENT


def _available_bytes() -> float | None:
    try:
        for line in Path("/proc/meminfo").read_text().splitlines():
            if line.startswith("MemAvailable:"):
                return float(line.split()[1]) * 1024.0
    except OSError:
        pass
    return None


def synthesize(cfg: DesignConfig) -> Design:
    t0 = time.perf_counter()
    comps = components(cfg)
    largest = max(len(c.joints) for c in comps)
    need, have = coupled_bytes(largest), _available_bytes()
    if largest > 1 and have is not None and need > 0.8 * have:
        raise SynthesisError(f"a coupled problem of {largest} joints needs about {need / 1e9:.1f} GB, and "
                             f"{have / 1e9:.1f} GB are available: use structure = \"auto\" (per-joint problems) "
                             "or weights that decouple the joints")
    keys = [subproblem_key(cfg, c) for c in comps]
    solved: dict[str, ComponentDesign] = {}
    for c, k in zip(comps, keys):
        if k not in solved:
            solved[k] = design_component(cfg, c.joints, c.rows)
    t_solve = time.perf_counter() - t0

    n, T = cfg.n_joints, cfg.period_s
    per_joint = len(solved) == 1 and all(len(c.joints) == 1 for c in comps)
    if per_joint:
        mode, m = "per_joint", 1
        only = next(iter(solved.values()))
        K, C = only.estimator.system, only.controller.system
        Pf, Po = only.estimator.plant, only.controller.plant
    else:
        mode = "coupled" if len(comps) == 1 else "block_diagonal"
        m = n
        K = _assemble([(solved[k].estimator.system, c.joints) for c, k in zip(comps, keys)], n)
        C = _assemble([(solved[k].controller.system, c.joints) for c, k in zip(comps, keys)], n)
        all_rows = tuple(r for c in comps for r in c.rows)
        Pf, Po = subproblem_plants(cfg, tuple(range(n)), tuple(sorted(all_rows)))

    y_max = np.concatenate([np.full(m, cfg.e_max), np.full(m, cfg.e_dot_max)])
    # One Q format for every [e; e_dot]-like signal (estimator and controller inputs, internal-model
    # state), with room for 4x the largest range so y - x_m cannot overflow before saturation.
    y_frac = frac_for(float(y_max.max()), headroom=4.0)
    est = _emit_system("EST", K, T, y_max, y_frac)
    ctl = _emit_system("CTL", C, T, y_max, y_frac)
    # The internal model of one joint; its state is |y| + |y - x_m| <= 2 * range (saturated in firmware).
    im_d = double_integrator_zoh(1, T)
    A1, B1 = double_integrator(1)
    u_max = float(np.max(ctl.fixed.u_bound))
    im_fixed = quantise(
        "IM",
        StateSpace(im_d.A, im_d.B, np.eye(2), np.zeros((2, 1))),
        np.array([u_max]),
        ctl.fixed.u_frac,
        x_bound=2.0 * np.array([cfg.e_max, cfg.e_dot_max]),
        x_frac=y_frac,
    )
    im = Emitted(StateSpace(A1, B1, np.eye(2), np.zeros((2, 1))), StateSpace(im_d.A, im_d.B, np.eye(2), np.zeros((2, 1))), [1.0, 1.0], 0, im_fixed)

    d = Design(cfg, mode, per_joint, m, comps, solved, keys, est, ctl, im, y_frac, {})
    t1 = time.perf_counter()
    d.verification = _verify(d, Pf, Po, T, cfg.delay_margin_samples)
    d.timings = {"solve_s": t_solve, "discretise_quantise_s": t1 - t0 - t_solve, "verify_s": time.perf_counter() - t1}
    return d

