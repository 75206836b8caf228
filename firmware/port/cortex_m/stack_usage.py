"""Flash, RAM and worst-case stack of a bare-metal image, checked against the part's budget.

Worst-case stack = the deepest path of the static call graph from the reset handler, plus the
deepest exception handler on top of it with its hardware-stacked frame:

- frame sizes: GCC's -fstack-usage (.su files of every object of this build) where it has them;
  for library code without .su (newlib-nano, libgcc) every instruction in the disassembly that
  moves sp down (push/stmdb, vpush/vstmdb, sub sp, str/strd with pre-decrement) is summed;
- call edges: bl/blx <symbol> and tail calls (b/b.w <symbol>) in the disassembly of the linked
  image, so library calls (sinf, memcpy, soft-float helpers) are on the path too.

It refuses what it cannot bound: recursion, indirect calls (blx rN), dynamic frames (alloca/VLA,
.su "dynamic"). Exits 1 when anything is over budget or unbounded (the build fails).

Usage (from firmware/port/cortex_m/CMakeLists.txt):
  stack_usage.py --elf X.elf --objdump arm-none-eabi-objdump --su-root BUILD --mcu cortex-m4 ...
"""

from __future__ import annotations

import argparse
import bisect
import json
import re
import subprocess
import sys
from pathlib import Path

FUNC_RE = re.compile(r"^([0-9a-f]+) <([^>]+)>:$")
INSN_RE = re.compile(r"^\s*([0-9a-f]+):\s+(?:[0-9a-f]{4}\s?){1,2}\s+(\S+)\s*(.*)$")
TARGET_RE = re.compile(r"^([0-9a-f]+) <[^>]+>$")
BRANCH_RE = re.compile(r"^b(?:eq|ne|cs|hs|cc|lo|mi|pl|vs|vc|hi|ls|ge|lt|gt|le|al)?(?:\.w|\.n)?$")

# Hardware-stacked exception frame: 8 words; with the FPU's lazy context 26 words (+ alignment).
EXC_FRAME = {0: 32 + 4, 1: 104 + 4}
ENTRY = "Reset_Handler"
HANDLERS = ("Fault_Handler", "Default_Handler")


def read_su(root: Path) -> tuple[dict[str, int], set[str]]:
    frames: dict[str, int] = {}
    dynamic: set[str] = set()
    for su in root.rglob("*.su"):
        if "CompilerId" in str(su):  # CMake's compiler identification, not part of the image
            continue
        for line in su.read_text().splitlines():
            parts = line.split("\t")
            if len(parts) < 3:
                continue
            name = parts[0].rsplit(":", 1)[-1]
            size = int(parts[1])
            frames[name] = max(frames.get(name, 0), size)
            if "dynamic" in parts[2] and "bounded" not in parts[2]:
                dynamic.add(name)
    return frames, dynamic


def reglist_count(ops: str) -> int:
    m = re.search(r"\{([^}]*)\}", ops)
    if not m:
        return 0
    n = 0
    for item in m.group(1).split(","):
        item = item.strip()
        r = re.match(r"([rsd])(\d+)-[rsd](\d+)", item)
        n += int(r.group(3)) - int(r.group(2)) + 1 if r else 1
    return n


