"""arm_sim's random numbers are numpy's, bit for bit (host_sim/native/sim_rng.c): the same seed
gives the same uncertainty as np.random.default_rng(seed) gave the Python simulator before."""

from __future__ import annotations

import subprocess
from pathlib import Path

import numpy as np
import pytest


@pytest.mark.parametrize("seed", [0, 1, 2, 101, 2**32 - 1, 2**32, 123456789012345, 2**64 - 1])
def test_uniform_draws_equal_numpys(build_dir: Path, seed: int) -> None:
    exe = build_dir / "tests" / "c" / "sim" / "sim_rng_dump"
    if not exe.exists():
        pytest.skip(f"{exe} not built")
    out = subprocess.run([str(exe), str(seed), "2000", "-0.05", "0.05"], capture_output=True, text=True,
                         check=True).stdout.split()
    want = np.random.default_rng(seed).uniform(-0.05, 0.05, 2000)
    assert [float(x) for x in out] == want.tolist()  # exact: the same bits
