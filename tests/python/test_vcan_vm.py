"""HIL over real SocketCAN buses: the controller and the simulator on vcan0 + vcan1 inside the qemu VM.

This machine's kernel has no CAN, so tools/vm boots Debian's kernel under qemu (software
emulation), where vcan0 and vcan1 (CAN FD, MTU 72) exist, chroots into this very filesystem and runs
VM_SCRIPT below through `armctl vcan run`. One boot serves the tests that read its results
(software emulation: ~10 s to boot, far slower than the host):

0. what a command gets there: a normal /dev, and `armctl vcan up` creating an interface;
1. the SocketCAN unit test again, now on a kernel that has AF_CAN, and the live transport selftest;
2. `candump -L vcan0 vcan1` records both buses while `arm_controller` and `python -m host_sim`
   (arm_sim) run lockstep on the default topology (firmware/protocol/buses.toml): drives 1-3
   on vcan0, 4-6 on vcan1 (`--bus socketcan:vcan0@1-3 --bus socketcan:vcan1@4-6`);
3. after the 20th SYNC a misbehaving node (`cansend`) puts frames on the bus that nobody may act
   on: unknown ids, wrong lengths, a classic frame where FD is expected, remote and 29-bit frames,
   and drive 1's STATE on vcan1 (not drive 1's bus); 300 periods later SIGTERM stops the
   controller (a safe stop: zero torque, shutdown, NMT stop, then its summary).

4. your arm's whole rehearsal on real SocketCAN (docs/run-on-your-arm.md), through the documented
   commands on vcan0..vcan2: `armctl plant --bus vcan` (the arm, a process of its own), then
   `armctl commission`, `armctl run --hold --duration 5`, `--jog`, the built-in reference, a
   trajectory file and `--hold` ended by Ctrl-C: each ends as asked, the arm follows, the last stop
   leaves it held and braked, no joint moving more than 1 deg after any stop; and an interface
   that is down, refused in one line before anything starts. The release build those commands
   run is brought up to date on the host before the boot and named in ARMCTL_PREBUILT, so no
   command in the VM checks it again (tools/build/__init__.py).

On the host: both processes ended as they should; every captured frame is either one of the injected ones
(each exactly once) or decodes with the DBC via cantools with the DBC's length and FD/BRS format;
both sides counted each injected frame in the right counter and nothing else went wrong.

Skipped (with the reason) only if the VM cannot be set up on this machine (no qemu/busybox and not
root to install them, no Debian kernel package reachable).
"""

from __future__ import annotations

import json
import math
import re
import subprocess
import sys
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from pathlib import Path

import cantools
import pytest

from host_sim.protocol import DBC_PATH
from gen.lib.paths import REPO, env_with_repo
from test_run_on_arm import trajectory_csv
from tools.build import PREBUILT_ENV
from tools.build.arm import DEFAULT_ARM, build_arm

pytestmark = pytest.mark.long  # minutes: three runs of the qemu VM (five boots); the first also runs your arm's whole rehearsal

# Not serial: the guest's runs are lockstep (no wall clock decides them) and qemu takes one core,
# so these share the machine with one other test file; a boot that hangs is booted again.

PERIODS = 300
VM_TIMEOUT_S = 420.0  # generous: one boot's HIL run, or `hil --bus vm`, takes ~1-2 min on the 2-core CI machine
REHEARSAL_TIMEOUT_S = 1800.0  # the rehearsal's part of vm_run's boot: eight armctl start-ups, commissioning, the tasks
MOVED_AFTER_STOP_DEG = 1.0   # the most any joint may move in the 2 s the plant watches after the stop
N_JOINTS = 6

