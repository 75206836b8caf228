"""The CLI's one pattern (issue 20 item 5): every command module has add_subparser() and run(), one
map in tools/cli.py turns a command's exception into its exit code and message, and a command
imports its own module alone."""

from __future__ import annotations

import argparse

import pytest

from tools import cli

from tools.run import procs
from tools.commands import CommandError, UsageError


@pytest.fixture(autouse=True)
def _no_signal_handlers(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(procs, "install", lambda: None)  # main() installs them for a command's processes


def test_every_command_is_a_module_with_add_subparser_and_run() -> None:
    p = cli.parser()
    sub = next(a for a in p._actions if isinstance(a, argparse._SubParsersAction))  # noqa: SLF001
    assert list(sub.choices) == ["setup", "build", "cluster-certs", "timing", "hil", "plant", "commission", "run", "identify",
                                 "demo", "test", "synth", "vcan",
                                 "busload", "drive", "study", "tune", "faults", "fuzz", "bench", "docs", "arms", "render",
                                 "export", "lock"]
    for name, parser in sub.choices.items():
        assert callable(parser.get_default("run")), name
    for module in cli._commands():  # noqa: SLF001
        assert callable(module.add_subparser), module.__name__
    assert list(cli.COMMAND_MODULES) == list(sub.choices)


@pytest.mark.parametrize("command", list(cli.COMMAND_MODULES))
def test_a_command_s_parser_is_its_module_s_alone(command: str) -> None:
    """`armctl CMD` builds CMD's parser from CMD's module alone (what the table says), and parses
    the same as the whole parser."""
    p = cli.parser(command)
    sub = next(a for a in p._actions if isinstance(a, argparse._SubParsersAction))  # noqa: SLF001
    registered_by = {name for name, module in cli.COMMAND_MODULES.items() if module == cli.COMMAND_MODULES[command]}
    assert set(sub.choices) == registered_by
    whole = next(a for a in cli.parser()._actions if isinstance(a, argparse._SubParsersAction))  # noqa: SLF001
    assert sub.choices[command].format_help() == whole.choices[command].format_help()


def test_a_light_command_imports_no_heavy_module() -> None:
    """`armctl vcan` (run inside the slow VM too) does not pay for MuJoCo, numpy or cvxpy."""
    import subprocess
    import sys

    from gen.lib.paths import REPO, env_with_repo

    code = ("import sys; from tools import cli; cli.parser('vcan'); "
            "print(sorted(m for m in ('mujoco', 'numpy', 'cvxpy', 'scipy') if m in sys.modules))")
    r = subprocess.run([sys.executable, "-c", code], cwd=REPO, env=env_with_repo(), capture_output=True, text=True)
    assert r.returncode == 0 and r.stdout.strip() == "[]", r.stdout + r.stderr


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


def test_only_a_results_record_renders_the_docs(monkeypatch: pytest.MonkeyPatch, tmp_path) -> None:
    """`--record` (store_true: results kept for the docs) renders the docs after the command; `run`,
    `commission` and `identify` name a commissioning record FILE with `--record`: that renders nothing
    (it once re-rendered every page after each rehearsal step: a minute a command in the qemu VM)."""
    import tools.commands.docs as docs

    rendered: list[str] = []
    monkeypatch.setattr(docs, "render", lambda skipped: rendered.append("render"))
    assert cli.run_command(_ns("run", run=lambda ns: 0, record=tmp_path / "record.json")) == 0
    assert rendered == []
    assert cli.run_command(_ns("timing", run=lambda ns: 0, record=True)) == 0
    assert rendered == ["render"]
