"""Where things live in the repository and the build tree (every layer: gen, host_sim, tools)."""

from __future__ import annotations

import os
from pathlib import Path

REPO = Path(__file__).resolve().parents[2]
BUILD = REPO / "build"
DOCS = REPO / "docs"  # the user guide (MkDocs, mkdocs.yml)
DOCS_RESULTS = DOCS / "results"  # the results files the docs' figures are rendered from (`--record`)
PARAMETERS_PAGE = DOCS / "reference" / "parameters.md"  # the option tables generated from the registry
# the bundled arm's drive train and rated payload, cited (gen/drivetrain.py)
BUNDLED_DRIVETRAIN = REPO / "host_sim" / "models" / "ur5e_arm_drivetrain.toml"


def build_dir(preset: str) -> Path:
    return BUILD / preset


def controller_binary(bdir: Path) -> Path:
    """The controller in a build folder (build/<preset>, or an arm's: tools/build/arm.py)."""
    return bdir / "firmware" / "arm_controller"


def logger_binary(bdir: Path) -> Path:
    """The HIL run's telemetry logger (tools/lcm_logger) in a build folder."""
    return bdir / "tools" / "lcm_logger" / "arm_lcm_logger"


def env_with_repo() -> dict[str, str]:
    env = dict(os.environ)
    env["PYTHONPATH"] = str(REPO) + (os.pathsep + env["PYTHONPATH"] if env.get("PYTHONPATH") else "")
    return env