# (IFACE/cansend argument, where the controller counts it, where the simulator counts it). Frames
# with a master's ids (SYNC, a command) are not here: only the master sends them, so the controller
# stops the arm for another master on the bus (the fault matrix's second-master and spoofed-commands
# rows), rather than count and ignore them.
GARBAGE = [
    ("vcan0/123#DEADBEEF", "rx_unknown_id", "rx_unknown_id"),                          # unknown id
    ("vcan0/345##100112233445566778899AABBCCDDEEFF", "rx_unknown_id", "rx_unknown_id"),  # unknown id, FD
    ("vcan0/181#01020304", "rx_bad_format", "rx_foreign_drive"),    # DRIVE_1_STATE as a classic frame
    ("vcan0/182##10011223344556677", "rx_bad_length", "rx_foreign_drive"),  # DRIVE_2_STATE, FD, 8 bytes
    ("vcan0/701#0005", "rx_bad_length", "rx_foreign_drive"),        # heartbeat with 2 bytes
    ("vcan0/7FF#R", "rx_bad_format", "rx_bad_frame"),          # remote frame
    ("vcan0/12345678#00", "rx_bad_format", "rx_bad_frame"),    # 29-bit id
    ("vcan1/181##1FFEEDDCCBBAA99887766554433221100", "rx_wrong_bus", "rx_foreign_drive"),  # drive 1's STATE on vcan1
]
BUSES = "--bus socketcan:vcan0@1-3 --bus socketcan:vcan1@4-6"
ARMCTL = str(REPO / "tools" / "armctl")


def _frame_text(g: str) -> str:
    return g.split("/", 1)[1]

VM_SCRIPT = r"""#!/bin/sh
# Runs inside the VM, chrooted into the host's filesystem (tests/python/test_vcan_vm.py).
OUT=$1; CTL=$2; PY=$3; UNIT=$4; SELFTEST=$5; PERIODS=$6; GARBAGE=$7; CTL_EXTRA=$8; BUSES=$9; BUSLOG=${10}
REHEARSAL=${11}; TRAJ=${12}
# can-utils' canplayer reads a run's capture (armctl hil --capture: candump's log format), each
# bus's lines printed as they would be sent (it needs AF_CAN even for that: here it has it); into
# the guest's tmpfs, then copied out: a 9p write a line took 5 s
canplayer -I "$BUSLOG" -t stdout=can0 stdout=can1 stdout=can2 stdout=can3 > /dev/shm/replay.log 2> "$OUT/replay.err"
echo $? > "$OUT/replay.rc"; cp /dev/shm/replay.log "$OUT/replay.log"
DURATION=$PERIODS
# what `armctl vcan run` gives a command: a normal /dev (process substitution, /dev/std*, /dev/shm,
# /dev/pts), and `vcan up` creates an interface; its output streams back to the host
bash -c 'set -e; cat <(echo procsub-ok); echo to-stderr >> /dev/stderr; readlink /dev/stdout; test -L /dev/stdin;
         mountpoint -q /dev/shm; mountpoint -q /dev/pts; tools/armctl vcan up --iface vcan5; ip -details link show vcan5'
echo $? > "$OUT/dev.rc"
"$UNIT" > "$OUT/unit.out" 2>&1; echo $? > "$OUT/unit.rc"
"$SELFTEST" vcan0 > "$OUT/selftest.out" 2>&1; echo $? > "$OUT/selftest.rc"

# candump writes to the guest's tmpfs with a large socket buffer (-r, SO_RCVBUFFORCE): a capture
# must not lose frames while 9p writes stall on a busy host; copied out at the end.
CAP=/dev/shm/candump.log
candump -L -r 8388608 vcan0 vcan1 > "$CAP" 2> "$OUT/candump.err" &
CD=$!
"$PY" -m host_sim $BUSES --lcm-url "" --boot-timeout 180 --idle-timeout 60 \
    --summary "$OUT/sim.json" > "$OUT/sim.out" 2> "$OUT/sim.err" &
SIM=$!
"$CTL" $BUSES --lcm-url "" --duration 3600 --boot-timeout 180 \
    --lockstep-timeout 5 $CTL_EXTRA --summary "$OUT/ctl.json" > "$OUT/ctl.out" 2> "$OUT/ctl.err" &
CTLPID=$!
(   # a misbehaving node: once 20 periods ran (SYNC on both buses), frames that nobody may act on;
    # then the run goes on for PERIODS more, and SIGTERM ends it (a safe stop, then the summary)
    n=0
    while [ "$(grep -c ' 080#' "$CAP")" -lt 40 ] && [ $n -lt 1500 ]; do
        sleep 0.05; n=$((n + 1))
    done
    for f in $GARBAGE; do cansend "${f%%/*}" "${f#*/}" || echo "cansend $f failed" >> "$OUT/garbage.err"; done
    [ -f "$OUT/ctl.rc" ] || echo sent > "$OUT/garbage.done"
    want=$(( $(grep -c ' 080#' "$CAP") + 2 * DURATION ))
    while [ "$(grep -c ' 080#' "$CAP")" -lt $want ] && [ $n -lt 6000 ]; do
        sleep 0.05; n=$((n + 1))
    done
    kill -TERM $CTLPID
) &
INJ=$!
wait $CTLPID; echo $? > "$OUT/ctl.rc"
wait $SIM; echo $? > "$OUT/sim.rc"
kill $INJ 2>/dev/null; wait $INJ 2>/dev/null
sleep 0.5; kill $CD; wait $CD 2>/dev/null
cp "$CAP" "$OUT/candump.log"
# the same boot: your arm's rehearsal on vcan (REHEARSAL_SCRIPT)
bash "$REHEARSAL" "$OUT/rehearsal" "$TRAJ"
exit 0
"""

