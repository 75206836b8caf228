"""Emission: manifest + headers, atomic output, the content hash, C compilation, and the
fixed-point overflow bounds checked against the integer arithmetic the header documents."""

from __future__ import annotations

import argparse
import json
import re
import shutil
import subprocess
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from gen.synth import emit as emit_mod
from gen.synth.cli import DEFAULT_CONFIG, add_arguments, run, synth_to_dir
from gen.synth.fixedpoint import l1_gains
from gen.synth.manifest import content_hash

GCC_FLAGS = ["-std=c11", "-Wall", "-Wextra", "-Wconversion", "-Werror"]


@pytest.fixture(scope="module")
def out(tmp_path_factory: pytest.TempPathFactory) -> Path:
    d = tmp_path_factory.mktemp("synth") / "design"
    parser = argparse.ArgumentParser()
    add_arguments(parser)
    assert run(parser.parse_args(["--out", str(d), "--quiet"])) == 0
    return d


@pytest.fixture(scope="module")
def manifest(out: Path) -> dict[str, Any]:
    return json.loads((out / "manifest.json").read_text())


def test_outputs_and_manifest_fields(out: Path, manifest: dict[str, Any]) -> None:
    assert sorted(p.name for p in out.iterdir()) == ["manifest.json", "pm_design.txt", "pm_design_fixed.h",
                                                     "pm_design_float.h"]
    assert not list(out.parent.glob(".design.synth-*"))  # temp dir cleaned up
    for kind in ("estimator", "controller"):
        assert {"gamma_opt", "gamma_design", "continuous", "discrete", "subproblems"} <= set(manifest[kind])
    assert manifest["controller"]["degenerate"] is True
    v = manifest["verification"]
    assert set(v["combined_loop"]) == {"decoupled", "paper"}
    for st in ("decoupled", "paper"):
        assert v["combined_loop"][st]["sampled_spectral_radius"] < 1
        assert v["combined_loop"][st]["sampled_spectral_radius_delayed"] < 1
    assert manifest["inputs"]["arm"] == {"n_joints": 6, "loop_rate_hz": 1000}
    assert manifest["fixed_point"]["estimator"]["bound_method"].startswith("l1 norm")


def test_content_hash_covers_the_design_and_matches_the_headers(out: Path, manifest: dict[str, Any]) -> None:
    assert content_hash(manifest) == manifest["content_hash"]
    short = manifest["content_hash"][:16]
    for h in ("pm_design_float.h", "pm_design_fixed.h"):
        assert f'#define ARM_DESIGN_HASH "{short}"' in (out / h).read_text()
    tampered = json.loads(json.dumps(manifest))
    tampered["estimator"]["discrete"]["D"][0][1] += 1e-9
    assert content_hash(tampered) != manifest["content_hash"]
    rerun = json.loads(json.dumps(manifest))
    rerun["run"]["timings_s"] = {}  # wall times are outside the hash
    assert content_hash(rerun) == manifest["content_hash"]