def disassemble(objdump: str, elf: Path) -> dict[str, dict]:
    out = subprocess.run([objdump, "-d", "--no-show-raw-insn", str(elf)], capture_output=True,
                         text=True, check=True).stdout
    # A target is resolved by its address, never by objdump's label: the label is the nearest
    # symbol, which may be an absolute one such as the linker script's _stack_size = 0x2000 when a
    # branch inside a function lands on that address.
    starts = sorted((int(m.group(1), 16), m.group(2)) for m in map(FUNC_RE.match, out.splitlines()) if m)
    addrs = [a for a, _ in starts]

    def owner(addr: int) -> tuple[str, bool] | None:
        """The function that holds addr, and whether addr is its entry."""
        i = bisect.bisect_right(addrs, addr) - 1
        return (starts[i][1], starts[i][0] == addr) if i >= 0 else None

    funcs: dict[str, dict] = {}
    cur: dict | None = None
    for line in out.splitlines():
        m = FUNC_RE.match(line)
        if m:
            cur = {"name": m.group(2), "calls": set(), "indirect": False, "prologue": 0, "n": 0}
            funcs[m.group(2)] = cur
            continue
        if cur is None:
            continue
        m = re.match(r"^\s*[0-9a-f]+:\s+(\S+)\s*(.*)$", line)
        if not m:
            continue
        op, args = m.group(1), m.group(2).split(";")[0].strip()
        cur["n"] += 1
        # Every instruction that moves sp down, anywhere in the function (compilers shrink-wrap:
        # the push may come after an early-return test). Summed: an upper bound of the frame.
        if op in ("push", "push.w") or (op in ("stmdb", "stmdb.w") and args.startswith("sp!")):
            cur["prologue"] += 4 * reglist_count(args)
        elif op in ("vpush", "vpush.64", "vpush.32") or (op.startswith("vstmdb") and args.startswith("sp!")):
            regs = reglist_count(args)
            cur["prologue"] += (8 if args.split("{")[1].strip().startswith("d") else 4) * regs
        elif re.match(r"subw?(\.w)?$", op) and re.match(r"sp,\s*(sp,\s*)?#", args):
            cur["prologue"] += int(re.search(r"#(\d+)", args).group(1))
        elif op.startswith("str") and re.search(r"\[sp, #-(\d+)\]!", args):
            cur["prologue"] += int(re.search(r"\[sp, #-(\d+)\]!", args).group(1))
        t = TARGET_RE.match(args)
        target = owner(int(t.group(1), 16)) if t else None
        if op in ("bl", "blx") and target:
            cur["calls"].add(target[0])
        elif op == "blx":
            cur["indirect"] = True  # blx rN
        elif BRANCH_RE.match(op) and target and target[0] != cur["name"]:
            cur["calls"].add(target[0])  # tail call (into another function)
    return funcs


def worst_paths(funcs: dict[str, dict], su: dict[str, int], dynamic: set[str], root: str):
    memo: dict[str, tuple[int, list[str]]] = {}
    problems: list[str] = []

    def frame(f: str) -> int:
        return su[f] if f in su else funcs.get(f, {}).get("prologue", 0)

    def visit(f: str, stack: list[str]) -> tuple[int, list[str]]:
        if f in memo:
            return memo[f]
        if f in stack:
            problems.append("recursion: " + " -> ".join(stack[stack.index(f):] + [f]))
            return 0, [f]
        info = funcs.get(f)
        if info is None:
            problems.append(f"no code for {f}")
            return 0, [f]
        if info["indirect"]:
            problems.append(f"indirect call in {f}")
        if f in dynamic:
            problems.append(f"dynamic stack frame in {f}")
        best, best_path = 0, []
        for c in sorted(info["calls"]):
            d, p = visit(c, stack + [f])
            if d > best:
                best, best_path = d, p
        memo[f] = (frame(f) + best, [f] + best_path)
        return memo[f]

    depth, path = visit(root, [])
    frames = [{"function": f, "frame_bytes": frame(f), "from": "su" if f in su else "objdump"} for f in path]
    return depth, frames, problems


