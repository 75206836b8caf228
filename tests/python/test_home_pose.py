"""The arm's home pose comes from its model (the keyframe "home" gen/arm writes, arm.json's
per-joint "home"), emitted as ARM_HOME_Q in the generated model header: the C tests and the MCU's
closed-loop check start there, for any arm, instead of a UR5e pose reused through `j % 6`."""

from __future__ import annotations

import json
import re
from pathlib import Path

import numpy as np
import pytest

from gen.lib.paths import REPO
from gen.robot_model import extract, model_header


def _header_home(text: str) -> list[float]:
    m = re.search(r"ARM_HOME_Q\[ARM_N_JOINTS\] = \{([^}]*)\}", text)
    assert m, "no ARM_HOME_Q in the header"
    return [float(x.rstrip("f")) for x in m.group(1).split(",")]


def test_the_generated_header_has_the_arms_home(build_dir: Path) -> None:
    gen = build_dir / "generated"
    if not (gen / "arm" / "arm.json").exists():
        pytest.skip(f"{gen} not generated (tools/armctl build --preset debug)")
    info = json.loads((gen / "arm" / "arm.json").read_text())
    home = _header_home((gen / "arm_robot_model_data.h").read_text())
    assert home == pytest.approx([j["home"] for j in info["joints"]], abs=1e-6)
    assert len(home) == info["n_joints"]


def test_the_home_is_the_models_keyframe_not_a_fixed_pose(tmp_path: Path, build_dir: Path) -> None:
    xml = build_dir / "generated" / "arm" / "arm.xml"
    if not xml.exists():
        pytest.skip(f"{xml} not generated")
    text = xml.read_text()
    moved = re.sub(r'(<key name="home" qpos=")([^"]*)(")',
                   lambda m: m.group(1) + " ".join(f"{float(x) + 0.25:g}" for x in m.group(2).split()) + m.group(3),
                   text)
    assert moved != text
    (tmp_path / "arm.xml").write_text(moved)
    for f in xml.parent.iterdir():  # meshes and includes beside it
        if f.name != "arm.xml" and not (tmp_path / f.name).exists():
            (tmp_path / f.name).symlink_to(f)
    base, other = extract(xml), extract(tmp_path / "arm.xml")
    assert np.allclose(other.home, base.home + 0.25)
    assert _header_home(model_header(other, "x")) == pytest.approx(list(other.home + 0.0), abs=1e-6)


@pytest.mark.parametrize("path", ["tests/c/test_safety.c", "firmware/port/cortex_m/closed_loop.c"])
def test_no_hard_coded_home_pose(path: str) -> None:
    text = (REPO / path).read_text()
    assert "-1.87f" not in text and "% 6]" not in text, path
