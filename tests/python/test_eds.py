"""gen/eds.py reads real drives' EDS and DCF files as python-canopen does (every entry: data type,
access, value with a DCF's ParameterValue over the DefaultValue and $NODEID evaluated, limits, PDO
mapping), every CiA 301 basic data type, and refuses a broken file in one line, exit 2, never a
traceback (a hypothesis test mutates real files to show it)."""

from __future__ import annotations

import contextlib
import io
import math
import subprocess
import sys
from pathlib import Path

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from gen import eds
from gen.lib.paths import REPO

EDS = REPO / "firmware" / "protocol" / "cia402_servo.eds"
VENDOR = sorted(p for p in (REPO / "tests" / "drives").iterdir() if p.suffix in (".eds", ".dcf"))
FILES = [EDS, *VENDOR]
NODE_ID = 5


def _theirs(path: Path) -> dict:
    canopen = pytest.importorskip("canopen")
    od = canopen.import_od(str(path), NODE_ID)
    out = {}
    for obj in od.values():
        for var in ([obj] if isinstance(obj, canopen.objectdictionary.ODVariable) else obj.values()):
            out[(var.index, var.subindex)] = var
    return out


@pytest.mark.parametrize("path", FILES, ids=lambda p: p.name)
def test_every_entry_as_python_canopen_reads_it(path: Path) -> None:
    ours = {(e.index, e.sub): e for e in eds.entries(path)}
    theirs = _theirs(path)
    assert set(ours) == set(theirs)
    for key, e in ours.items():
        v = theirs[key]
        assert e.dtype == v.data_type, key
        assert e.access.lower() == v.access_type.replace("rww", "rw").replace("rwr", "rw"), key
        if key[0] > 7:  # python-canopen leaves the dummy objects unmappable
            assert e.pdo == v.pdo_mappable, key
        want = v.value if v.value is not None else v.default
        got = e.value(NODE_ID)
        if want is None:
            continue
        if isinstance(got, int) and isinstance(want, int):  # python-canopen keeps hex defaults unsigned
            assert (got - want) % (1 << e.bits()) == 0, key
        elif isinstance(got, float):
            assert math.isclose(got, want), key
        else:
            assert got == want, key
        for mine, its in ((e.low, v.min), (e.high, v.max)):
            if its is not None:
                assert mine == its, key


def test_the_projects_own_drive() -> None:
    contract = {(0x1000, 0): (0x0007, "CONST", 0x00020192), (0x6076, 0): (0x0007, "RW", 1486),
                (0x608F, 1): (0x0007, "RW", 524288), (0x6091, 1): (0x0007, "RW", 101), (0x6060, 0): (0x0002, "RW", 0),
                (0x6071, 0): (0x0003, "RW", 0), (0x6041, 0): (0x0006, "RO", 0), (0x1A01, 1): (0x0007, "RW", 0x60770010)}
    d = eds.load(EDS)
    for (index, sub), (dtype, access, value) in contract.items():
        e = d.get(index, sub)
        assert e is not None and (e.dtype, e.access, e.default) == (dtype, access, value), (index, sub)
    assert d.get(0x1800, 1).nodeid_rel and d.get(0x1800, 1).value(NODE_ID) == 0x180 + NODE_ID


def test_every_basic_data_type_is_read(tmp_path: Path) -> None:
    """python-canopen's type catalogue holds an object of each CiA 301 basic type but the two times
    (0x000C TIME_OF_DAY, 0x000D TIME_DIFFERENCE, 6 bytes each), added here."""
    text = (REPO / "tests" / "drives" / "python_canopen_datatypes.eds").read_text()
    for index, dtype in ((0x2100, 0x000C), (0x2101, 0x000D)):
        text += f"\n[{index:04X}]\nParameterName=time\nObjectType=0x7\nDataType=0x{dtype:04X}\nAccessType=rw\n" \
                "DefaultValue=0x123456789ABC\nPDOMapping=1\n"
    (tmp_path / "types.eds").write_text(text)
    d = eds.load(tmp_path / "types.eds")
    assert {e.dtype for e in d.entries} >= set(eds.TYPES)
    assert d.get(0x2100).default == 0x123456789ABC and d.get(0x2100).bits() == 48
    table = eds.table_text(d)
    assert len(table.splitlines()) == len(d.entries) + 1


