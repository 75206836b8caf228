"""Hostile and unlucky input (issue 24, items 8-13): a full or read-only disk under --out, hostile
arm models and TOML nested without end. Each gives one line naming the path or element, a
non-zero exit (2 for bad input), no traceback, and nothing half-written: no temporary file, no
build folder."""

from __future__ import annotations

import pickle
import subprocess
from collections.abc import Iterator
from pathlib import Path

import pytest

from gen.lib.atomic_output import OutputError, write_files_atomically, write_json_atomic
from gen.lib.paths import REPO

ARMCTL = str(REPO / "tools" / "armctl")


def armctl(*args: str, timeout: float = 300) -> subprocess.CompletedProcess[str]:
    return subprocess.run([ARMCTL, *args], cwd=REPO, capture_output=True, text=True, timeout=timeout)


def one_line_error(r: subprocess.CompletedProcess[str], code: int, *named: str) -> str:
    assert r.returncode == code, (r.returncode, r.stdout, r.stderr)
    assert "Traceback" not in r.stderr, r.stderr
    lines = [ln for ln in r.stderr.splitlines() if ln.strip() and not ln.startswith("armctl: ")]
    assert len(lines) == 1, r.stderr
    for n in named:
        assert n in lines[0], lines[0]
    return lines[0]


def leftovers(d: Path) -> list[str]:
    return sorted(str(p.relative_to(d)) for p in d.rglob("*") if ".tmp" in p.name or p.name.startswith(".tmp-"))


# ---- a full disk, a read-only disk ----------------------------------------------------------
def _mount_tmpfs(where: Path, size: str) -> None:
    where.mkdir(parents=True, exist_ok=True)
    r = subprocess.run(["mount", "-t", "tmpfs", "-o", f"size={size}", "tmpfs", str(where)],
                       capture_output=True, text=True)
    if r.returncode != 0:
        pytest.skip(f"cannot mount a tmpfs here (needs root): {r.stderr.strip()}")


@pytest.fixture()
def full_disk(tmp_path: Path) -> Iterator[Path]:
    """A 2 MB tmpfs with no byte left: the next write of any size fails with ENOSPC."""
    d = tmp_path / "full"
    _mount_tmpfs(d, "2m")
    try:
        with open(d / "filler", "wb") as fh:
            try:
                while True:
                    fh.write(b"\0" * 65536)
                    fh.flush()
            except OSError:
                pass
        yield d
    finally:
        subprocess.run(["umount", "-l", str(d)], check=False)


@pytest.fixture()
def read_only_disk(tmp_path: Path) -> Iterator[Path]:
    """A tmpfs remounted read-only: every write fails with EROFS (as root, too)."""
    d = tmp_path / "ro"
    _mount_tmpfs(d, "2m")
    try:
        (d / "old.json").write_text("{}\n")
        r = subprocess.run(["mount", "-o", "remount,ro", str(d)], capture_output=True, text=True)
        if r.returncode != 0:
            pytest.skip(f"cannot remount the tmpfs read-only: {r.stderr.strip()}")
        yield d
    finally:
        subprocess.run(["umount", "-l", str(d)], check=False)


def test_the_writer_on_a_full_disk_names_the_path_and_leaves_no_temporary_file(full_disk: Path) -> None:
    with pytest.raises(OutputError) as e:
        write_json_atomic(full_disk / "run.json", {"x": "y" * 100_000})
    assert str(e.value) == f"cannot write {full_disk / 'run.json'}: No space left on device"
    assert str(pickle.loads(pickle.dumps(e.value))) == str(e.value)  # it crosses to and from a study's workers
    with pytest.raises(OutputError) as e:
        write_files_atomically(full_disk / "gen", {"a.h": "int x;\n" * 10_000, "manifest.json": "{}\n"})
    assert str(e.value) == f"cannot write {full_disk / 'gen' / 'a.h'}: No space left on device"
    assert sorted(p.name for p in full_disk.iterdir()) == ["filler"]  # no temp file, no half-made folder


def test_the_writer_on_a_read_only_disk_keeps_the_old_file(read_only_disk: Path) -> None:
    with pytest.raises(OutputError) as e:
        write_json_atomic(read_only_disk / "old.json", {"new": True})
    assert str(e.value) == f"cannot write {read_only_disk / 'old.json'}: Read-only file system"
    assert (read_only_disk / "old.json").read_text() == "{}\n"
    with pytest.raises(OutputError, match="Read-only file system"):
        write_files_atomically(read_only_disk / "gen", {"a.h": "x"})
    assert sorted(p.name for p in read_only_disk.iterdir()) == ["old.json"]


