"""armctl run's trajectory file (tools/run/trajectory.py) before anything runs: the curve the
controller follows is the clamped cubic spline through the rows (checked against scipy's, an
implementation no one here wrote), and a malformed file is one line naming the file and the row."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from scipy.interpolate import CubicSpline

from tools.run.trajectory import TrajectoryError, clamped_slopes, hermite, read_csv


def test_the_curve_is_scipys_clamped_cubic_spline() -> None:
    rng = np.random.default_rng(46)
    t = np.concatenate([[0.0], np.cumsum(rng.uniform(0.01, 0.4, 59))])
    q = rng.normal(size=(60, 6))
    m = clamped_slopes(t, q)
    ref = CubicSpline(t, q, bc_type="clamped")
    assert np.abs(m - ref(t, 1)).max() < 1e-9
    at = np.linspace(0.0, t[-1], 2001)
    pos, vel, acc = hermite(t, q, m, at)
    assert np.abs(pos - ref(at)).max() < 1e-9 and np.abs(vel - ref(at, 1)).max() < 1e-8
    assert np.abs(acc - ref(at, 2)).max() < 1e-6
    assert np.all(m[0] == 0) and np.all(m[-1] == 0)  # at rest at both ends


@pytest.mark.parametrize(("text", "message"), [
    ("t,a,b\n0,0,0\n1,0,x\n", "row 3: not numbers"),
    ("0,0,0\n1,0\n", "row 2: 2 columns; t and one per joint (2) are 3"),
    ("0,0,0\n0.5,0,0\n0.5,1,1\n", "row 3: t = 0.5 s does not increase"),
    ("# only one point\n0,0,0\n", "1 row(s) of t, q1..q2: a trajectory needs at least 2"),
    ("0,0,0\n1,nan,0\n", "row 2: a value that is not a finite number"),
])
def test_a_malformed_file_is_one_line_naming_the_row(tmp_path: Path, text: str, message: str) -> None:
    f = tmp_path / "t.csv"
    f.write_text(text)
    with pytest.raises(TrajectoryError) as exc:
        read_csv(f, 2)
    assert str(exc.value) == f"{f}: {message}" or str(exc.value).startswith(f"{f}: {message}"), str(exc.value)
    assert "\n" not in str(exc.value)


def test_times_start_at_the_first_row_and_a_header_is_taken(tmp_path: Path) -> None:
    f = tmp_path / "t.csv"
    f.write_text("t,j1,j2\n# comment\n2.0,0.1,0.2\n2.5,0.3,0.4\n")
    t, rows, lines = read_csv(f, 2)
    assert t == [0.0, 0.5] and rows == [[0.1, 0.2], [0.3, 0.4]] and lines == [3, 4]