def test_a_dcf_s_parameter_value_wins_and_nodeid_is_evaluated(tmp_path: Path) -> None:
    epos4 = eds.load(REPO / "tests" / "drives" / "maxon_epos4_50_15.dcf")
    rated = epos4.get(0x6076)
    assert rated.configured and rated.default == 512871  # DefaultValue=0, ParameterValue=512871
    assert epos4.node_id == 1
    ipos = eds.load(REPO / "tests" / "drives" / "technosoft_ipos.eds")
    assert ipos.get(0x1800, 1).value(9) == 0x180 + 9  # $NODEID+0x180
    text = EDS.read_text().replace("DefaultValue=$NODEID+0x180", "DefaultValue=0x180 + $NODEID")
    (tmp_path / "front.eds").write_text(text)
    assert eds.load(tmp_path / "front.eds").get(0x1800, 1).value(9) == 0x189


def test_optional_objects_may_be_missing() -> None:
    """A drive without CiA 301's or 402's optional objects is a drive: the file says what it has."""
    e35 = eds.load(REPO / "tests" / "drives" / "python_canopen_e35.eds")
    assert not e35.has(0x1016) and e35.has(0x1006)
    epos4 = eds.load(REPO / "tests" / "drives" / "maxon_epos4_50_15.dcf")
    assert not epos4.has(0x1006) and not epos4.has(0x608F) and not epos4.has(0x6091)


def test_emits_the_table_and_the_builtin(tmp_path: Path) -> None:
    r = subprocess.run([sys.executable, "-m", "gen.eds", "--eds", str(EDS), "--out", str(tmp_path)], cwd=REPO,
                       capture_output=True, text=True)
    assert r.returncode == 0, r.stderr
    c = (tmp_path / "sim_co_od_builtin.c").read_text()
    n = len(eds.entries(EDS))
    assert f'"{eds.TABLE_MAGIC} {n}\\n"' in c and c.count('\\n"\n') == n + 1
    r = subprocess.run([sys.executable, "-m", "gen.eds", "--eds", str(EDS), "--table", str(tmp_path / "od.txt")],
                       cwd=REPO, capture_output=True, text=True)
    assert r.returncode == 0, r.stderr
    assert (tmp_path / "od.txt").read_text() == eds.table_text(eds.load(EDS))


def _mapping_over_64_bits(text: str) -> str:
    # TPDO1 (0x1A00) mapped to 0x6064 twice and 0x606C: 96 bits
    text = text.replace("[1A00sub0]\nParameterName=Number of mapped objects\nObjectType=0x7\nDataType=0x0005\n"
                        "AccessType=rw\nDefaultValue=2", "[1A00sub0]\nParameterName=Number of mapped objects\n"
                        "ObjectType=0x7\nDataType=0x0005\nAccessType=rw\nDefaultValue=3")
    return text.replace("[1A00sub3]\nParameterName=Mapped object 3\nObjectType=0x7\nDataType=0x0007\nAccessType=rw\n"
                        "DefaultValue=0x00000000", "[1A00sub3]\nParameterName=Mapped object 3\nObjectType=0x7\n"
                        "DataType=0x0007\nAccessType=rw\nDefaultValue=0x60640020")


BAD = [
    (lambda t: t.replace("DataType=0x0007", "DataType=0x0040", 1), "DataType=0x0040: not a CiA 301 basic data type"),
    (lambda t: t.replace("DataType=0x0007", "DataType=0x000E", 1), "DataType=0x000E: not a CiA 301 basic data type"),
    (lambda t: t.replace("DefaultValue=$NODEID+0x180", "DefaultValue=$NODEID*2"), "[1800sub1] DefaultValue=$NODEID*2: a $NODEID value is"),
    (lambda t: t.replace("DefaultValue=$NODEID+0x180", "DefaultValue=0x180-$NODEID"), "[1800sub1] DefaultValue=0x180-$NODEID"),
    (lambda t: t.replace("DefaultValue=$NODEID+0x180", "DefaultValue=$NODEID+$NODEID"), "a $NODEID value is"),
    (_mapping_over_64_bits, "[1A00] its mapping of 3 entries is 96 bits, more than the 64 of a CAN frame"),
    (lambda t: t.replace("[MandatoryObjects]", "[SomeObjects]"), "no [MandatoryObjects] section"),
    (lambda t: t.replace("AccessType=const", "AccessType=readonly", 1), "AccessType=readonly: expected ro, rw"),
    (lambda t: t.replace("DefaultValue=0x00020192", "DefaultValue=lots"), "[1000] DefaultValue=lots: not an integer"),
    (lambda t: t.replace("[6060]\nParameterName=Modes of operation\nObjectType=0x7\nDataType=0x0002\nAccessType=rw\n"
                         "DefaultValue=0", "[6060]\nParameterName=Modes of operation\nObjectType=0x7\nDataType=0x0002\n"
                         "AccessType=rw\nDefaultValue=300"), "[6060] DefaultValue=300: out of range for INTEGER8"),
    (lambda t: t + "\n[1000]\nParameterName=again\n", "section '1000' already exists"),
    (lambda t: "not an ini file\n" + t, "File contains no section headers"),
]