def section_sizes(objdump: str, elf: Path) -> dict[str, int]:
    out = subprocess.run([objdump, "-h", str(elf)], capture_output=True, text=True, check=True).stdout
    sizes: dict[str, int] = {}
    for line in out.splitlines():
        parts = line.split()
        if len(parts) >= 7 and parts[0].isdigit():
            sizes[parts[1]] = int(parts[2], 16)
    return sizes


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--elf", type=Path, required=True)
    p.add_argument("--objdump", required=True)
    p.add_argument("--su-root", type=Path, required=True)
    p.add_argument("--mcu", required=True)
    p.add_argument("--part", default="")
    p.add_argument("--qemu-machine", default="")
    p.add_argument("--flash-budget", type=int, required=True)
    p.add_argument("--ram-budget", type=int, required=True)
    p.add_argument("--stack-budget", type=int, required=True)
    p.add_argument("--fpu", type=int, choices=(0, 1), required=True)
    p.add_argument("--out", type=Path, required=True)
    ns = p.parse_args()

    sec = section_sizes(ns.objdump, ns.elf)
    flash = sum(sec.get(s, 0) for s in (".vectors", ".text", ".ARM.extab", ".ARM.exidx", ".data"))
    ram_static = sec.get(".data", 0) + sec.get(".bss", 0)
    ram = ram_static + sec.get(".stack", 0)

    su, dynamic = read_su(ns.su_root)
    funcs = disassemble(ns.objdump, ns.elf)
    main_depth, main_frames, problems = worst_paths(funcs, su, dynamic, ENTRY)
    main_path = [f["function"] for f in main_frames]
    handler_depth, handler_path = 0, []
    for h in HANDLERS:
        d, frames, prob = worst_paths(funcs, su, dynamic, h)
        problems += prob
        if d > handler_depth:
            handler_depth, handler_path = d, [f["function"] for f in frames]
    stack = main_depth + handler_depth + EXC_FRAME[ns.fpu]
    # The control step alone (what a product firmware's control task needs on top of its caller).
    step_depth, step_frames, _ = worst_paths(funcs, su, dynamic, "arm_ctl_step") if "arm_ctl_step" in funcs else (0, [], [])

    over = []
    if flash > ns.flash_budget:
        over.append(f"flash {flash} > {ns.flash_budget}")
    if ram > ns.ram_budget:
        over.append(f"RAM {ram} > {ns.ram_budget}")
    if stack > ns.stack_budget:
        over.append(f"worst-case stack {stack} > {ns.stack_budget}")
    report = {
        "mcu": ns.mcu, "part": ns.part, "qemu_machine": ns.qemu_machine,
        "flash_bytes": flash, "flash_budget": ns.flash_budget,
        "ram_bytes": ram, "ram_static_bytes": ram_static, "ram_budget": ns.ram_budget,
        "stack_reserved_bytes": sec.get(".stack", 0),
        "stack_worst_case_bytes": stack, "stack_budget": ns.stack_budget,
        "stack_main_path": main_path, "stack_main_frames": main_frames, "stack_main_bytes": main_depth,
        "stack_handler_path": handler_path, "stack_handler_bytes": handler_depth,
        "exception_frame_bytes": EXC_FRAME[ns.fpu],
        "stack_ctl_step_bytes": step_depth, "stack_ctl_step_path": [f["function"] for f in step_frames],
        "sections": sec, "problems": sorted(set(problems)), "over_budget": over,
        "ok": not over and not problems,
    }
    kib = lambda b: f"{b / 1024:.1f} KiB"  # noqa: E731
    print(f"{ns.mcu}: flash {kib(flash)} of {kib(ns.flash_budget)} ({100 * flash / ns.flash_budget:.1f} %), "
          f"RAM {kib(ram)} of {kib(ns.ram_budget)} ({kib(ram_static)} static + {kib(sec.get('.stack', 0))} stack), "
          f"part: {ns.part}")
    print(f"{ns.mcu}: worst-case stack {stack} B of {ns.stack_budget} B reserved "
          f"(main path {main_depth} B: {' > '.join(main_path[:12])}{' ...' if len(main_path) > 12 else ''}; "
          f"+ handler {handler_depth} B + exception frame {EXC_FRAME[ns.fpu]} B)")
    print(f"{ns.mcu}: arm_ctl_step alone needs {step_depth} B of stack ({' > '.join(f['function'] for f in step_frames)})")
    for prob in report["problems"]:
        print(f"{ns.mcu}: stack analysis: {prob}", file=sys.stderr)
    for o in over:
        print(f"{ns.mcu}: OVER BUDGET: {o}", file=sys.stderr)
    if report["ok"]:
        ns.out.write_text(json.dumps(report, indent=2) + "\n")
        return 0
    ns.out.unlink(missing_ok=True)
    return 1


if __name__ == "__main__":
    sys.exit(main())