def test_design_file_holds_exactly_the_headers_numbers(out: Path) -> None:
    """pm_design.txt (what --design-file loads) against the headers as C reads them: every float
    the float32 value the header's literal compiles to, every integer the same."""
    from gen.design_headers import parse

    mf, af = parse(out / "pm_design_float.h")
    mq, aq = parse(out / "pm_design_fixed.h")
    lines = [ln.split() for ln in (out / "pm_design.txt").read_text().splitlines() if ln and not ln.startswith("#")]
    assert lines[0] == ["arm-pm-design", "1"] and lines[-1] == ["end"]
    f = {ln[0]: ln[1:] for ln in lines[1:-1]}
    assert f'#define ARM_DESIGN_HASH "{f["hash"][0]}"' in (out / "pm_design_float.h").read_text()
    assert (int(f["n_joints"][0]), float(f["loop_rate_hz"][0])) == (mf["ARM_DESIGN_N_JOINTS"], mf["ARM_LOOP_RATE_HZ"])
    assert (int(f["est_nx"][0]), int(f["ctl_nx"][0])) == (mf["ARM_EST_NX"], mf["ARM_CTL_NX"])
    for name, arr in af.items():  # ARM_EST_A -> est_a
        got = np.array([float.fromhex(v) for v in f[name[4:].lower()]], dtype=np.float32)
        assert np.array_equal(got.view(np.uint32), arr.ravel().astype(np.float32).view(np.uint32)), name
    for name, arr in aq.items():  # ARM_EST_A_Q -> est_a_q
        assert [int(v) for v in f[name[4:].lower()]] == arr.ravel().tolist(), name
    for key, macro in (("y_frac", "ARM_Y_FRAC"), ("est_u_frac", "ARM_EST_U_FRAC"), ("ctl_u_frac", "ARM_CTL_U_FRAC"),
                       ("est_acc_x_shift", "ARM_EST_ACC_X_SHIFT"), ("est_acc_u_shift", "ARM_EST_ACC_U_SHIFT"),
                       ("ctl_acc_x_shift", "ARM_CTL_ACC_X_SHIFT"), ("ctl_acc_u_shift", "ARM_CTL_ACC_U_SHIFT"),
                       ("im_acc_x_shift", "ARM_IM_ACC_X_SHIFT"), ("range_e_max_q", "ARM_RANGE_E_MAX_Q"),
                       ("range_e_dot_max_q", "ARM_RANGE_E_DOT_MAX_Q"), ("im_e_max_q", "ARM_IM_E_MAX_Q"),
                       ("im_e_dot_max_q", "ARM_IM_E_DOT_MAX_Q")):
        assert f[key] == [str(mq[macro])], key


