"""armctl vcan: a real SocketCAN bus (vcan0) natively where the kernel has CAN, else inside a qemu VM.

    armctl vcan status            what is available here (kernel CAN, vcan interfaces, the VM cache)
    armctl vcan up [--iface N]    create/configure vcan0 natively (modprobe vcan; ip link add ...)
    armctl vcan setup             download + build the VM image now (otherwise done on first run)
    armctl vcan run -- CMD ...    run CMD inside the VM, where vcan0 exists (same files, cwd, env)

`run` exits with CMD's exit code (124: the VM timed out; 125: CMD could not be started in it);
3 when the VM cannot be set up on this machine.
"""

from __future__ import annotations

import argparse
import errno
import os
import shutil
import socket
import subprocess
import sys
from pathlib import Path

EXIT_NO_VM = 3
ARPHRD_CAN = 280
NO_CAN_HINT = ("use --bus udp (CAN over loopback multicast), or run it in the VM: "
               "tools/armctl vcan run -- CMD ...")


def kernel_has_can() -> tuple[bool, str]:
    """(True, "") if socket(AF_CAN, SOCK_RAW, CAN_RAW) works, else (False, why)."""
    if not hasattr(socket, "AF_CAN"):
        return False, "this Python has no socket.AF_CAN"
    try:
        socket.socket(socket.AF_CAN, socket.SOCK_RAW, socket.CAN_RAW).close()
        return True, ""
    except OSError as exc:
        if exc.errno == errno.EAFNOSUPPORT:
            return False, "this kernel has no SocketCAN (AF_CAN: EAFNOSUPPORT)"
        if exc.errno == errno.EPROTONOSUPPORT:
            return False, "this kernel has AF_CAN but no CAN_RAW (modprobe can-raw)"
        return False, f"socket(AF_CAN): {exc.strerror}"


def can_interfaces() -> list[dict[str, str]]:
    """CAN interfaces (link type 280) with their MTU, txqueuelen and state, from /sys/class/net."""
    out = []
    for d in sorted(Path("/sys/class/net").glob("*")):
        try:
            if int((d / "type").read_text()) != ARPHRD_CAN:
                continue
            out.append({"name": d.name, "mtu": (d / "mtu").read_text().strip(),
                        "txqueuelen": (d / "tx_queue_len").read_text().strip(),
                        "state": (d / "operstate").read_text().strip()})
        except (OSError, ValueError):
            continue
    return out


def _run(cmd: list[str]) -> tuple[int, str]:
    r = subprocess.run(cmd, capture_output=True, text=True)
    return r.returncode, (r.stderr or r.stdout).strip()


def cmd_up(ns: argparse.Namespace) -> int:
    from tools.errors import CommandError

    iface = ns.iface
    mtu = "16" if ns.classic else "72"
    steps = [["modprobe", "vcan"],
             ["ip", "link", "add", "dev", iface, "type", "vcan"],
             ["ip", "link", "set", iface, "mtu", mtu, "txqueuelen", str(ns.txqueuelen), "up"]]
    if os.geteuid() != 0:
        raise CommandError(f"needs root; run:\n  sudo {' && sudo '.join(' '.join(s) for s in steps)}")
    ok, why = kernel_has_can()
    if not ok:
        mod_dir = Path("/lib/modules") / os.uname().release
        if shutil.which("modprobe") and mod_dir.is_dir():
            rc, msg = _run(["modprobe", "can_raw"])
            ok, _ = kernel_has_can()
            detail = f"modprobe can_raw: {msg or 'loaded'}" if not ok else ""
        else:
            detail = f"no modprobe or no module tree {mod_dir}: nothing to load"
        if not ok:
            raise CommandError(f"{why}; {detail}.\n  {NO_CAN_HINT}")
    if not Path(f"/sys/class/net/{iface}").exists():
        if shutil.which("modprobe"):
            _run(steps[0])
        rc, msg = _run(steps[1])
        if rc != 0:
            raise CommandError(f"{' '.join(steps[1])}: {msg}\n  (no vcan driver in this kernel?) {NO_CAN_HINT}")
    rc, msg = _run(steps[2])
    if rc != 0:
        raise CommandError(f"{' '.join(steps[2])}: {msg}")
    for i in can_interfaces():
        if i["name"] == iface:
            print(f"armctl vcan: {iface} up (mtu {i['mtu']}{' = CAN FD' if i['mtu'] == '72' else ' = classic'}, "
                  f"txqueuelen {i['txqueuelen']}); use --bus socketcan:{iface}")
    return 0