REHEARSAL_SCRIPT = r"""#!/bin/bash
# Runs inside the VM after VM_SCRIPT's HIL run (tests/python/test_vcan_vm.py): your arm's whole
# rehearsal through the documented commands on vcan0..vcan2, the plant a process of its own:
# commission -> hold 5 s -> jog -> the built-in reference -> a file trajectory -> Ctrl-C.
OUT=$1; TRAJ=$2
A=tools/armctl
RECORD=$OUT/record.json
mkdir -p "$OUT"
wait_for() {  # wait_for FILE TEXT SECONDS: until FILE says TEXT, at most SECONDS (the wall clock's)
    local t0=$SECONDS
    until grep -q "$2" "$1" 2>/dev/null; do sleep 0.5; [ $((SECONDS - t0)) -ge "$3" ] && return 1; done
    return 0
}
step() {  # step NAME ARGS...: one armctl command, its output, exit code and wall time
    local name=$1 t0; shift
    t0=$(date +%s%N)
    $A "$@" --out "$OUT/$name" > "$OUT/$name.out" 2>&1; echo $? > "$OUT/$name.rc"
    echo "$name $(( ($(date +%s%N) - t0) / 1000000 )) ms" >> "$OUT/times.txt"
}
# what a command's start-up costs here: armctl itself (its checks, Python's imports), then the
# build's check that ARMCTL_PREBUILT spares each command
t0=$(date +%s%N); $A run --help > /dev/null 2>&1; echo "startup $(( ($(date +%s%N) - t0) / 1000000 )) ms" >> "$OUT/times.txt"
t0=$(date +%s%N)
env -u ARMCTL_PREBUILT PYTHONPYCACHEPREFIX="$PWD/build/pycache" .venv/bin/python -c "from tools.build.arm import DEFAULT_ARM, build_arm
build_arm('release', DEFAULT_ARM, targets=['arm_controller', 'arm_sim', 'arm_lcm_logger'])" > "$OUT/buildcheck.out" 2>&1
echo "build-check $(( ($(date +%s%N) - t0) / 1000000 )) ms" >> "$OUT/times.txt"
$A plant --bus vcan --out "$OUT/plant" > "$OUT/plant.out" 2>&1 &
PLANT=$!
# meanwhile, a bus that is down: refused before anything starts (the plant, on vcan0..vcan2, never sees it)
ip link add dev vcan9 type vcan
$A run --hold --bus socketcan:vcan0,vcan1,vcan9 --record "$RECORD" > "$OUT/down.out" 2>&1 &
DOWN=$!
wait_for "$OUT/plant.out" "waiting for a master" 300 || echo "no plant" > "$OUT/plant.failed"
wait $DOWN; echo $? > "$OUT/down.rc"
R="--bus vcan --record $RECORD"
step commission commission $R
step hold run --hold --duration 5 $R
step jog run --jog elbow=5 $R
step reference run --duration 1 $R
step trajectory run "$TRAJ" $R
# a hold, ended by Ctrl-C once it holds
$A run --hold $R --out "$OUT/stop" > "$OUT/stop.out" 2>&1 &
RUN=$!
wait_for "$OUT/stop/controller.log" "hold: holding" 300
sleep 1
kill -INT $RUN   # Ctrl-C
wait $RUN; echo $? > "$OUT/stop.rc"
# the plant watches the arm for 2 s after each stop: until its record of the last session is final
settled() {
    python3 -c "import json, sys; s = json.load(open('$OUT/plant/sessions.json'))['sessions']
sys.exit(0 if len(s) >= 6 and s[-1]['complete'] else 1)" 2>/dev/null
}
t0=$SECONDS; until settled; do sleep 1; [ $((SECONDS - t0)) -ge 300 ] && break; done
cp "$OUT/plant/sessions.json" "$OUT/plant_settled.json" 2>/dev/null
kill -INT $PLANT; wait $PLANT; echo $? > "$OUT/plant.rc"
exit 0
"""


