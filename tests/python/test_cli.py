"""The CLI's one pattern (issue 20 item 5): every command module has add_subparser() and run(), one
map in tools/cli.py turns a command's exception into its exit code and message, and `hil --bus vm`
passes hil's own arguments on to the VM."""

from __future__ import annotations

import argparse
from pathlib import Path

import pytest

from tools import cli

from tools.run import procs
from tools.commands import CommandError, UsageError
from tools.commands import hil as hil_command


@pytest.fixture(autouse=True)
def _no_signal_handlers(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(procs, "install", lambda: None)  # main() installs them for a command's processes


def test_every_command_is_a_module_with_add_subparser_and_run() -> None:
    p = cli.parser()
    sub = next(a for a in p._actions if isinstance(a, argparse._SubParsersAction))  # noqa: SLF001
    assert list(sub.choices) == ["setup", "build", "cluster-certs", "timing", "hil", "demo", "test", "synth", "vcan",
                                 "busload", "study", "tune", "faults", "fuzz", "bench"]
    for name, parser in sub.choices.items():
        assert callable(parser.get_default("run")), name
    for module in cli._commands():  # noqa: SLF001
        assert callable(module.add_subparser), module.__name__


@pytest.mark.parametrize("args,code,message", [
    (["fuzz", "--seconds", "0"], 2, "armctl fuzz: --seconds: must be in [1, 86400]\n"),
    (["fuzz", "--only", "nope"], 2, "armctl fuzz: --only: unknown nope\n"),
    (["timing", "--duration", "0"], 2, "armctl timing: --duration: must be > 0, got 0.0\n"),
    (["busload", "--budget", "0"], 2, "armctl busload: --budget 0: must be in (0, 100] %\n"),
    (["vcan", "run"], 2, "armctl vcan run: no command; usage: armctl vcan run -- CMD [ARGS...]\n"),
    (["hil", "--ref-hold", "-1"], 2, "armctl hil: --ref-hold: must be in [0, 3600] s, got -1.0\n"),
    (["hil", "--ref-amp", "0.1"], 2, "armctl hil: --ref-amp and --ref-freq go together\n"),
    (["hil", "--seed", "3"], 2, "armctl hil: --seed: one run of a study: give --scenario\n"),
    (["hil", "--scenario", "x", "--tuned", "pm", "--knobs", "{}"], 2, "armctl hil: --tuned and --knobs: give one\n"),
    (["faults", "--only", "nope"], 2, "armctl faults: --only: unknown fault(s) nope\n"),
])
def test_bad_input_exits_through_the_one_map(capsys: pytest.CaptureFixture[str], args: list[str], code: int,
                                             message: str) -> None:
    assert cli.main(args) == code
    assert capsys.readouterr().err == message


def _ns(command: str, **kw: object) -> argparse.Namespace:
    return argparse.Namespace(command=command, **kw)


@pytest.mark.parametrize("exc,code,message", [
    (procs.Interrupted(15), 143, "armctl study: interrupted (stopped by signal 15); no process of this command is "
                                 "left running\n"),
    (CommandError("FAILED (ctest)"), 1, "armctl study: FAILED (ctest)\n"),
    (CommandError("odd", 5), 5, "armctl study: odd\n"),
    (UsageError("--x: bad"), 2, "armctl study: --x: bad\n"),
    (PermissionError(13, "Permission denied"), 1, "armctl study: [Errno 13] Permission denied\n"),
])
def test_the_map(capsys: pytest.CaptureFixture[str], exc: BaseException, code: int, message: str) -> None:
    assert cli.exit_code(exc, _ns("study")) == code
    assert capsys.readouterr().err == message


def test_the_map_by_library_exception(capsys: pytest.CaptureFixture[str]) -> None:
    from gen.lib.atomic_output import OutputError
    from gen.lib.outdir import OutDirError
    from tools.build.arm import ArmChoiceError
    from tools.build import BuildError
    from tools.run.cluster import ClusterError
    from tools.run.hil import HilError
    from tools.study.config import StudyConfigError
    from tools.vm.image import VmError

    for exc, code in ((StudyConfigError("s"), 2), (ArmChoiceError("a"), 2), (OutDirError("o"), 2),
                      (ClusterError("c"), 2), (HilError("h"), 1), (OutputError("w"), 1), (VmError("v"), 1)):
        assert cli.exit_code(exc, _ns("tune")) == code, exc
        assert capsys.readouterr().err == f"armctl tune: {exc}\n"
    assert cli.exit_code(BuildError("cmake --build failed (log: x)"), _ns("build")) == 1
    assert capsys.readouterr().err == "cmake --build failed (log: x)\n"  # it names itself
    # A command's own prefix and codes: vcan's subcommands, and the VM it cannot set up (3).
    vm = _ns("vcan", prefix="armctl vcan setup", exit_codes={VmError: 3})
    assert cli.exit_code(VmError("no qemu"), vm) == 3
    assert capsys.readouterr().err == "armctl vcan setup: no qemu\n"
    assert cli.exit_code(ValueError("a bug"), _ns("study")) is None  # not in the map: its traceback


def test_vcan_subcommands_name_themselves() -> None:
    from tools.vm.image import VmError

    ns = cli.parser().parse_args(["vcan", "setup"])
    assert ns.prefix == "armctl vcan setup" and ns.exit_codes == {VmError: 3}


def test_a_bug_keeps_its_traceback() -> None:
    def run(ns: argparse.Namespace) -> int:
        raise ZeroDivisionError

    with pytest.raises(ZeroDivisionError):
        cli.run_command(_ns("x", run=run))


@pytest.fixture()
def hil_parser() -> argparse.ArgumentParser:
    cli.parser()  # makes hil's
    assert hil_command._PARSER is not None  # noqa: SLF001
    return hil_command._PARSER  # noqa: SLF001


def test_hil_in_the_vm_gets_its_own_arguments(hil_parser: argparse.ArgumentParser, tmp_path: Path) -> None:
    args = ["--duration", "2", "--bus", "vm", "--method", "lqr", "--out", "runs/x", "--ref-amp", "-0.1,0.2",
            "--ref-freq", "0.5,0.5", "--bus-timing", "--top=buses.toml", "--model", "../arm.xml",
            "--arm", "/abs/panda.toml", "--max-error-deg", "3", "--capture"]
    assert hil_command.vm_argv(args, hil_parser, tmp_path) == [
        "--duration", "2", "--bus", "vcan", "--method", "lqr", "--out", str(tmp_path / "runs" / "x"),
        "--ref-amp", "-0.1,0.2", "--ref-freq", "0.5,0.5", "--bus-timing",
        f"--top={tmp_path / 'buses.toml'}", "--model", str((tmp_path / ".." / "arm.xml").resolve()),
        "--arm", "/abs/panda.toml", "--max-error-deg", "3", "--capture"]


@pytest.mark.parametrize("given,inner", [
    (["--bus=vm"], ["--bus=vcan"]),
    (["--bus", "udp", "--bus", "vm"], ["--bus", "udp", "--bus", "vcan"]),
    (["--design", "d"], ["--design", "/w/d"]),
    (["--bus-timing", "--bus", "vm"], ["--bus-timing", "--bus", "vcan"]),
    ([], []),
])
def test_hil_in_the_vm_rewrites_only_bus_and_paths(hil_parser: argparse.ArgumentParser, given: list[str],
                                                   inner: list[str]) -> None:
    assert hil_command.vm_argv(given, hil_parser, Path("/w")) == inner


def test_hil_in_the_vm_reads_the_arguments_main_was_given(monkeypatch: pytest.MonkeyPatch, tmp_path: Path) -> None:
    from tools.build import arm
    from tools.vm import run as vm_run

    seen: dict[str, object] = {}

    class Done:
        returncode = 7

    def run_in_vm(argv: list[str], timeout: float, keep: bool) -> Done:
        seen.update(argv=argv, timeout=timeout)
        return Done()

    monkeypatch.setattr(arm, "build_arm", lambda *a, **k: tmp_path)
    monkeypatch.setattr(vm_run, "run_in_vm", run_in_vm)
    monkeypatch.chdir(tmp_path)
    assert cli.main(["hil", "--bus", "vm", "--duration", "1", "--out", "o"]) == 7
    assert seen == {"argv": ["tools/armctl", "hil", "--bus", "vcan", "--duration", "1", "--out", str(tmp_path / "o")],
                    "timeout": 4200.0}