def test_failed_emission_leaves_no_partial_header(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    target = tmp_path / "design"
    target.mkdir()
    (target / "robot_model.h").write_text("/* someone else's */\n")

    def boom(_m: dict[str, Any]) -> str:
        raise RuntimeError("disk full")

    monkeypatch.setattr(emit_mod, "fixed_header", boom)
    with pytest.raises(RuntimeError, match="disk full"):
        synth_to_dir(DEFAULT_CONFIG, target)
    assert sorted(p.name for p in target.iterdir()) == ["robot_model.h"]
    assert sorted(p.name for p in tmp_path.iterdir()) == ["design"]


def test_refused_design_writes_nothing(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    cfg = tmp_path / "slow.toml"
    cfg.write_text(DEFAULT_CONFIG.read_text().replace("loop_rate_hz = 1000", "loop_rate_hz = 2"))
    parser = argparse.ArgumentParser()
    add_arguments(parser)
    assert run(parser.parse_args(["--config", str(cfg), "--out", str(tmp_path / "o")])) == 3
    assert "2 Hz" in capsys.readouterr().err
    assert not (tmp_path / "o").exists()


# ---------------------------------------------------------------- C compilation and arithmetic

C_PROGRAM = r"""
#include <stdio.h>
#include <string.h>
#include "pm_design_float.h"
#include "pm_design_fixed.h"

#if ARM_DESIGN_PER_JOINT != 1 || ARM_EST_NY != 2 || ARM_CTL_NY != 2
#error "this test drives one joint"
#endif

static int32_t sat32(int64_t v) { return v > INT32_MAX ? INT32_MAX : (v < -INT32_MAX ? -INT32_MAX : (int32_t)v); }
static int32_t shr(int64_t acc, int s) { return sat32(s > 0 ? (acc + ((int64_t)1 << (s - 1))) >> s : acc); }
static int32_t clampq(int32_t v, int32_t lim) { return v > lim ? lim : (v < -lim ? -lim : v); }
static double scale(int frac) { return (double)((int64_t)1 << frac); }
static int32_t toq(double v, int frac, int32_t lim) {
    double s = v * scale(frac);
    s = s > (double)lim ? (double)lim : (s < -(double)lim ? -(double)lim : s);
    return (int32_t)(s >= 0 ? s + 0.5 : s - 0.5);
}

int main(void) {
    const double T = (double)ARM_LOOP_PERIOD_S, w = 1.0;
    double pf[2] = {0.2, 0.0}, pq[2] = {0.2, 0.0};  /* plants (e, e_dot) in double */
    float xk[ARM_EST_NX] = {0}, xc[ARM_CTL_NX] = {0};
    int32_t qk[ARM_EST_NX] = {0}, qc[ARM_CTL_NX] = {0};
    const int32_t lim[2] = {ARM_RANGE_E_MAX_Q, ARM_RANGE_E_DOT_MAX_Q};
    const int32_t imlim[2] = {ARM_IM_E_MAX_Q, ARM_IM_E_DOT_MAX_Q};
    /* the internal model starts at the first measurement, so K sees no fictitious disturbance */
    float xm[2] = {(float)pf[0], (float)pf[1]};
    int32_t qm[2] = {toq(pq[0], ARM_Y_FRAC, lim[0]), toq(pq[1], ARM_Y_FRAC, lim[1])};
    for (int k = 0; k < 3000; ++k) {
        /* ---- float32 */
        float y[2] = {(float)pf[0], (float)pf[1]}, v[2], uo = 0.0f, wh = 0.0f;
        for (int j = 0; j < 2; ++j) v[j] = y[j] - xm[j];
        for (int j = 0; j < ARM_CTL_NX; ++j) uo += ARM_CTL_C[0][j] * xc[j];
        for (int j = 0; j < 2; ++j) uo += ARM_CTL_D[0][j] * y[j];
        for (int j = 0; j < ARM_EST_NX; ++j) wh += ARM_EST_C[0][j] * xk[j];
        for (int j = 0; j < 2; ++j) wh += ARM_EST_D[0][j] * v[j];
        float nk[ARM_EST_NX], nc[ARM_CTL_NX], nm[2];
        for (int i = 0; i < ARM_EST_NX; ++i) { nk[i] = 0.0f; for (int j = 0; j < ARM_EST_NX; ++j) nk[i] += ARM_EST_A[i][j] * xk[j]; for (int j = 0; j < 2; ++j) nk[i] += ARM_EST_B[i][j] * v[j]; }
        for (int i = 0; i < ARM_CTL_NX; ++i) { nc[i] = 0.0f; for (int j = 0; j < ARM_CTL_NX; ++j) nc[i] += ARM_CTL_A[i][j] * xc[j]; for (int j = 0; j < 2; ++j) nc[i] += ARM_CTL_B[i][j] * y[j]; }
        for (int i = 0; i < 2; ++i) { nm[i] = ARM_IM_B[i][0] * uo; for (int j = 0; j < 2; ++j) nm[i] += ARM_IM_A[i][j] * xm[j]; }
        memcpy(xk, nk, sizeof xk); memcpy(xc, nc, sizeof xc); memcpy(xm, nm, sizeof xm);
        double a = (double)(uo - wh) + w;
        pf[0] += T * pf[1] + 0.5 * T * T * a; pf[1] += T * a;

        /* ---- int32 Q-format, exactly as documented in pm_design_fixed.h */
        int32_t yq[2], vq[2];
        for (int j = 0; j < 2; ++j) { yq[j] = toq(pq[j], ARM_Y_FRAC, lim[j]); vq[j] = clampq(yq[j] - qm[j], lim[j]); }
        int64_t acc = 0;
        for (int j = 0; j < ARM_CTL_NX; ++j) acc += (int64_t)ARM_CTL_C_Q[0][j] * qc[j];
        for (int j = 0; j < 2; ++j) acc += (int64_t)ARM_CTL_D_Q[0][j] * yq[j];
        int32_t uoq = shr(acc, ARM_CTL_ACC_U_SHIFT);
        acc = 0;
        for (int j = 0; j < ARM_EST_NX; ++j) acc += (int64_t)ARM_EST_C_Q[0][j] * qk[j];
        for (int j = 0; j < 2; ++j) acc += (int64_t)ARM_EST_D_Q[0][j] * vq[j];
        int32_t whq = shr(acc, ARM_EST_ACC_U_SHIFT);
        int32_t mk[ARM_EST_NX], mc[ARM_CTL_NX], mm[2];
        for (int i = 0; i < ARM_EST_NX; ++i) { acc = 0; for (int j = 0; j < ARM_EST_NX; ++j) acc += (int64_t)ARM_EST_A_Q[i][j] * qk[j]; for (int j = 0; j < 2; ++j) acc += (int64_t)ARM_EST_B_Q[i][j] * vq[j]; mk[i] = shr(acc, ARM_EST_ACC_X_SHIFT); }
        for (int i = 0; i < ARM_CTL_NX; ++i) { acc = 0; for (int j = 0; j < ARM_CTL_NX; ++j) acc += (int64_t)ARM_CTL_A_Q[i][j] * qc[j]; for (int j = 0; j < 2; ++j) acc += (int64_t)ARM_CTL_B_Q[i][j] * yq[j]; mc[i] = shr(acc, ARM_CTL_ACC_X_SHIFT); }
        for (int i = 0; i < 2; ++i) { acc = (int64_t)ARM_IM_B_Q[i][0] * uoq; for (int j = 0; j < 2; ++j) acc += (int64_t)ARM_IM_A_Q[i][j] * qm[j]; mm[i] = clampq(shr(acc, ARM_IM_ACC_X_SHIFT), imlim[i]); }
        memcpy(qk, mk, sizeof qk); memcpy(qc, mc, sizeof qc); memcpy(qm, mm, sizeof qm);
        double aq = (double)uoq / scale(ARM_CTL_U_FRAC) - (double)whq / scale(ARM_EST_U_FRAC) + w;
        pq[0] += T * pq[1] + 0.5 * T * T * aq; pq[1] += T * aq;
        if (k % 500 == 0 || k == 2999) printf("%d %.9e %.9e\n", k, pf[0], pq[0]);
    }
    return 0;
}
"""


def _python_reference(m: dict[str, Any], steps: int = 3000) -> dict[int, float]:
    """The same closed loop in float64 from the manifest's discrete matrices."""
    K = {k: np.array(v) for k, v in m["estimator"]["discrete"].items() if k in "ABCD"}
    C = {k: np.array(v) for k, v in m["controller"]["discrete"].items() if k in "ABCD"}
    IM = {k: np.array(v) for k, v in m["internal_model"]["discrete"].items() if k in "AB"}
    T, w = m["loop_period_s"], 1.0
    p, xk, xc = np.array([0.2, 0.0]), np.zeros(K["A"].shape[0]), np.zeros(C["A"].shape[0])
    xm = p.copy()
    out = {}
    for k in range(steps):
        y = p.copy()
        uo = float((C["C"] @ xc + C["D"] @ y)[0])
        v = y - xm
        wh = float((K["C"] @ xk + K["D"] @ v)[0])
        xk, xc, xm = K["A"] @ xk + K["B"] @ v, C["A"] @ xc + C["B"] @ y, IM["A"] @ xm + IM["B"][:, 0] * uo
        a = uo - wh + w
        p = np.array([p[0] + T * p[1] + 0.5 * T * T * a, p[1] + T * a])
        if k % 500 == 0 or k == steps - 1:
            out[k] = float(p[0])
    return out


@pytest.mark.skipif(shutil.which("gcc") is None, reason="gcc not installed")
def test_headers_compile_strictly_and_run_the_documented_arithmetic(out: Path, manifest: dict[str, Any], tmp_path: Path) -> None:
    src = tmp_path / "use_headers.c"
    src.write_text(C_PROGRAM)
    exe = tmp_path / "use_headers"
    for headers_only in (True, False):
        if headers_only:  # each header alone, in a file that reads nothing: still warning-free
            for h in ("pm_design_float.h", "pm_design_fixed.h"):
                only = tmp_path / f"only_{h}.c"
                only.write_text(f'#include "{h}"\nint main(void) {{ return 0; }}\n')
                subprocess.run(["gcc", *GCC_FLAGS, "-pedantic", "-I", str(out), str(only), "-o", str(tmp_path / "only")], check=True)
        else:
            subprocess.run(["gcc", *GCC_FLAGS, "-I", str(out), str(src), "-o", str(exe)], check=True)
    lines = subprocess.run([str(exe)], check=True, capture_output=True, text=True).stdout.split("\n")
    rows = {int(a): (float(b), float(c)) for a, b, c in (ln.split() for ln in lines if ln.strip())}
    ref = _python_reference(manifest)
    scale = max(abs(v) for v in ref.values())
    for k, e_ref in ref.items():
        e_f32, e_fix = rows[k]
        assert abs(e_f32 - e_ref) < 1e-3 * scale, (k, e_f32, e_ref)
        assert abs(e_fix - e_ref) < 1e-3 * scale, (k, e_fix, e_ref)
    # A constant disturbance is being rejected (the estimator's slow mode, not a bug, sets the pace).
    assert abs(ref[2999]) < abs(ref[500])


def test_every_contract_name_is_emitted(out: Path) -> None:
    fl = (out / "pm_design_float.h").read_text()
    fx = (out / "pm_design_fixed.h").read_text()
    for name in [
        "ARM_DESIGN_HASH", "ARM_DESIGN_N_JOINTS 6", "ARM_DESIGN_PER_JOINT 1", "ARM_LOOP_RATE_HZ 1000",
        "ARM_LOOP_PERIOD_S 0.001f", "ARM_EST_NX", "ARM_EST_NY 2", "ARM_EST_NU 1", "ARM_CTL_NX", "ARM_CTL_NY 2",
        "ARM_CTL_NU 1", "ARM_EST_A[ARM_EST_NX][ARM_EST_NX]", "ARM_EST_B[ARM_EST_NX][ARM_EST_NY]",
        "ARM_EST_C[ARM_EST_NU][ARM_EST_NX]", "ARM_EST_D[ARM_EST_NU][ARM_EST_NY]", "ARM_CTL_A[", "ARM_CTL_B[",
        "ARM_CTL_C[", "ARM_CTL_D[", "ARM_IM_A[2][2]", "ARM_IM_B[2][1]",
    ]:
        assert name in fl, name
    for name in ["ARM_EST_A_Q[", "ARM_CTL_D_Q[", "ARM_IM_A_Q[2][2]", "ARM_IM_B_Q[2][1]", "ARM_EST_A_FRAC", "ARM_EST_X_FRAC",
                 "ARM_EST_Y_FRAC", "ARM_EST_U_FRAC", "ARM_CTL_X_FRAC", "ARM_CTL_U_FRAC", "ARM_RANGE_E_MAX_Q", "ARM_EST_X_BOUND_Q"]:
        assert name in fx, name
    assert re.search(r"#include <stdint.h>", fl) and len(re.findall(r"#include", fl)) == 1
    assert len(re.findall(r"#include", fx)) == 1


def _worst_case_run(fx: dict[str, Any], y_frac: int, steps: int, target: tuple[str, int]) -> tuple[
        list[int], list[int]]:
    """Drive the documented integer recursion with the input sign sequence that maximises one
    state or output at the last step; return each state's and each output's peak |value| seen,
    in Q units."""
    A, B = np.array(fx["A_Q"], dtype=object), np.array(fx["B_Q"], dtype=object)
    C, D = np.array(fx["C_Q"], dtype=object), np.array(fx["D_Q"], dtype=object)
    lim = [int(np.floor(r * 2.0**y_frac)) for r in fx["input_max"]]
    Ah = np.array(fx["A_Q"], dtype=float) / 2.0 ** fx["A_FRAC"]
    Bh = np.array(fx["B_Q"], dtype=float) / 2.0 ** fx["B_FRAC"]
    Ch = np.array(fx["C_Q"], dtype=float) / 2.0 ** fx["C_FRAC"]
    kind, i = target
    h, M = [], Bh.copy()  # impulse response of the target from each input, h[k] for delay k
    for _ in range(steps):
        h.append(M[i] if kind == "x" else Ch[i] @ M)
        M = Ah @ M
    x = [0] * A.shape[0]
    sx = fx["ACC_X_SHIFT"]
    su = fx["ACC_U_SHIFT"]

    def shr(acc: int, s: int) -> int:
        v = (acc + (1 << (s - 1))) >> s if s > 0 else acc
        return max(-(2**31 - 1), min(2**31 - 1, v))

    peak_x, peak_u = [0] * A.shape[0], [0] * C.shape[0]
    for k in range(steps):
        hk = h[steps - 1 - k] if kind == "x" else (h[steps - 2 - k] if k < steps - 1 else np.array(fx["D_Q"], dtype=float)[i])
        y = [lim[j] * (1 if hk[j] >= 0 else -1) for j in range(len(lim))]
        u = [shr(sum(int(C[r, j]) * x[j] for j in range(len(x))) + sum(int(D[r, j]) * y[j] for j in range(len(y))), su) for r in range(C.shape[0])]
        x = [shr(sum(int(A[r, j]) * x[j] for j in range(len(x))) + sum(int(B[r, j]) * y[j] for j in range(len(y))), sx) for r in range(A.shape[0])]
        peak_x = [max(p, abs(v)) for p, v in zip(peak_x, x)]
        peak_u = [max(p, abs(v)) for p, v in zip(peak_u, u)]
    return peak_x, peak_u


@pytest.fixture(scope="module")
def two_state_manifest(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Any]:
    """The paper's weights with a second-order F: an estimator of two states per joint, each with a
    bound of its own (the paper's F gives one state, where the largest bound is its own)."""
    base = tmp_path_factory.mktemp("synth2")
    text, n = re.subn(r"(?m)^F = \{[^}]*\}", "F = { num = [100.0], den = [1.0, 14.0, 100.0] }",
                      DEFAULT_CONFIG.read_text())
    assert n == 1
    (base / "f2.toml").write_text(text)
    parser = argparse.ArgumentParser()
    add_arguments(parser)
    assert run(parser.parse_args(["--config", str(base / "f2.toml"), "--out", str(base / "design"), "--quiet"])) == 0
    m = json.loads((base / "design" / "manifest.json").read_text())
    assert len(m["fixed_point"]["estimator"]["state_bound"]) == 2
    return m


@pytest.mark.parametrize("which", ["manifest", "two_state_manifest"])
def test_fixed_point_bounds_hold_for_worst_case_inputs(which: str, request: pytest.FixtureRequest) -> None:
    manifest = request.getfixturevalue(which)
    y_frac = manifest["fixed_point"]["Y_FRAC"]
    for name in ("estimator", "controller"):
        fx = manifest["fixed_point"][name]
        xb = [int(np.floor(b * 2.0 ** fx["X_FRAC"])) for b in fx["state_bound"]]
        ub = [int(np.floor(b * 2.0 ** fx["U_FRAC"])) for b in fx["output_bound"]]
        for target in [("x", i) for i in range(len(xb))] + [("u", i) for i in range(len(ub))]:
            peak_x, peak_u = _worst_case_run(fx, y_frac, 4000, target)
            # every state and output within its own bound (not the largest of them), whatever input
            assert all(p <= b + 1 for p, b in zip(peak_x, xb)), (name, target, peak_x, xb)
            assert all(p <= b + 1 for p, b in zip(peak_u, ub)), (name, target, peak_u, ub)
            assert max(peak_x) < 2**31 - 1 and max(peak_u) < 2**31 - 1
        # The bound is tight, not just safe: the worst case reaches most of it.
        if name == "estimator":
            assert _worst_case_run(fx, y_frac, 4000, ("u", 0))[1][0] > 0.5 * ub[0]


def test_l1_gain_of_a_first_order_system_is_exact() -> None:
    a, b = 0.999, 2e-3
    got = l1_gains(np.array([[a]]), np.array([[b]]))[0, 0]
    assert got == pytest.approx(b / (1 - a), rel=1e-6)
    assert got >= b / (1 - a)  # an upper bound, never below the truth