@dataclass(frozen=True)
class Frame:
    can_id: int
    extended: bool
    fd: bool
    brs: bool
    remote: bool
    data: bytes


_LINE = re.compile(r"^\((\d+\.\d+)\) (\S+) ([0-9A-Fa-f]{3}|[0-9A-Fa-f]{8})(##|#)(\S*)$")


def parse_frame(text: str) -> Frame:
    """A frame in candump -L / cansend notation: ID#DATA, ID#R, ID##<flags>DATA."""
    m = re.fullmatch(r"([0-9A-Fa-f]{3}|[0-9A-Fa-f]{8})(##|#)(\S*)", text)
    assert m, f"not a frame: {text!r}"
    ident, sep, rest = m.groups()
    ext = len(ident) == 8
    if sep == "##":
        flags = int(rest[0], 16)
        return Frame(int(ident, 16), ext, True, bool(flags & 1), False, bytes.fromhex(rest[1:].replace(".", "")))
    if rest.startswith("R"):
        return Frame(int(ident, 16), ext, False, False, True, b"")
    return Frame(int(ident, 16), ext, False, False, False, bytes.fromhex(rest.replace(".", "")))


def parse_capture(path: Path, with_iface: bool = False) -> list:
    frames = []
    for line in path.read_text().splitlines():
        m = _LINE.match(line.strip())
        assert m, f"{path.name}: unexpected line {line!r}"
        f = parse_frame(m.group(3) + m.group(4) + m.group(5))
        frames.append((m.group(2), f) if with_iface else f)
    return frames


def _vm_or_skip() -> None:
    from tools.vm.image import APT_HINT, VmError, ensure_image, missing_tools

    missing = missing_tools()
    if missing:
        pytest.skip(f"no qemu VM here: missing {', '.join(missing)} ({APT_HINT})")
    try:
        ensure_image()
    except VmError as exc:
        pytest.skip(f"the qemu VM cannot be set up on this machine: {exc}")


@pytest.fixture(scope="module")
def vm_run(tmp_path_factory: pytest.TempPathFactory, build_dir: Path) -> dict:
    exes = {name: build_dir / rel for name, rel in {
        "ctl": "firmware/arm_controller",
        "unit": "tests/c/transport/test_can_socketcan",
        "selftest": "tests/c/transport/can_socketcan_selftest"}.items()}
    for exe in exes.values():
        if not exe.exists():
            pytest.skip(f"{exe} not built (run tools/armctl build --preset debug)")
    _vm_or_skip()

    out = tmp_path_factory.mktemp("vcan_vm")
    script = out / "vm_script.sh"
    script.write_text(VM_SCRIPT)
    (out / "rehearsal.sh").write_text(REHEARSAL_SCRIPT)
    # no start-pose hold where the controller has one: the VM is slow, the periods are precious
    helptext = subprocess.run([str(exes["ctl"]), "--help"], capture_output=True, text=True).stdout
    ctl_extra = "--ref-hold 0" if "--ref-hold" in helptext else ""
    from tools.run.hil import CAPTURE_FILE, HilOptions, run_hil

    # the VM's inputs, made before it boots (a file the host writes during the run may look stale
    # in it: 9p's cache): the capture canplayer replays, the rehearsal's trajectory file, and the
    # release build the rehearsal's commands run, brought up to date here (ARMCTL_PREBUILT: not
    # checked again by each command in the VM, where ninja's look at the tree over 9p is slow)
    run_hil(HilOptions(out=out / "sil", duration_s=0.2, preset=build_dir.name, bus="sil", capture=True))
    traj = trajectory_csv(out / "traj.csv", [0.3, 0.2, -0.3, 0.2, 0.3, 0.4], seconds=2.0, rows=41)
    release = build_arm("release", DEFAULT_ARM, targets=["arm_controller", "arm_sim", "arm_lcm_logger"])
    # through the CLI, as a user runs a command in the VM (docs/drives.md)
    res = subprocess.run(
        [ARMCTL, "vcan", "run", "--verbose", "--timeout", f"{VM_TIMEOUT_S + REHEARSAL_TIMEOUT_S:g}", "--",
         "sh", str(script), str(out), str(exes["ctl"]), sys.executable, str(exes["unit"]),
         str(exes["selftest"]), str(PERIODS), " ".join(g for g, _, _ in GARBAGE), ctl_extra, BUSES,
         str(out / "sil" / CAPTURE_FILE), str(out / "rehearsal.sh"), str(traj)],
        cwd=REPO, capture_output=True, text=True, timeout=VM_TIMEOUT_S + REHEARSAL_TIMEOUT_S + 60,
        env={**env_with_repo(), PREBUILT_ENV: str(release)})
    assert res.returncode == 0, f"armctl vcan run: exit {res.returncode}: {res.stdout[-3000:]}{res.stderr[-3000:]}"

    def read(name: str) -> str:
        p = out / name
        return p.read_text() if p.exists() else f"<{name} missing>"

    print(f"test_vcan_vm: {res.stderr.strip().splitlines()[-1]}; the rehearsal's steps: "
          f"{read('rehearsal/times.txt').strip()}", file=sys.stderr)
    return {"out": out, "read": read, "stdout": res.stdout, "stderr": res.stderr}


