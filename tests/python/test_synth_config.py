"""Design-config validation: every bad field is named, and the CLI exits non-zero without output."""

from __future__ import annotations

import argparse
import copy
import subprocess
import sys
import tomllib
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from gen.synth.cli import DEFAULT_CONFIG, add_arguments, run
from gen.synth.config import ConfigError, load_config, parse_config

REPO = Path(__file__).resolve().parents[2]


def paper_doc() -> dict[str, Any]:
    return tomllib.loads(DEFAULT_CONFIG.read_text())


def test_shipped_default_is_the_papers_design() -> None:
    cfg = load_config(DEFAULT_CONFIG)
    I6 = np.eye(6)
    assert cfg.n_joints == 6 and cfg.loop_rate_hz == 1000
    assert all(f.num == (1.0,) and f.den == (1.0, 1.0) for f in cfg.F)
    np.testing.assert_array_equal(cfg.H, 0.5 * I6)
    np.testing.assert_array_equal(np.hstack([cfg.E1, cfg.E2]), np.hstack([10 * I6, I6]))  # C1_o = [10 I, I]
    np.testing.assert_array_equal(cfg.D12, 0.5 * I6)


def test_full_matrices_and_per_joint_shorthand_agree() -> None:
    doc = paper_doc()
    doc["estimator"]["H"] = (0.5 * np.eye(6)).tolist()
    doc["estimator"]["F"] = [{"num": [1.0], "den": [1.0, 1.0]}] * 6
    doc["controller"]["E1"] = (10 * np.eye(6)).tolist()
    full, short = parse_config(doc), parse_config(paper_doc())
    np.testing.assert_array_equal(full.H, short.H)
    np.testing.assert_array_equal(full.E1, short.E1)
    assert full.F == short.F


def _set(doc: dict[str, Any], path: str, value: Any) -> None:
    *head, last = path.split(".")
    node = doc
    for k in head:
        node = node.setdefault(k, {})
    if value is _DELETE:
        del node[last]
    else:
        node[last] = value


_DELETE = object()

BAD_FIELDS = [
    ("estimator.H", [[0.5, 0.0, 0.0], [0.0, 0.5, 0.0]], "estimator.H: must be square 1x1 or 6x6, got 2x3"),
    ("estimator.H", [[0.0]], "estimator.H: must have full column rank"),
    ("estimator.H", "half", "estimator.H: must be a number or"),
    ("estimator.F", {"num": [1.0, 0.0], "den": [1.0, 1.0]}, "estimator.F: must be strictly proper"),
    ("estimator.F", {"num": [1.0, 0.0, 0.0], "den": [1.0, 1.0]}, "estimator.F: is improper"),
    ("estimator.F", {"num": [1.0], "den": [1.0, -1.0]}, "estimator.F: must be stable"),
    ("estimator.F", {"num": [0.0], "den": [1.0, 1.0]}, "estimator.F.num: F must not be identically zero"),
    ("estimator.F", {"num": [1.0], "den": [0.0, 1.0]}, "estimator.F.den: leading coefficient must be nonzero"),
    ("estimator.F", [{"num": [1.0], "den": [1.0, 1.0]}] * 5, "estimator.F: must be one {num, den} table"),
    ("estimator.F", _DELETE, "estimator.F: is missing"),
    ("arm.n_joints", 0, "arm.n_joints: must be an integer in [1, 16]"),
    ("arm.n_joints", 2.5, "arm.n_joints: must be an integer in [1, 16]"),
    ("arm.n_joints", True, "arm.n_joints: must be an integer in [1, 16]"),
    ("arm.loop_rate_hz", -1000, "arm.loop_rate_hz: must be an integer in [1, 100000]"),
    ("controller.D12", [[0.0]], "controller.D12: must have full column rank"),
    ("controller.E1", [[1.0, 2.0]], "controller.E1: must have 1 column (one joint) or 6 columns"),
    ("controller.E2", [[1.0], [0.0]], "controller.E2: has 12 rows after expansion but controller.E1 has 6"),
    ("controller.E1", [[float("nan")]], "controller.E1: entries must be finite numbers"),
    ("design.structure", "diagonal", "design.structure: must be one of auto, coupled"),
    ("design.backoff_ladder", [0.01, 0.001], "design.backoff_ladder: must be strictly increasing"),
    ("design.backoff_ladder", [-0.01], "design.backoff_ladder[0]: must be > 0"),
    ("design.delay_margin_samples", -1, "design.delay_margin_samples: must be an integer in [0, 50]"),
    ("ranges.e_max", 0.0, "ranges.e_max: must be > 0"),
    ("ranges.e_dot_max", _DELETE, "ranges.e_dot_max: is missing"),
    ("estimator.Hh", 0.5, "estimator.Hh: unknown field"),
    ("controler", {}, "controler: unknown section"),
]


