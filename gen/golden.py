"""Golden vectors for the firmware's estimator/controller blocks (tests/c/test_pm_golden.c).

For one joint and 10,000 periods of a deterministic input within the declared ranges, with
stretches where the joint's torque is limited (anti-windup hold), this writes what the firmware
must produce in each structure (decoupled, paper, no estimator):
- float path: a double-precision simulation of the emitted float32 tables (the C float32
  arithmetic must agree to 1e-5 relative);
- fixed path: an exact integer simulation of the arithmetic pm_design_fixed.h prescribes (the C
  must agree bit for bit).
File layout (little-endian float32): n_steps x [e, e_dot, hold, then for structure s in
(decoupled, paper, none) and numeric in (float, fixed): u_o, w_hat] = 15 values per step.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

from gen.lib.atomic_output import exit_on_output_error, write_bytes_atomic, write_files_atomically
from gen.design_headers import parse

STRUCTURES = ("decoupled", "paper", "none")


def inputs(n: int, e_max: float, e_dot_max: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    t = np.arange(n) * 1e-3
    rng = np.random.default_rng(11)
    e = 0.3 * np.sin(2 * np.pi * 0.37 * t) + 0.01 * rng.standard_normal(n)
    e_dot = 2.0 * np.cos(2 * np.pi * 1.3 * t) + 0.1 * rng.standard_normal(n)
    e = np.clip(e, -e_max, e_max).astype(np.float32)
    e_dot = np.clip(e_dot, -e_dot_max, e_dot_max).astype(np.float32)
    # The torque limiter holds the estimator for 10 ms every second. Besides testing the hold,
    # this keeps the internal model inside its range: driven by these synthetic (not physically
    # consistent) inputs, the double integrator would otherwise drift into saturation.
    hold = ((t % 1.0) < 0.01).astype(np.float32)
    return e, e_dot, hold


def simulate_float(a: dict[str, np.ndarray], e: np.ndarray, e_dot: np.ndarray, hold: np.ndarray,
                   structure: str) -> tuple[np.ndarray, np.ndarray]:
    d = {k: v.astype(np.float64) for k, v in a.items() if v.dtype == np.float32}
    xk = np.zeros(d["ARM_EST_A"].shape[0])
    xc = np.zeros(d["ARM_CTL_A"].shape[0])
    xm = np.zeros(2)
    u_out, w_out = np.zeros(len(e)), np.zeros(len(e))
    for k in range(len(e)):
        y = np.array([e[k], e_dot[k]], dtype=np.float64)
        if k == 0:
            xm = y.copy()  # the internal model starts at the first measurement
        u = float((d["ARM_CTL_C"] @ xc + d["ARM_CTL_D"] @ y)[0])
        v = y - xm if structure == "decoupled" else y
        w = float((d["ARM_EST_C"] @ xk + d["ARM_EST_D"] @ v)[0]) if structure != "none" else 0.0
        u_out[k], w_out[k] = u, w
        xc = d["ARM_CTL_A"] @ xc + d["ARM_CTL_B"] @ y
        if structure != "none" and not hold[k]:
            xk = d["ARM_EST_A"] @ xk + d["ARM_EST_B"] @ v
            if structure == "decoupled":
                xm = d["ARM_IM_A"] @ xm + (d["ARM_IM_B"] * u).ravel()
        elif structure == "decoupled" and hold[k]:
            xm = y.copy()
    return u_out, w_out


def _sat32(v: int) -> int:
    return max(-2147483647, min(2147483647, v))


def _round_shift(acc: int, shift: int) -> int:
    return _sat32(acc if shift == 0 else (acc + (1 << (shift - 1))) >> shift)


def _clamp(v: int, lim: int) -> int:
    return max(-lim, min(lim, v))


def _to_q(v: np.float32, frac: int, lim: int) -> int:
    return _clamp(int(np.rint(np.float32(v) * np.float32(2.0**frac))), lim)


def _from_q(q: int, frac: int) -> float:
    return float(np.float32(q) / np.float32(2.0**frac))


def _mv(m: np.ndarray, x: list[int]) -> list[int]:
    return [sum(int(m[i, j]) * x[j] for j in range(m.shape[1])) for i in range(m.shape[0])]


def simulate_fixed(mac: dict[str, float], a: dict[str, np.ndarray], e: np.ndarray, e_dot: np.ndarray,
                   hold: np.ndarray, structure: str) -> tuple[np.ndarray, np.ndarray]:
    g = lambda name: int(mac[name])  # noqa: E731
    yf, e_lim, ed_lim = g("ARM_Y_FRAC"), g("ARM_RANGE_E_MAX_Q"), g("ARM_RANGE_E_DOT_MAX_Q")
    im_lim = (g("ARM_IM_E_MAX_Q"), g("ARM_IM_E_DOT_MAX_Q"))
    xk = [0] * a["ARM_EST_A_Q"].shape[0]
    xc = [0] * a["ARM_CTL_A_Q"].shape[0]
    xm = [0, 0]
    u_out, w_out = np.zeros(len(e)), np.zeros(len(e))
    for k in range(len(e)):
        y = [_to_q(e[k], yf, e_lim), _to_q(e_dot[k], yf, ed_lim)]
        if k == 0:
            xm = list(y)
        uq = _round_shift(_mv(a["ARM_CTL_C_Q"], xc)[0] + _mv(a["ARM_CTL_D_Q"], y)[0], g("ARM_CTL_ACC_U_SHIFT"))
        if structure == "decoupled":
            v = [_clamp(y[0] - xm[0], e_lim), _clamp(y[1] - xm[1], ed_lim)]
        else:
            v = y
        u_out[k] = _from_q(uq, g("ARM_CTL_U_FRAC"))
        if structure != "none":
            wq = _round_shift(_mv(a["ARM_EST_C_Q"], xk)[0] + _mv(a["ARM_EST_D_Q"], v)[0], g("ARM_EST_ACC_U_SHIFT"))
            w_out[k] = _from_q(wq, g("ARM_EST_U_FRAC"))
        ax, bx = _mv(a["ARM_CTL_A_Q"], xc), _mv(a["ARM_CTL_B_Q"], y)
        xc = [_round_shift(ax[i] + bx[i], g("ARM_CTL_ACC_X_SHIFT")) for i in range(len(xc))]
        if structure != "none" and not hold[k]:
            ax, bx = _mv(a["ARM_EST_A_Q"], xk), _mv(a["ARM_EST_B_Q"], v)
            xk = [_round_shift(ax[i] + bx[i], g("ARM_EST_ACC_X_SHIFT")) for i in range(len(xk))]
            if structure == "decoupled":
                ax, bx = _mv(a["ARM_IM_A_Q"], xm), _mv(a["ARM_IM_B_Q"], [uq])
                xm = [_clamp(_round_shift(ax[i] + bx[i], g("ARM_IM_ACC_X_SHIFT")), im_lim[i]) for i in range(2)]
        elif structure == "decoupled" and hold[k]:
            xm = list(y)
    return u_out, w_out


def golden(design_dir: Path, n: int = 10_000) -> bytes:
    mac_f, arr_f = parse(design_dir / "pm_design_float.h")
    mac_q, arr_q = parse(design_dir / "pm_design_fixed.h")
    e, e_dot, hold = inputs(n, float(mac_q["ARM_RANGE_E_MAX"]), float(mac_q["ARM_RANGE_E_DOT_MAX"]))
    cols = [e, e_dot, hold]
    for s in STRUCTURES:
        cols.extend(simulate_float(arr_f, e, e_dot, hold, s))
        cols.extend(simulate_fixed(mac_q, arr_q, e, e_dot, hold, s))
    return np.stack(cols, axis=1).astype("<f4").tobytes()


@exit_on_output_error("gen.golden")
def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="gen.golden", description=__doc__)
    p.add_argument("--design", type=Path, required=True, help="directory with pm_design_*.h")
    p.add_argument("--out", type=Path, required=True)
    p.add_argument("--steps", type=int, default=10_000)
    ns = p.parse_args(argv)
    data = golden(ns.design, ns.steps)
    write_bytes_atomic(ns.out, data)
    return 0


if __name__ == "__main__":
    sys.exit(main())