def _rc(vm_run: dict, name: str) -> int:
    text = vm_run["read"](f"{name}.rc").strip()
    assert text.lstrip("-").isdigit(), f"{name} never finished in the VM ({text})"
    return int(text)


def test_canplayer_replays_a_capture(vm_run: dict) -> None:
    """Every line of a run's capture (--capture; a CiA 402 run's three classic buses) is a frame
    canplayer replays, on every bus."""
    assert _rc(vm_run, "replay") == 0, vm_run["read"]("replay.err")
    capture = (vm_run["out"] / "sil" / "bus.log").read_text().splitlines()
    replayed = vm_run["read"]("replay.log").splitlines()
    assert len(replayed) == len(capture) > 0
    assert [ln.split()[1:] for ln in replayed] == [ln.split()[1:] for ln in capture]  # ifaces, ids, data


def test_socketcan_transport_on_a_kernel_with_can(vm_run: dict) -> None:
    unit = vm_run["read"]("unit.out")
    assert _rc(vm_run, "unit") == 0, unit
    assert "kernel AF_CAN: yes" in unit  # the open-error branch for a kernel that has CAN ran
    selftest = vm_run["read"]("selftest.out")
    assert _rc(vm_run, "selftest") == 0, selftest
    assert re.search(r"\b0 failed", selftest), selftest


def test_hil_run_over_vcan_succeeds(vm_run: dict) -> None:
    read = vm_run["read"]
    assert _rc(vm_run, "ctl") == 5, read("ctl.err") + read("ctl.out")  # interrupted: the script's SIGTERM
    assert _rc(vm_run, "sim") == 0, read("sim.err") + read("sim.out")
    ctl = json.loads(read("ctl.json"))
    sim = json.loads(read("sim.json"))
    # the script ends the run with SIGTERM once PERIODS periods ran after the garbage
    assert ctl["result"] == 5 and ctl["final_state"] == "safe-stop" and "stopped by signal 15" in ctl["reason"], ctl
    assert ctl["steps_done"] >= PERIODS
    assert ctl["frames"]["tx_dropped"] == 0 and ctl["frames"]["rx_wrong_counter"] == 0
    assert sim["result"] == "ok" and sim["drive_faults"] == [] and sim["commands_missed"] == 0, sim
    assert sim["periods"] >= PERIODS


