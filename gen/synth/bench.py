"""Benchmark (not a test): `python -m gen.synth.bench --out results.json`.

1. Wall time of the whole synth (design + verification + quantisation + manifest/headers) for the
   paper's n = 6 design, per-joint (structure "auto") against the full coupled problem.
2. python-control's hinfsyn (SLICOT sb10ad, Riccati/gamma-iteration) on the same estimator plant.
   On the paper's P_f it cannot run: y has no noise (D21 = 0, and fewer exogenous inputs than
   measurements) and e is not penalised while its pole sits at s = 0 (a jw-axis invariant zero of
   [A - jwI, B2; C1, D12]). Both are Riccati-method assumptions, not LMI ones. So we also solve a
   regularised plant - measurement noise eps * v in y and a penalty eps * [e; e_dot] in z - with
   both methods, for shrinking eps, and compare gamma and time there.
"""

from __future__ import annotations

import argparse
import json
import platform
import shutil
import statistics
import time
import warnings
from pathlib import Path
from typing import Any

import numpy as np

from gen.lib.atomic_output import write_text_atomic
from gen.lib.escape import toml_string
from gen.synth.cli import DEFAULT_CONFIG
from gen.synth.config import DesignConfig, load_config
from gen.synth.hinf import hinf_synthesis
from gen.synth.lmi import SynthesisError
from gen.synth.plants import GeneralizedPlant, estimator_plant


def _time_synth(structure: str, repeats: int, out_dir: Path) -> dict[str, Any]:
    from gen.synth.cli import synth_to_dir

    cfg_path = out_dir / f"bench_{structure}.toml"
    text = DEFAULT_CONFIG.read_text().replace('structure = "auto"', f"structure = {toml_string(structure)}")
    cfg_path.write_text(text)
    times, manifest = [], {}
    for _ in range(repeats):
        t0 = time.perf_counter()
        manifest = synth_to_dir(cfg_path, out_dir / f"out_{structure}")
        times.append(time.perf_counter() - t0)
    return {
        "structure": structure,
        "mode": manifest["structure"]["mode"],
        "repeats": repeats,
        "wall_time_s": times,
        "wall_time_median_s": statistics.median(times),
        "estimator_gamma_opt": manifest["estimator"]["gamma_opt"],
        "estimator_gamma_design": manifest["estimator"]["gamma_design"],
        "estimator_verified_hinf_norm": manifest["verification"]["estimator_loop"]["hinf_norm"],
        "controller_gamma_opt": manifest["controller"]["gamma_opt"],
        "content_hash": manifest["content_hash"][:16],
    }


def regularised(P: GeneralizedPlant, eps: float) -> GeneralizedPlant:
    """z += eps [e; e_dot], y += eps v with v a new exogenous input."""
    ny, m = P.ny, P.ny // 2
    pen = np.hstack([np.eye(2 * m), np.zeros((2 * m, P.nx - 2 * m))])
    return GeneralizedPlant(
        A=P.A,
        B1=np.hstack([P.B1, np.zeros((P.nx, ny))]),
        B2=P.B2,
        C1=np.vstack([P.C1, eps * pen]),
        D11=np.block([[P.D11, np.zeros((P.nz, ny))], [np.zeros((2 * m, P.nw + ny))]]),
        D12=np.vstack([P.D12, np.zeros((2 * m, P.nu))]),
        C2=P.C2,
        D21=np.hstack([np.zeros((ny, P.nw)), eps * np.eye(ny)]),
    )


def _hinfsyn(P: GeneralizedPlant) -> dict[str, Any]:
    import control as ct

    d21 = P.d21
    B = np.hstack([P.B1, P.B2])
    C = np.vstack([P.C1, P.C2])
    D = np.block([[P.D11, P.D12], [d21, np.zeros((P.ny, P.nu))]])
    t0 = time.perf_counter()
    try:
        _, _, gam, _ = ct.hinfsyn(ct.ss(P.A, B, C, D), P.ny, P.nu)
    except Exception as exc:  # slycot raises its own error classes; record, don't crash
        return {"ok": False, "error": f"{type(exc).__name__}: {str(exc).strip().splitlines()[0]}" + (
            " " + " ".join(ln.strip() for ln in str(exc).strip().splitlines()[1:] if ln.strip() and not ln.strip().startswith("::"))
        ), "time_s": time.perf_counter() - t0}
    return {"ok": True, "gamma": float(gam), "time_s": time.perf_counter() - t0}