def cmd_status(ns: argparse.Namespace) -> int:
    from tools.vm.image import CACHE, cached_kernels, load_image, missing_tools

    ok, why = kernel_has_can()
    print(f"kernel SocketCAN (AF_CAN): {'yes' if ok else 'no: ' + why}")
    ifs = can_interfaces()
    if ifs:
        for i in ifs:
            print(f"  {i['name']}: mtu {i['mtu']}, txqueuelen {i['txqueuelen']}, {i['state']}")
    else:
        print("  no CAN interfaces" + ("; create one: tools/armctl vcan up" if ok else ""))
    missing = missing_tools()
    print(f"VM tools: {'ready' if not missing else 'missing ' + ', '.join(missing)}")
    img = load_image()
    if img is not None:
        size = sum(p.stat().st_size for p in CACHE.rglob("*") if p.is_file()) / 1e6
        print(f"VM image: cached, kernel {img.kernel_version} ({CACHE}, {size:.0f} MB)")
    elif cached_kernels():
        print(f"VM image: kernel cached in {CACHE}, initramfs built on first run")
    else:
        print("VM image: not built yet (first `vcan run`/`vcan setup` downloads the Debian kernel, ~70 MB)")
    print("usable buses: udp" + (", socketcan:IFACE (native)" if ok and ifs else "")
          + (", socketcan:vcan0..vcan3 inside `tools/armctl vcan run`" if not missing else ""))
    return 0


def cmd_setup(ns: argparse.Namespace) -> int:
    from tools.vm.image import ensure_image

    img = ensure_image(refresh=ns.refresh)  # a VmError exits EXIT_NO_VM (add_arguments)
    print(f"armctl vcan: VM image ready: kernel {img.kernel_version}, {img.initrd}")
    return 0


def cmd_run(ns: argparse.Namespace) -> int:
    from tools.errors import UsageError
    from tools.vm.run import run_in_vm

    argv = list(ns.argv)
    if argv and argv[0] == "--":
        argv = argv[1:]
    if not argv:
        raise UsageError("no command; usage: armctl vcan run -- CMD [ARGS...]")
    res = run_in_vm(argv, timeout=ns.timeout, keep=ns.keep)  # a VmError exits EXIT_NO_VM (add_arguments)
    if ns.verbose:
        print(f"armctl vcan: exit {res.returncode}; set-up {res.setup_s:.1f} s, boot {res.boot_s:.1f} s, "
              f"command {res.command_s:.1f} s, total {res.total_s:.1f} s", file=sys.stderr)
    return res.returncode


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """vcan's own subcommands; each names itself in its messages (armctl vcan up: ...), and a VM
    that cannot be set up exits EXIT_NO_VM."""
    from tools.vm.image import VmError

    sub = parser.add_subparsers(dest="vcan_command", required=True)
    s = sub.add_parser("status", help="what CAN is available here: kernel, interfaces, the VM")
    s.set_defaults(vcan_fn=cmd_status)
    u = sub.add_parser("up", help="create and configure a vcan interface natively (needs kernel CAN, root)")
    u.add_argument("--iface", default="vcan0")
    u.add_argument("--txqueuelen", type=int, default=1000, help="transmit queue (kernel default 10: ENOBUFS)")
    u.add_argument("--classic", action="store_true", help="MTU 16 (classic CAN only) instead of 72 (CAN FD)")
    u.set_defaults(vcan_fn=cmd_up)
    st = sub.add_parser("setup", help="download the Debian kernel and build the VM image now")
    st.add_argument("--refresh", action="store_true", help="fetch the kernel apt names today, rebuild")
    st.set_defaults(vcan_fn=cmd_setup)
    r = sub.add_parser("run", help="run a command inside the qemu VM, where vcan0..vcan3 (CAN FD) exist")
    r.add_argument("--timeout", type=float, default=1800.0, help="s before the VM is killed (exit 124)")
    r.add_argument("--keep", action="store_true", help="keep the run folder under .cache/vm/runs")
    r.add_argument("-v", "--verbose", action="store_true", help="print boot and run times")
    r.add_argument("argv", nargs=argparse.REMAINDER, help="-- CMD [ARGS...]")
    r.set_defaults(vcan_fn=cmd_run)
    for name, p in sub.choices.items():
        p.set_defaults(prefix=f"armctl vcan {name}", exit_codes={VmError: EXIT_NO_VM})


def add_subparser(sub: argparse._SubParsersAction) -> None:
    vc = sub.add_parser("vcan", help="real SocketCAN: vcan interfaces natively, or a qemu VM that has them "
                                     "(status/up/setup/run)")
    add_arguments(vc)
    vc.set_defaults(run=run)


def run(ns: argparse.Namespace) -> int:
    return int(ns.vcan_fn(ns))