def test_every_captured_frame_decodes_with_the_dbc(vm_run: dict) -> None:
    db = cantools.database.load_file(str(DBC_PATH))
    frames = parse_capture(vm_run["out"] / "candump.log", with_iface=True)
    sim = json.loads(vm_run["read"]("sim.json"))

    injected = [(g.split("/")[0], parse_frame(_frame_text(g))) for g, _, _ in GARBAGE]
    for g in injected:  # each injected frame is on its bus exactly once, unchanged
        assert frames.count(g) == 1, f"injected {g} seen {frames.count(g)} times"
        frames.remove(g)
    # every drive's STATE, CMD and HEARTBEAT on its own bus only: drives 1-3 on vcan0, 4-6 on vcan1
    for iface, f in frames:
        if f.can_id in (*range(0x181, 0x187), *range(0x201, 0x207), *range(0x701, 0x707)):
            drive = f.can_id & 0x7F
            assert iface == ("vcan0" if drive <= 3 else "vcan1"), f"drive {drive} frame {f} on {iface}"
    sync_per_bus = {i: sum(1 for b, f in frames if b == i and f.can_id == 0x080) for i in ("vcan0", "vcan1")}
    assert sync_per_bus["vcan0"] == sync_per_bus["vcan1"] == sim["periods"]
    frames = [f for _, f in frames]

    counts: dict[str, int] = {}
    for f in frames:
        msg = db.get_message_by_frame_id(f.can_id)  # KeyError: a frame the DBC does not define
        assert not f.extended and not f.remote
        assert len(f.data) == msg.length, f"{msg.name}: {len(f.data)} bytes"
        assert f.fd == msg.is_fd, f"{msg.name}: fd={f.fd}"
        if f.fd:
            assert f.brs, f"{msg.name}: FD frame without bit-rate switch"
        db.decode_message(f.can_id, f.data)  # raises on anything that does not decode
        counts[msg.name] = counts.get(msg.name, 0) + 1

    n_sync = counts["SYNC"] // 2  # SYNC goes on both buses
    assert n_sync == sim["periods"] >= PERIODS
    for i in range(1, 7):
        assert counts[f"DRIVE_{i}_STATE"] == n_sync
        # one per SYNC: the safe stop's zero torque and shutdown come in a period of their own
        assert counts[f"DRIVE_{i}_CMD"] == n_sync
        assert counts[f"DRIVE_{i}_HEARTBEAT"] >= 3  # boot-up, operational, stopped
    for i in range(1, 7):  # SIGTERM's controlled stop: quick stop under the hold, then each drive disabled
        cmds = [db.decode_message(0x200 + i, f.data) for f in frames if f.can_id == 0x200 + i]
        assert any(c["controlword"] == 0x0002 for c in cmds), (i, cmds[-3:])  # the quick stop
        assert cmds[-1]["controlword"] == 0x0000, (i, cmds[-1])  # disable voltage: the power stage off
    assert counts.get("NMT", 0) >= 4  # start ... stop, on both buses
    assert not any(name.endswith("_EMCY") for name in counts), counts
    assert len(frames) + len(injected) > 13 * PERIODS


def test_garbage_frames_are_counted_and_ignored(vm_run: dict) -> None:
    read = vm_run["read"]
    assert read("garbage.done").strip() == "sent", (
        "the garbage was not sent while the run was going: " + read("garbage.err"))
    ctl = json.loads(read("ctl.json"))["frames"]
    sim = json.loads(read("sim.json"))
    want_ctl = {k: 0 for k in ("rx_unknown_id", "rx_bad_format", "rx_bad_length", "rx_foreign_master", "rx_wrong_bus")}
    want_sim = {k: 0 for k in ("rx_unknown_id", "rx_foreign_drive", "rx_bad_frame")}
    for _, c, s in GARBAGE:
        want_ctl[c] += 1
        want_sim[s] += 1
    # the clean run counts zero in each of these; every injected frame landed in exactly one
    assert {k: ctl[k] for k in want_ctl} == want_ctl
    assert {k: sim[k] for k in want_sim} == want_sim
    # and changed nothing: every period's joint states arrived, no drive faulted
    assert ctl["rx_wrong_counter"] == 0 and sim["drive_faults"] == []


def test_hil_in_the_vm_through_the_cli(tmp_path: Path) -> None:
    """The docs' way (docs/drives.md) to run HIL over real SocketCAN, as a user types it: armctl builds and plans
    the run here, boots the VM and starts the logger, the simulator and the controller there on
    vcan0..vcan3 (tools/run/processes.py), then analyses what they wrote; here with a 7-DOF arm
    from an arm file, whose CiA 402 drives take four classic buses (2, 2, 2, 1), the most the
    controller has; in the slow VM the drives come up after the controller, which waits for them."""
    _vm_or_skip()
    r = subprocess.run([ARMCTL, "hil", "--bus", "vm", "--arm", "tests/arms/panda.toml", "--duration", "0.3",
                        "--out", str(tmp_path)], cwd=REPO, capture_output=True, text=True, timeout=VM_TIMEOUT_S)
    assert r.returncode == 0, r.stdout + r.stderr
    run = json.loads((tmp_path / "run.json").read_text())
    assert run["results"]["result"] == "ok", run["results"]
    assert run["environment"]["bus"].split() == ["socketcan:vcan0@1,2", "socketcan:vcan1@3,4",
                                                 "socketcan:vcan2@5,6", "socketcan:vcan3@7"]
    assert run["environment"]["protocol"] == "canopen" and run["environment"]["canopen"]["fault"]["code"] == "none"
    assert run["environment"]["bus_choice"].startswith("vm -> vcan (inside the qemu VM")
    assert run["environment"]["simulator_scheduling"].endswith("(in the VM)")
    assert len(run["results"]["tracking_max_abs_deg"]) == 7