def _lmi(P: GeneralizedPlant) -> dict[str, Any]:
    t0 = time.perf_counter()
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", UserWarning)
            sol = hinf_synthesis(P).min_gamma()
    except SynthesisError as exc:
        return {"ok": False, "error": str(exc), "time_s": time.perf_counter() - t0}
    return {"ok": True, "gamma": sol.gamma, "status": sol.status, "time_s": time.perf_counter() - t0}


def compare_hinfsyn(cfg: DesignConfig, eps_list: list[float], n_list: list[int]) -> list[dict[str, Any]]:
    rows = []
    for n in n_list:
        P = estimator_plant(list(cfg.F[:n]), cfg.H[:n, :n])
        rows.append({"n": n, "plant": "P_f exact (paper)", "eps": 0.0, "lmi": _lmi(P), "hinfsyn": _hinfsyn(P)})
        for eps in eps_list:
            Pr = regularised(P, eps)
            # The coupled n = 6 LMI takes ~10 s per solve: do it once, at the middle eps.
            lmi = _lmi(Pr) if (n == 1 or eps == eps_list[len(eps_list) // 2]) else {"ok": False, "error": "skipped (time)"}
            rows.append({"n": n, "plant": "P_f regularised", "eps": eps, "lmi": lmi, "hinfsyn": _hinfsyn(Pr)})
    return rows


def _fmt(r: dict[str, Any]) -> str:
    return f"{r['gamma']:.6f} in {r['time_s']:.3f} s" if r.get("ok") else f"- ({r.get('error', '')[:70]})"


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="python -m gen.synth.bench", description="synth timing and hinfsyn comparison")
    ap.add_argument("--out", type=Path, required=True, help="results JSON file")
    ap.add_argument("--repeats", type=int, default=3, help="timed runs of the per-joint synth")
    ap.add_argument("--skip-coupled", action="store_true", help="skip the ~1 min coupled n = 6 synth")
    ap.add_argument("--quick", action="store_true", help="the hinfsyn comparison for n = 1 and one eps only")
    ns = ap.parse_args(argv)

    base = load_config(DEFAULT_CONFIG)
    work = ns.out.parent / f".{ns.out.stem}.work"
    work.mkdir(parents=True, exist_ok=True)
    results: dict[str, Any] = {"machine": {"python": platform.python_version(), "processor": platform.processor() or platform.machine()}}
    try:
        synth = [_time_synth("auto", ns.repeats, work)]
        if not ns.skip_coupled:
            synth.append(_time_synth("coupled", 1, work))
    finally:
        shutil.rmtree(work, ignore_errors=True)
    results["synth_n6"] = synth
    results["hinfsyn_comparison"] = (compare_hinfsyn(base, [1e-3], [1]) if ns.quick
                                     else compare_hinfsyn(base, [1e-2, 1e-3, 1e-4], [1, 6]))
    results["quick"] = ns.quick
    results["note"] = (
        "wall times are in-process (imports excluded; importing cvxpy costs ~1.2-1.5 s per process). "
        "hinfsyn cannot solve the paper's plant itself; see the module docstring."
    )
    write_text_atomic(ns.out, json.dumps(results, indent=1) + "\n")

    print("synth, paper config, n = 6 (design + verification + emission, in-process):")
    for s in synth:
        print(f"  {s['structure']:8s} ({s['mode']}): median {s['wall_time_median_s']:.2f} s over {s['repeats']} run(s); "
              f"estimator gamma_opt {s['estimator_gamma_opt']:.6f}, gamma_design {s['estimator_gamma_design']:.6f}")
    print("\nH-infinity estimator: LMI (cvxpy + Clarabel, min gamma) vs python-control hinfsyn:")
    print(f"  {'n':>2} {'plant':20s} {'eps':>7}  {'LMI gamma_opt':32s} hinfsyn gamma")
    for r in results["hinfsyn_comparison"]:
        print(f"  {r['n']:>2} {r['plant']:20s} {r['eps']:7.0e}  {_fmt(r['lmi']):32s} {_fmt(r['hinfsyn'])}")
    print(f"\nresults written to {ns.out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