@pytest.mark.parametrize(("protocol", "first"), [("canopen", "canopen.dbc"), ("arm", "run.json")])
def test_hil_on_a_full_disk_is_one_line_and_leaves_no_temporary_file(full_disk: Path, protocol: str,
                                                                     first: str) -> None:
    """The first file a run writes names the failure: a CANopen run's DBC, before it starts, or the
    arm protocol's run.json after it."""
    r = armctl("hil", "--protocol", protocol, "--duration", "0.3", "--out", str(full_disk))
    one_line_error(r, 1, f"cannot write {full_disk / first}", "No space left on device")
    assert leftovers(full_disk) == []
    assert not (full_disk / "run.json").exists()


def test_synth_on_a_full_disk_is_one_line_and_leaves_no_temporary_file(full_disk: Path) -> None:
    out = full_disk / "design"
    r = armctl("synth", "--out", str(out))
    one_line_error(r, 1, f"cannot write {out}", "No space left on device")
    assert sorted(p.name for p in full_disk.iterdir()) == ["filler"]


def test_a_read_only_out_is_refused_before_any_work(read_only_disk: Path) -> None:
    for cmd in (["synth"], ["hil", "--duration", "0.3"]):
        r = armctl(*cmd, "--out", str(read_only_disk / "o"))
        one_line_error(r, 2, "--out", "Read-only file system")
    assert sorted(p.name for p in read_only_disk.iterdir()) == ["old.json"]


@pytest.mark.parametrize("module,args", [
    ("gen.robot_model", []),
    ("gen.rnea_kernel", ["--mjcf", str(REPO / "host_sim" / "models" / "ur5e_arm.xml")]),
    ("gen.drive_ids", ["--dbc", str(REPO / "firmware" / "protocol" / "arm_drives.dbc")]),
    ("gen.eds", ["--eds", str(REPO / "firmware" / "protocol" / "cia402_servo.eds")]),
    ("gen.params", []),
])
def test_a_build_step_generator_on_a_read_only_disk_is_one_line(read_only_disk: Path, module: str,
                                                                 args: list[str]) -> None:
    """Inside CMake a generator's traceback would bury the reason in the build's log."""
    out = read_only_disk / "gen"
    r = subprocess.run([str(REPO / ".venv" / "bin" / "python"), "-m", module, *args, "--out", str(out)],
                       cwd=REPO, capture_output=True, text=True, timeout=120)
    one_line_error(r, 1, f"{module}: cannot write {out}", "Read-only file system")
    assert sorted(p.name for p in read_only_disk.iterdir()) == ["old.json"]


# ---- TOML nested without end ----------------------------------------------------------------
def test_toml_nesting_is_bounded_at_the_stated_limit() -> None:
    from gen.lib.toml_input import MAX_NESTING, TomlNestingError, loads

    assert loads("x = " + "[" * MAX_NESTING + "]" * MAX_NESTING)["x"] is not None
    for text in ("x = " + "[" * (MAX_NESTING + 1) + "]" * (MAX_NESTING + 1),  # parses, but too deep
                 "x = " + "[" * 3000 + "]" * 3000,  # RecursionError inside tomllib
                 "a" + ".a" * (MAX_NESTING + 1) + " = 1",  # dotted keys: tables without recursion
                 "x = " + "{a = " * 3000 + "1" + "}" * 3000):
        with pytest.raises(TomlNestingError, match=f"nested deeper than {MAX_NESTING} levels"):
            loads(text)


DEEP = "x = " + "[" * 3000 + "]" * 3000 + "\n"


@pytest.mark.parametrize("args", [
    ["hil", "--arm", "{f}"], ["hil", "--design", "{f}"], ["hil", "--topology", "{f}"],
    ["study", "--config", "{f}"], ["synth", "--config", "{f}", "--out", "{d}/o"],
    ["busload", "--topology", "{f}"],
])
def test_a_3000_deep_toml_is_one_line_naming_the_file(tmp_path: Path, args: list[str]) -> None:
    f = tmp_path / "deep.toml"
    f.write_text(('model = "arm.xml"\n' if "--arm" in args else "") + DEEP)
    r = armctl(*[a.format(f=f, d=tmp_path) for a in args])
    one_line_error(r, 2, str(f), "nested deeper than 32 levels")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["deep.toml"]


# ---- hostile arm models ---------------------------------------------------------------------
def _chain(n: int = 3, inner: str = "", joint0: str = 'range="-2 2"', l1_pos: str = "0 0 0.2", model: str = "chain",
           assets: str = "") -> str:
    """A serial chain of hinge links with masses and motors (tests/python/test_arm_import.py's
    shape), with one thing swapped in by each case."""
    body = inner
    for i in reversed(range(n)):
        rng = joint0 if i == 0 else 'range="-2 2"'
        pos = l1_pos if i == 1 else "0 0 0.2"
        body = (f'<body name="l{i}" pos="{pos}"><joint name="j{i}" axis="0 0 1" {rng}/>'
                f'<inertial pos="0 0 0.1" mass="1" diaginertia="0.01 0.01 0.01"/>{body}</body>')
    acts = "".join(f'<motor joint="j{i}" ctrlrange="-50 50"/>' for i in range(n))
    return (f'<mujoco model="{model}"><compiler angle="radian" autolimits="true"/>{assets}<worldbody>{body}'
            f'</worldbody><actuator>{acts}</actuator></mujoco>')