def test_vcan_setup_run_and_up_in_the_vm(vm_run: dict) -> None:
    """`vcan setup` leaves a bootable image; in the VM (the run above, through `vcan run`) a command
    gets a normal /dev (process substitution, /dev/std*, /dev/shm, /dev/pts), `vcan up` creates an
    interface, and the command's output and the VM's times come back."""
    r = subprocess.run([ARMCTL, "vcan", "setup"], cwd=REPO, capture_output=True, text=True, timeout=600)
    assert r.returncode == 0 and "VM image ready" in r.stdout, r.stdout + r.stderr
    out, err = vm_run["stdout"], vm_run["stderr"]
    assert _rc(vm_run, "dev") == 0, out + err
    assert "procsub-ok" in out and "/proc/self/fd/1" in out and "to-stderr" in err
    assert "vcan5 up (mtu 72 = CAN FD, txqueuelen 1000)" in out and "vcan" in out.split("vcan5:")[-1]
    assert re.search(r"armctl vcan: exit 0; set-up \S+ s, boot \S+ s, command \S+ s, total \S+ s", err), err


def test_a_hung_boot_is_booted_again_and_the_vm_dies_with_the_armctl_that_booted_it(tmp_path: Path) -> None:
    """Two guards of tools/vm/run.py, checked on one run (a boot is the slowest thing here):
    - a boot that never starts the command (CI saw one spin for 7 min with an empty console) is
      killed after BOOT_WAIT_S and the VM booted again. Here every boot but the last is cut short
      (0.5 s: a boot takes seconds), so the command runs on the last one;
    - a SIGKILLed armctl (a CI timeout kills it so) left its qemu running at full CPU once: the
      kernel now stops qemu when the thread that started it is gone."""
    _vm_or_skip()
    import signal
    import time

    import tools.vm.run as vm

    marker, notes = tmp_path / "marker", tmp_path / "stderr"
    code = ("import tools.vm.run as vm; vm.BOOT_WAIT_S = 0.5; "
            f"vm.run_in_vm(['sh', '-c', 'touch {marker}; sleep 600'], timeout=700)")
    with open(notes, "w") as err:
        p = subprocess.Popen([sys.executable, "-c", code], cwd=REPO, env=env_with_repo(),
                             stdout=subprocess.DEVNULL, stderr=err)
    deadline = time.monotonic() + VM_TIMEOUT_S
    while not marker.exists() and time.monotonic() < deadline and p.poll() is None:
        time.sleep(0.2)
    assert marker.exists(), f"the command never started in the VM: {notes.read_text()}"
    assert notes.read_text().count("booting it again") == vm.BOOT_ATTEMPTS - 1, notes.read_text()
    qemu = subprocess.run(["pgrep", "-P", str(p.pid), "-f", "qemu-system"], capture_output=True, text=True).stdout.split()
    assert qemu, "no qemu child found"
    p.send_signal(signal.SIGKILL)
    p.wait()
    deadline = time.monotonic() + 30
    while time.monotonic() < deadline and Path(f"/proc/{qemu[0]}").exists():
        time.sleep(0.2)
    assert not Path(f"/proc/{qemu[0]}").exists(), f"qemu {qemu[0]} outlived its armctl"


def _rehearsal(vm_run: dict, name: str) -> str:
    return vm_run["read"](f"rehearsal/{name}")


TASKS = ("hold", "jog", "reference", "trajectory")


