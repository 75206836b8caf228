"""The rehearsal of your arm on real SocketCAN: vcan0..vcan2 inside the qemu VM (tools/vm), one boot
for all of it. `armctl plant --bus vcan` (a process of its own), then `armctl commission`,
`armctl run --hold` for 5 s, `--jog`, the built-in reference, a trajectory file and `--hold` ended by
Ctrl-C, each through the documented command, inside the VM on this very checkout; then an
interface that is down, refused in one line before anything starts (one that does not exist is
test_run_on_arm.py's, on this machine).

Inside the VM programs run about 10x slower than here (20-260x under load, tools/vm/README.md):
the rehearsal is lockstep (the plant steps on the controller's SYNC), so it takes longer but ends
the same. One boot; 643 s on the 2-core machine, alone on it: about 400 s are the rehearsal's 40
simulated seconds at 1 kHz over three vcan buses (commissioning alone is 24 of them), about 180 s
the eight armctl start-ups (Python, MuJoCo, the build's check) in the emulated machine. Skipped
(with the reason) only if the VM cannot be set up on this machine."""

from __future__ import annotations

import json
import math
import sys
from pathlib import Path

import pytest

from gen.lib.paths import REPO, env_with_repo

pytestmark = pytest.mark.long

VM_TIMEOUT_S = 2400.0
MOVED_AFTER_STOP_DEG = 1.0
HOME = [0.0, -1.3, 1.6, -1.87, -1.5708, 0.0]
NAMES = ["shoulder_pan", "shoulder_lift", "elbow", "wrist_1", "wrist_2", "wrist_3"]

VM_SCRIPT = r"""#!/bin/bash
# Runs inside the VM, chrooted into the host's filesystem (tests/python/test_run_on_arm_vm.py).
OUT=$1; TRAJ=$2
A=tools/armctl
ip route replace 239.255.76.67/32 dev lo   # the controller's telemetry stays on lo, as on the host
ip route replace 239.74.163.0/24 dev lo
wait_for() {  # wait_for FILE TEXT SECONDS: until FILE says TEXT, at most SECONDS (the wall clock's)
    local t0=$SECONDS
    until grep -q "$2" "$1" 2>/dev/null; do sleep 0.5; [ $((SECONDS - t0)) -ge "$3" ] && return 1; done
    return 0
}
$A plant --bus vcan --out "$OUT/plant" > "$OUT/plant.out" 2>&1 &
PLANT=$!
wait_for "$OUT/plant.out" "waiting for a master" 900 || echo "no plant" > "$OUT/plant.failed"
R="--bus vcan --record $OUT/record.json"
$A commission $R --out "$OUT/commission" > "$OUT/commission.out" 2>&1; echo $? > "$OUT/commission.rc"
$A run --hold --duration 5 $R --out "$OUT/hold" > "$OUT/hold.out" 2>&1; echo $? > "$OUT/hold.rc"
$A run --jog elbow=5 $R --out "$OUT/jog" > "$OUT/jog.out" 2>&1; echo $? > "$OUT/jog.rc"
$A run --duration 1 $R --out "$OUT/reference" > "$OUT/reference.out" 2>&1; echo $? > "$OUT/reference.rc"
$A run "$TRAJ" $R --out "$OUT/trajectory" > "$OUT/trajectory.out" 2>&1; echo $? > "$OUT/trajectory.rc"
$A run --hold $R --out "$OUT/stop" > "$OUT/stop.out" 2>&1 &
RUN=$!
wait_for "$OUT/stop/controller.log" "hold: holding" 900
sleep 2
kill -INT $RUN   # Ctrl-C
wait $RUN; echo $? > "$OUT/stop.rc"
# the plant watches the arm for 2 s after the stop: until its record of the last session is final
settled() {
    python3 -c "import json, sys; s = json.load(open('$OUT/plant/sessions.json'))['sessions']
sys.exit(0 if len(s) >= 6 and s[-1]['complete'] else 1)" 2>/dev/null
}
t0=$SECONDS; until settled; do sleep 1; [ $((SECONDS - t0)) -ge 600 ] && break; done
kill -INT $PLANT; wait $PLANT; echo $? > "$OUT/plant.rc"
# a bus that is down
ip link add dev vcan9 type vcan
$A run --hold --bus socketcan:vcan0,vcan1,vcan9 --record "$OUT/record.json" > "$OUT/down.out" 2>&1
echo $? > "$OUT/down.rc"
exit 0
"""


