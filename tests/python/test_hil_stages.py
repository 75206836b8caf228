"""A HIL run's stages before anything starts (tools/run/hil.py _run_hil): validate, resolve the
wiring, locate the programs, prepare the run folder, build the command lines. Each is tested here
without starting a process: only the build folder's arm.json and the drive table's files are read."""

from __future__ import annotations

from pathlib import Path

import pytest

from gen.lib.paths import REPO
from tools.build.arm import ArmChoiceError, arm_info
from tools.run import hil
from tools.run.hil import SIL, HilError, HilOptions
from tools.run.run_files import CONTROLLER_SUMMARY, RUN_RECORD, TELEMETRY_LOG

DRIVES = REPO / "firmware" / "protocol" / "drives.toml"


@pytest.fixture(scope="module")
def info(build_dir: Path) -> dict:
    try:
        return arm_info(build_dir)
    except ArmChoiceError:
        pytest.skip(f"{build_dir}: no arm.json (run tools/armctl build --preset debug)")


def _drive_table(tmp_path: Path, heartbeat_ms: int) -> Path:
    """The bundled drive table with another heartbeat, its EDS named by an absolute path."""
    text = DRIVES.read_text().replace("heartbeat_ms = 100", f"heartbeat_ms = {heartbeat_ms}")
    text = text.replace('eds = "', f'eds = "{DRIVES.parent}/')
    assert f"heartbeat_ms = {heartbeat_ms}" in text
    path = tmp_path / "drives.toml"
    path.write_text(text)
    return path


def test_validate_refuses_software_in_the_loop_in_realtime(tmp_path: Path) -> None:
    with pytest.raises(HilError, match=r"^--bus sil: .* lockstep only"):
        hil._validate(HilOptions(out=tmp_path, bus=SIL, mode="realtime"))
    assert hil._validate(HilOptions(out=tmp_path, bus=SIL)) is True


def test_the_wiring_names_a_bad_protocol_and_brakes(tmp_path: Path, info: dict) -> None:
    with pytest.raises(HilError, match=r"^--protocol nope: expected one of arm, canopen"):
        hil._resolve_wiring(HilOptions(out=tmp_path, protocol="nope"), info)
    with pytest.raises(HilError, match=r"^brakes: 'loose': expected one of"):
        hil._resolve_wiring(HilOptions(out=tmp_path, protocol="arm", brakes="loose"), info)


def test_a_drive_tables_heartbeat_reaches_the_controllers_command_line(tmp_path: Path, info: dict,
                                                                        build_dir: Path) -> None:
    """The stages from the options to the command lines: the drive table's heartbeat is on the
    controller's, its dictionary and decoder in the run folder, an earlier run's record gone."""
    out = tmp_path / "run"
    opt = HilOptions(out=out, protocol="canopen", bus="udp", drive_config=_drive_table(tmp_path, 250))
    wiring = hil._resolve_wiring(opt, info)
    assert wiring.canopen and wiring.drive_table.heartbeat_ms == 250
    programs = hil._Programs(binary=Path("/bin/true"), logger=Path("/bin/true"), sim=Path("/bin/true"),
                             sil=Path("/bin/true"))
    out.mkdir()
    (out / RUN_RECORD).write_text("{}")  # an earlier run's
    hil._prepare_out(opt, wiring)
    assert not (out / RUN_RECORD).exists()
    assert (out / hil.CANOPEN_DBC_FILE).is_file() and (out / hil.CANOPEN_OD_FILE).is_file()
    lines = hil._command_lines(opt, info, build_dir, wiring, programs, 43000, 7700, sil=False)
    ctl = lines.ctl_args
    assert ctl[ctl.index("--heartbeat-ms") + 1] == "250"
    assert ctl[ctl.index("--summary") + 1] == str(out / CONTROLLER_SUMMARY)
    assert lines.sim_args[lines.sim_args.index("--od") + 1] == str(out / hil.CANOPEN_OD_FILE)
    assert lines.log_path == out / TELEMETRY_LOG
    assert lines.buses and all(b.startswith("udp:") for b in lines.buses)


def test_a_missing_program_is_named(tmp_path: Path, build_dir: Path) -> None:
    missing = tmp_path / "arm_controller"
    with pytest.raises(HilError, match=rf"^{missing} is missing: run tools/armctl build"):
        hil._locate_programs(HilOptions(out=tmp_path, controller=missing), build_dir, sil=False)