def _stl(faces: int) -> bytes:
    return bytes(80) + faces.to_bytes(4, "little") + (bytes(12) + bytes.fromhex("0000803f" "00" * 8) * 3
                                                      + bytes(2)) * faces


FIXED_484 = "".join(f'<body name="f{i}"><inertial pos="0 0 0" mass="0.1" diaginertia="0.01 0.01 0.01"/>'
                    for i in range(484)) + "</body>" * 484

HOSTILE_MODELS = {
    "swapped-range": (lambda d: _chain(joint0='range="3.1416 -3.1416"'),
                      ["joint 'j0': range [3.1416, -3.1416]", "range[0] < range[1]"]),
    "unbounded-range": (lambda d: _chain(joint0='range="1e308 -1e308"'), ["joint 'j0': range [1e+308, -1e+308]"]),
    "nan-body-pos": (lambda d: _chain(l1_pos="nan 0 0.2"), ["body 'l1': pos=\"nan 0 0.2\" is not finite"]),
    "mass-over-float32": (lambda d: _chain().replace('mass="1"', 'mass="1e39"', 1),
                          ["body 'l0': mass: 1e+39 is not a finite float32"]),
    "non-utf8-joint-name": (lambda d: _chain().replace('name="j1"', 'name="j\xe9"').encode("latin-1"),
                            ['<joint name="j\\xe9', "not UTF-8"]),
    "non-utf8-model-name": (lambda d: _chain(model="ch\xe9in").encode("latin-1"), ['model="ch\\xe9', "not UTF-8"]),
    "484-fixed-bodies": (lambda d: _chain(6, inner=FIXED_484), ["nested 257 elements deep, more than 256"]),
    "mesh-over-face-limit": (lambda d: (d / "hull.stl").write_bytes(_stl(200_001)) and _chain(
        inner='<geom type="mesh" mesh="hull"/>', assets='<asset><mesh name="hull" file="hull.stl"/></asset>'),
        ["MuJoCo cannot take", "number of faces should be between 1 and 200000", "'hull'"]),
}


@pytest.mark.parametrize("case", sorted(HOSTILE_MODELS))
def test_a_hostile_model_is_one_line_naming_the_element_and_nothing_is_built(tmp_path: Path, case: str) -> None:
    from tools.build.arm import ArmRef
    from gen.lib.paths import BUILD

    make, named = HOSTILE_MODELS[case]
    text = make(tmp_path)
    model = tmp_path / "arm.xml"
    model.write_bytes(text if isinstance(text, bytes) else text.encode())
    r = armctl("hil", "--model", str(model), "--duration", "0.3", "--out", str(tmp_path / "out"))
    one_line_error(r, 2, str(model), *named)
    assert not (BUILD / "arms" / ArmRef(model.resolve()).key()).exists()
    assert not (tmp_path / "out").exists()


def test_a_torque_limit_beyond_float32_in_the_arm_file_is_refused_up_front(tmp_path: Path) -> None:
    (tmp_path / "arm.xml").write_text(_chain())
    arm = tmp_path / "arm.toml"
    arm.write_text('model = "arm.xml"\ntorque_limits = { j1 = 1e308 }\n')
    r = armctl("build", "--arm", str(arm))
    one_line_error(r, 2, f"arm file {arm}: torque_limits.j1: 1e+308 is not a finite float32")


def test_fixed_body_chains_are_walked_without_recursion() -> None:
    """240 fixed bodies below six hinges: inside the limit, and the chain is found by a loop
    (the old recursive walk hit Python's recursion limit at a few hundred)."""
    import sys

    from gen.arm import ArmFile, DEFAULT_DESIGN, prepare

    inner = "".join(f'<body name="f{i}"><inertial pos="0 0 0" mass="0.1" diaginertia="0.01 0.01 0.01"/>'
                    for i in range(240)) + "</body>" * 240
    old = sys.getrecursionlimit()
    sys.setrecursionlimit(300)  # below the chain's depth: any recursion over the bodies would fail
    try:
        import tempfile

        with tempfile.TemporaryDirectory() as d:
            model = Path(d) / "arm.xml"
            model.write_text(_chain(6, inner=inner))
            info = prepare(ArmFile(None, None, model), DEFAULT_DESIGN).info
    finally:
        sys.setrecursionlimit(old)
    assert info["n_joints"] == 6


def test_an_output_is_as_readable_as_any_file_this_process_makes(tmp_path: Path) -> None:
    """The writer's temporary file (mkstemp: 0600) must not leave the output unreadable to others."""
    import os

    from gen.lib.atomic_output import write_text_atomic

    mask = os.umask(0o022)
    try:
        write_text_atomic(tmp_path / "out.json", "{}\n")
    finally:
        os.umask(mask)
    assert (tmp_path / "out.json").stat().st_mode & 0o777 == 0o644