@pytest.fixture(scope="module")
def vm(tmp_path_factory: pytest.TempPathFactory) -> Path:
    from tools.vm.image import APT_HINT, VmError, ensure_image, missing_tools
    from tools.vm.run import run_in_vm

    missing = missing_tools()
    if missing:
        pytest.skip(f"the VM needs {', '.join(missing)} ({APT_HINT})")
    try:
        ensure_image(log=lambda m: None)
    except VmError as exc:
        pytest.skip(f"the VM cannot be set up here: {exc}")
    out = tmp_path_factory.mktemp("run_on_arm_vm")
    script = out / "vm.sh"
    script.write_text(VM_SCRIPT)
    traj = out / "traj.csv"
    lines = ["t," + ",".join(NAMES)]
    for k in range(41):
        t = 2.0 * k / 40
        s = 0.5 * (1 - math.cos(math.pi * t))
        q = [h + a * s for h, a in zip(HOME, [0.2, 0.1, -0.2, 0.1, 0.2, 0.2])]
        lines.append(",".join(f"{x:.6f}" for x in [t, *q]))
    traj.write_text("\n".join(lines) + "\n")
    with open(out / "vm.log", "w") as log:
        res = run_in_vm(["bash", str(script), str(out), str(traj)], cwd=REPO, env=env_with_repo(),
                        timeout=VM_TIMEOUT_S, stdout=log, stderr=log)
    assert res.returncode == 0 and not res.timed_out, (out / "vm.log").read_text()[-3000:]
    print(f"run_on_arm_vm: boot {res.boot_s} s, rehearsal {res.command_s} s", file=sys.stderr)
    return out


def _rc(out: Path, name: str) -> int:
    return int((out / f"{name}.rc").read_text())


def _text(out: Path, name: str) -> str:
    return (out / f"{name}.out").read_text()


def test_the_rehearsal_on_vcan_ends_as_asked(vm: Path) -> None:
    assert not (vm / "plant.failed").exists(), _text(vm, "plant")
    cm = _text(vm, "commission")
    assert _rc(vm, "commission") == 0 and "armctl commission: passed" in cm, cm
    for name in ("hold", "jog", "reference", "trajectory"):
        assert _rc(vm, name) == 0, _text(vm, name)
        s = json.loads((vm / name / "session.json").read_text())
        assert s["task_report"]["ended"] and s["buses"][0].startswith("socketcan:vcan0@"), s
        assert max(s["tracking"]["max_abs_deg"].values()) < 1.0, (name, s["tracking"])


def test_ctrl_c_on_vcan_stops_the_arm_and_it_stays(vm: Path) -> None:
    assert _rc(vm, "stop") == 0 and "stopped by you" in _text(vm, "stop"), _text(vm, "stop")
    plant = json.loads((vm / "plant" / "sessions.json").read_text())
    sessions = plant["sessions"]
    assert len(sessions) == 6 and all(s["ended"] == "stopped" for s in sessions), sessions
    stop = json.loads((vm / "stop" / "session.json").read_text())["stop"]
    assert stop["cause"] == "stop signal" and stop["braked"], stop  # the controlled stop, every brake closed
    assert plant["brakes_closed"] == (1 << len(NAMES)) - 1, plant  # the arm left held by its brakes
    last = sessions[-1]
    assert last["complete"] and last["window_s"] >= 2.0 - 1e-3 and max(last["moved_after_stop_deg"]) <= \
        MOVED_AFTER_STOP_DEG, last
    assert _rc(vm, "plant") == 0, _text(vm, "plant")


def test_a_down_interface_is_one_line(vm: Path) -> None:
    down = _text(vm, "down").strip().splitlines()
    assert _rc(vm, "down") == 2 and down[-1] == ("armctl run: --bus socketcan:vcan9: the interface is down (as root: "
                                                "ip link set vcan9 up)"), down
