"""`armctl bench step`'s agreement check on the bundled arm: Pinocchio's RNEA, given the arm's
armature (model.armature) and joint damping, against ours (the general arm_rnea and the arm's
generated kernel) on 200 states, through the same function the benchmark runs before it counts
anything (tools/bench rnea_agreement). Not its timing."""

from __future__ import annotations

import re

import pytest

from tools.bench import rnea_agreement

# Compiling bench_rnea takes about 2 minutes and 4.7 GB (Pinocchio's headers): alone, never beside
# another build.
pytestmark = pytest.mark.serial


def test_pinocchio_and_our_rnea_agree_on_the_bundled_arm() -> None:
    _, line = rnea_agreement()
    worst = float(re.search(r"worst relative difference (\S+)", line).group(1))
    assert worst < 1e-5, line
