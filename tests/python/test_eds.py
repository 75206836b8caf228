"""gen/eds.py reads the drive's EDS as python-canopen does (the master's view and the simulator's
C table are one dictionary), and refuses a broken EDS in one line naming the section."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

from gen import eds
from gen.lib.paths import REPO

EDS = REPO / "firmware" / "protocol" / "cia402_servo.eds"
CONTRACT = {  # (index, sub): (data type, access, default) as the CANopen contract states them
    (0x1000, 0): (0x0007, "CONST", 0x00020192), (0x6076, 0): (0x0007, "RW", 150000),
    (0x608F, 1): (0x0007, "RW", 524288), (0x608F, 2): (0x0007, "RW", 1), (0x6091, 1): (0x0007, "RW", 101),
    (0x6091, 2): (0x0007, "RW", 1), (0x6060, 0): (0x0002, "RW", 0), (0x6071, 0): (0x0003, "RW", 0),
    (0x6064, 0): (0x0004, "RO", 0), (0x6041, 0): (0x0006, "RO", 0), (0x1017, 0): (0x0006, "RW", 0),
    (0x1600, 1): (0x0007, "RW", 0x60400010), (0x1600, 2): (0x0007, "RW", 0x60710010),
    (0x1A00, 1): (0x0007, "RW", 0x60640020), (0x1A00, 2): (0x0007, "RW", 0x606C0020),
    (0x1A01, 1): (0x0007, "RW", 0x60770010), (0x1A01, 2): (0x0007, "RW", 0x60410010),
}


def test_entries_match_python_canopen() -> None:
    canopen = pytest.importorskip("canopen")
    node_id = 5
    od = canopen.import_od(str(EDS), node_id)
    ours = {(e.index, e.sub): e for e in eds.entries(EDS)}
    theirs = {}
    for obj in od.values():
        for var in ([obj] if isinstance(obj, canopen.objectdictionary.ODVariable) else obj.values()):
            theirs[(var.index, var.subindex)] = var
    assert set(ours) == set(theirs)
    for key, e in ours.items():
        v = theirs[key]
        assert e.dtype == v.data_type, key
        assert e.access.lower() == v.access_type.replace("rww", "rw").replace("rwr", "rw"), key
        if e.dtype == 0x0009:
            assert e.text == v.default, key
        else:
            assert e.default + (node_id if e.nodeid_rel else 0) == v.default, key
        assert e.pdo == v.pdo_mappable, key
    for key, (dtype, access, default) in CONTRACT.items():
        assert (ours[key].dtype, ours[key].access, ours[key].default) == (dtype, access, default), key
    assert ours[(0x1800, 1)].nodeid_rel and ours[(0x1800, 1)].default == 0x180


def test_emits_one_row_per_entry(tmp_path: Path) -> None:
    r = subprocess.run([sys.executable, "-m", "gen.eds", "--eds", str(EDS), "--out", str(tmp_path)], cwd=REPO,
                       capture_output=True, text=True)
    assert r.returncode == 0, r.stderr
    c = (tmp_path / "sim_co_od_table.c").read_text()
    n = len(eds.entries(EDS))
    assert f"#define SIM_CO_OD_N {n}u" in (tmp_path / "sim_co_od_table.h").read_text()
    assert c.count("\n    {0x") == n


@pytest.mark.parametrize(("edit", "needle"), [
    (("DataType=0x0007", "DataType=0x0011"), "DataType=0x0011: not one of the types"),
    (("AccessType=const", "AccessType=readonly"), "AccessType='readonly'"),
    (("DefaultValue=0x00020192", "DefaultValue=lots"), "[1000] DefaultValue='lots' is not an integer"),
])
def test_bad_eds_is_one_line(tmp_path: Path, edit: tuple[str, str], needle: str) -> None:
    bad = tmp_path / "bad.eds"
    bad.write_text(EDS.read_text().replace(*edit, 1))
    out = tmp_path / "out"
    r = subprocess.run([sys.executable, "-m", "gen.eds", "--eds", str(bad), "--out", str(out)], cwd=REPO,
                       capture_output=True, text=True)
    assert r.returncode == 2 and needle in r.stderr and len(r.stderr.strip().splitlines()) == 1, r.stderr
    assert not out.exists()  # nothing half-written