@pytest.mark.parametrize(("edit", "needle"), BAD, ids=[n for _, n in BAD])
def test_a_bad_file_is_one_line_exit_2_and_nothing_written(tmp_path: Path, edit, needle: str) -> None:  # noqa: ANN001
    bad = tmp_path / "bad.eds"
    text = edit(EDS.read_text())
    assert text != EDS.read_text()
    bad.write_text(text)
    out = tmp_path / "out"
    r = subprocess.run([sys.executable, "-m", "gen.eds", "--eds", str(bad), "--out", str(out)], cwd=REPO,
                       capture_output=True, text=True)
    assert r.returncode == 2 and needle in r.stderr and len(r.stderr.strip().splitlines()) == 1, r.stderr
    assert "Traceback" not in r.stderr
    assert not out.exists()  # nothing half-written


def _gen_eds(path: Path, out: Path) -> tuple[int, str]:
    err = io.StringIO()
    with contextlib.redirect_stderr(err):
        try:
            rc = eds.main(["--eds", str(path), "--table", str(out)])
        except SystemExit as exc:  # argparse: never reached with these arguments
            rc = int(exc.code or 0)
    return rc, err.getvalue()


TOKENS = ["$NODEID", "+", "0x", "-", "0", "1", "7", "8", "9", "A", "F", "FFFFFFFF", "10000000000000000", "1e999",
          "nan", "0x1B", "0x0E", "rw", "rww", "const", "[", "]", "=", ";", " ", "\t", "é", "\x00", "sub", "1600",
          "0x60640020"]
VALUE = st.one_of(st.text(max_size=12), st.lists(st.sampled_from(TOKENS), max_size=6).map("".join))


@settings(max_examples=200, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(source=st.sampled_from([EDS, VENDOR[2], VENDOR[4]]), edits=st.lists(
    st.tuples(st.integers(min_value=0), st.sampled_from(["value", "drop", "dup", "garbage"]), VALUE), min_size=1,
    max_size=4))
def test_any_mutated_file_is_read_or_one_line_never_a_traceback(tmp_path: Path, source: Path, edits: list) -> None:
    """Real files with random edits (a key's value replaced, a line dropped or doubled, garbage in):
    gen.eds writes the table or says what is wrong in one line, exit 2."""
    lines = source.read_text(encoding="utf-8", errors="replace").splitlines()
    for where, how, text in edits:
        k = where % len(lines)
        if how == "value" and "=" in lines[k]:
            lines[k] = lines[k].split("=", 1)[0] + "=" + text
        elif how == "drop":
            del lines[k]
        elif how == "dup":
            lines.insert(k, lines[k])
        else:
            lines.insert(k, text)
        if not lines:
            lines = [""]
    path = tmp_path / "mutated.eds"
    path.write_bytes("\n".join(lines).encode("utf-8", errors="surrogatepass"))
    out = tmp_path / "od.txt"
    out.unlink(missing_ok=True)
    rc, err = _gen_eds(path, out)
    assert rc in (0, 2), err
    if rc == 2:
        assert err.startswith("gen.eds: ") and len(err.strip().splitlines()) == 1 and err.strip().isprintable(), err
        assert not out.exists()
    else:
        assert out.read_text().startswith(eds.TABLE_MAGIC)