def test_commission_passes_on_vcan(vm_run: dict) -> None:
    """`armctl commission --bus vcan` against `armctl plant --bus vcan`: the arm is the one the model
    describes, each joint's direction, inertia and gravity checked on real SocketCAN."""
    assert not (vm_run["out"] / "rehearsal" / "plant.failed").exists(), _rehearsal(vm_run, "plant.out")
    cm = _rehearsal(vm_run, "commission.out")
    assert _rc(vm_run, "rehearsal/commission") == 0 and "armctl commission: passed" in cm, cm
    rec = json.loads(_rehearsal(vm_run, "record.json"))
    assert rec["passed"] and rec["findings"] == [] and len(rec["joints"]) == N_JOINTS, rec
    assert all(j["direction"] == "ok" for j in rec["joints"]), rec["joints"]


def test_every_task_on_vcan_ends_as_asked_and_the_arm_follows(vm_run: dict) -> None:
    """hold 5 s, jog, the built-in reference, a trajectory file: each `armctl run --bus vcan` on
    vcan0..vcan2 ends as asked (exit 0), the arm within 1 deg of each task's reference."""
    for name in TASKS:
        assert _rc(vm_run, f"rehearsal/{name}") == 0, _rehearsal(vm_run, f"{name}.out")
        s = json.loads(_rehearsal(vm_run, f"{name}/session.json"))
        assert [b.split("@")[0] for b in s["buses"]] == ["socketcan:vcan0", "socketcan:vcan1", "socketcan:vcan2"], s
        assert s["final_state"] == "safe-stop" and s["task_report"]["ended"], (name, s)
        assert s["stop"]["cause"] == "end of the run" and s["stop"]["braked"], (name, s["stop"])
        assert s["tracking"]["periods"] > 0 and max(s["tracking"]["max_abs_deg"].values()) < 1.0, (name, s["tracking"])
    hold = json.loads(_rehearsal(vm_run, "hold/session.json"))["task_report"]
    assert hold["name"] == "hold" and abs(hold["task_s"] - 5.0) < 1e-3, hold
    jog = json.loads(_rehearsal(vm_run, "jog/session.json"))["task_report"]
    moved = [b - a for a, b in zip(jog["start_pose"], jog["first_point"])]
    assert moved == pytest.approx([0, 0, math.radians(5), 0, 0, 0], abs=1e-6), jog
    traj = json.loads(_rehearsal(vm_run, "trajectory/session.json"))["task_report"]
    assert traj["name"] == "trajectory" and abs(traj["task_s"] - 3.0) < 1e-3, traj  # 2 s and the end's 1 s hold


def test_ctrl_c_on_vcan_stops_the_arm_and_it_stays(vm_run: dict) -> None:
    """Ctrl-C on `armctl run --hold --bus vcan`: the controlled stop, exit 0, the arm held by its
    brakes; after every stop of the rehearsal no joint moved more than 1 deg in the 2 s watched."""
    stop_out = _rehearsal(vm_run, "stop.out")
    assert _rc(vm_run, "rehearsal/stop") == 0 and "stopped by you" in stop_out, stop_out
    session = json.loads(_rehearsal(vm_run, "stop/session.json"))
    assert session["stopped_by_user"], session
    stop = session["stop"]
    assert stop["cause"] == "stop signal" and stop["braked"], stop  # the controlled stop, every brake closed
    plant = json.loads(_rehearsal(vm_run, "plant/sessions.json"))
    assert plant["brakes_closed"] == (1 << N_JOINTS) - 1 and not plant["in_session"], plant  # held by its brakes
    sessions = plant["sessions"]
    assert len(sessions) == 1 + len(TASKS) + 1 and all(s["ended"] == "stopped" for s in sessions), sessions
    last = sessions[-1]
    assert last["complete"] and last["window_s"] >= 2.0 - 1e-3, last
    for s in sessions:
        if s["window_s"] >= 2.0 - 1e-3:  # the sessions whose whole 2 s after the stop were watched
            assert max(s["moved_after_stop_deg"]) <= MOVED_AFTER_STOP_DEG, s
    assert _rc(vm_run, "rehearsal/plant") == 0, _rehearsal(vm_run, "plant.out")


def test_a_down_interface_is_one_line(vm_run: dict) -> None:
    down = _rehearsal(vm_run, "down.out").strip().splitlines()
    assert _rc(vm_run, "rehearsal/down") == 2 and down[-1] == (
        "armctl run: --bus socketcan:vcan9: the interface is down (as root: ip link set vcan9 up)"), down
