"""tools/run/processes.py: the part of a HIL run that also runs inside the qemu VM (`hil --bus vm`).
Its entry point there reads the host's plan and writes the exit codes or the run's error; it
imports the standard library alone, since imports cost tens of seconds in the emulated machine.
(The run through it, in the VM: test_vcan_vm.py::test_hil_in_the_vm_through_the_cli.)"""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

from gen.lib.paths import REPO, env_with_repo, logger_binary
from tools.run.processes import ProcessPlan, plan_json
from tools.run.slots import LCM_GROUP, Slot


def _guest(tmp_path: Path, plan: ProcessPlan) -> dict:
    (tmp_path / "plan.json").write_text(plan_json(plan))
    r = subprocess.run([sys.executable, "-m", "tools.run.processes", str(tmp_path / "plan.json"),
                        str(tmp_path / "result.json")], cwd=REPO, env=env_with_repo(), capture_output=True, text=True,
                       timeout=120)
    assert r.returncode == 0, r.stdout + r.stderr
    return json.loads((tmp_path / "result.json").read_text())


def _plan(tmp_path: Path, slot: Slot, build_dir: Path, controller: list[str], simulator: list[str]) -> ProcessPlan:
    return ProcessPlan(out=str(tmp_path), mode="lockstep", cpu=0, deadline_s=60.0,
                       logger=[str(logger_binary(build_dir)), "--lcm-url", f"udpm://{LCM_GROUP}:{slot.lcm_port}?ttl=0",
                               str(tmp_path / "telemetry.lcmlog")],
                       simulator=simulator, controller=controller, cwd=str(REPO))


def test_a_refused_argument_comes_back_as_the_run_s_error(tmp_path: Path, slot: Slot, build_dir: Path,
                                                          controller_bin: Path) -> None:
    result = _guest(tmp_path, _plan(tmp_path, slot, build_dir, [str(controller_bin), "--duration", "-1"],
                                         ["sleep", "60"]))  # a simulator waiting on its bus: stopped
    assert set(result) == {"error"}
    assert result["error"].startswith("the controller refused its arguments: ") and "--duration" in result["error"]
    assert (tmp_path / "logger.log").exists() and (tmp_path / "controller.log").exists()


def test_exit_codes_and_the_simulator_s_scheduling_come_back(tmp_path: Path, slot: Slot, build_dir: Path,
                                                             controller_bin: Path) -> None:
    """The controller ends first (here: --help), then the simulator (here: a sleep)."""
    result = _guest(tmp_path, _plan(tmp_path, slot, build_dir, [str(controller_bin), "--help"], ["sleep", "0.5"]))
    assert result["exit_codes"]["controller"] == 0, result
    assert result["exit_codes"]["simulator"] == 0 and result["simulator_scheduling"].startswith("SCHED_OTHER")
    assert result["wall_s"] > 0


def test_the_guest_side_imports_no_heavy_module() -> None:
    code = ("import sys, tools.run.processes; "
            "print(sorted(m for m in ('numpy', 'mujoco', 'cvxpy', 'lcm', 'can') if m in sys.modules))")
    r = subprocess.run([sys.executable, "-c", code], cwd=REPO, env=env_with_repo(), capture_output=True, text=True)
    assert r.returncode == 0 and r.stdout.strip() == "[]", r.stdout + r.stderr