@pytest.mark.parametrize("path,value,message", BAD_FIELDS,
                         ids=[f"{p}=<deleted>" if v is _DELETE else f"{p}={v!r}"[:60] for p, v, _ in BAD_FIELDS])
def test_bad_field_is_named(path: str, value: Any, message: str) -> None:
    doc = copy.deepcopy(paper_doc())
    _set(doc, path, value)
    with pytest.raises(ConfigError) as info:
        parse_config(doc)
    assert str(info.value).startswith(message), str(info.value)


def test_biproper_F_needs_the_explicit_flag() -> None:
    doc = paper_doc()
    doc["estimator"]["F"] = {"num": [1.0, 2.0], "den": [1.0, 1.0]}
    with pytest.raises(ConfigError, match="Theorem 2"):
        parse_config(doc)
    doc["estimator"]["allow_biproper_F"] = True
    assert parse_config(doc).F[0].num == (1.0, 2.0)


def _cli(config: Path, out: Path) -> int:
    parser = argparse.ArgumentParser()
    add_arguments(parser)
    return run(parser.parse_args(["--config", str(config), "--out", str(out), "--quiet"]))


def test_cli_names_the_field_on_stderr_and_writes_nothing(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    bad = tmp_path / "bad.toml"
    bad.write_text(DEFAULT_CONFIG.read_text().replace("H = [[0.5]]", "H = [[0.5, 0.0, 0.0], [0.0, 0.5, 0.0]]"))
    out = tmp_path / "out"
    assert _cli(bad, out) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err == ["config error: estimator.H: must be square 1x1 or 6x6, got 2x3"]
    assert not out.exists()


def test_cli_reports_unreadable_config(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert _cli(tmp_path / "missing.toml", tmp_path / "out") == 2
    assert capsys.readouterr().err.startswith("config error: config: file not found")
    broken = tmp_path / "broken.toml"
    broken.write_text("[arm\nn_joints = 6\n")
    assert _cli(broken, tmp_path / "out") == 2
    assert "not valid TOML" in capsys.readouterr().err


def test_default_config_path_is_repo_relative() -> None:
    parser = argparse.ArgumentParser()
    add_arguments(parser)
    ns = parser.parse_args(["--out", "x"])
    assert ns.config == DEFAULT_CONFIG and ns.config.is_file()


@pytest.mark.parametrize(("edit", "named"), [
    (("n_joints = 6", "n_joints = 60"), "arm.n_joints: must be an integer in [1, 16]"),
    (("n_joints = 6", "n_joints = 1e9"), "arm.n_joints"),
    (("delay_margin_samples = 1", "delay_margin_samples = 100000000"), "design.delay_margin_samples"),
    (("H = [[0.5]]", "H = [[1e308]]"), "estimator.H: entries must be finite numbers within"),
    (("e_max = 3.2", "e_max = 1e308"), "ranges.e_max"),
])
def test_values_that_would_crash_the_solve_are_refused_by_name(tmp_path: Path, edit: tuple[str, str],
                                                              named: str) -> None:
    text = (REPO / "gen" / "configs" / "paper.toml").read_text()
    assert edit[0] in text
    bad = tmp_path / "bad.toml"
    bad.write_text(text.replace(edit[0], edit[1], 1))
    r = subprocess.run([sys.executable, "-m", "gen.synth", "--config", str(bad), "--out", str(tmp_path / "o")],
                       cwd=REPO, capture_output=True, text=True, timeout=120)
    assert r.returncode == 2 and named in r.stderr and "Traceback" not in r.stderr, r.stderr


def test_a_coupled_problem_too_big_for_the_memory_is_refused() -> None:
    from gen.synth.pipeline import coupled_bytes

    assert coupled_bytes(4) == pytest.approx(57e6)
    assert 20e9 < coupled_bytes(60) < 30e9  # the size that once took the OOM killer
    assert coupled_bytes(16) < 2e9  # the firmware's largest arm fits a small machine
