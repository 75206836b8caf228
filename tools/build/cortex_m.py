"""The bare-metal Cortex-M images (firmware/port/cortex_m): the QEMU board of each preset, one
run of the golden image and the step's cost it prints, and the processor-in-the-loop image's
place and the clock its figures are stated at."""

from __future__ import annotations

import re
import subprocess
from pathlib import Path

from gen.lib.paths import build_dir

MACHINES = {"cortex-m4": "mps2-an386", "cortex-m7": "mps2-an500", "cortex-m3": "mps2-an385"}

# The clock a PIL run's share of the period is stated at: a representative part's core clock
# (QEMU counts instructions; at one instruction a cycle, the share such a part would use).
STATED_CLOCK = {"cortex-m4": (168e6, "STM32F407-class Cortex-M4F at 168 MHz"),
                "cortex-m7": (216e6, "STM32F767-class Cortex-M7 at 216 MHz"),
                "cortex-m3": (120e6, "STM32F205-class Cortex-M3 at 120 MHz")}


# How far a PIL run's results may be from the software-in-the-loop run of the same method (docs/pil.md):
# newlib's sinf/cosf and glibc's differ in the last bit, and the closed loop carries those
# differences along: each result within PIL_SIL_REL_TOL of itself; a peak (max_abs_*: the
# largest sample of a torque that carries the estimator's high gain on e_dot, where a last-bit
# difference may pick another sample) within PIL_SIL_PEAK_TOL; the estimation error's RMS, the
# small difference of w and w_hat, within PIL_SIL_W_TOL of w's RMS. Measured on the bundled arm's
# 3 s run: 2.6e-4, 4.0e-3 and 1.0e-3 (docs/results/bench-pil.json); each bound is that with a margin.
PIL_SIL_REL_TOL = 1e-3
PIL_SIL_PEAK_TOL = 1e-2
PIL_SIL_W_TOL = 2.5e-3
PIL_SIL_KINDS = ("relative", "peak", "estimation_over_w")

# How far two counts of the same control step may be apart (firmware/port/cortex_m/mcu_clock.c):
# the count starts 0-2 instructions after a SysTick edge (a 3-instruction poll) and ends 0-3 before
# one (4-instruction polls), and the calibrated overhead carries the same error once: each count is
# within 5 of the step's own. Where the edges fall follows the host's clock while the image sleeps,
# so the same run twice gives the same results bit for bit but its counts only within this.
STEP_INSTRUCTIONS_SPREAD = 10


def pil_sil_differences(pil: dict, sil: dict) -> dict[str, tuple[float, str]]:
    """The worst difference of two runs' numeric results, each as the tolerances measure it:
    {kind: (worst, which result)} for each of PIL_SIL_KINDS."""
    worst = {kind: (0.0, "") for kind in PIL_SIL_KINDS}
    for key, value in sil.items():
        if isinstance(value, bool) or not isinstance(value, (int, float, list)) or key not in pil:
            continue
        a, b = (pil[key], value) if isinstance(value, list) else ([pil[key]], [value])
        for i, (x, y) in enumerate(zip(a, b, strict=True)):
            if not (isinstance(x, (int, float)) and isinstance(y, (int, float))) or x == y:
                continue
            if key == "estimation_error_rms":
                kind, d = "estimation_over_w", abs(x - y) / max(sil["w_rms"][i], 1e-300)
            else:
                kind, d = "peak" if key.startswith("max_abs_") else "relative", abs(x - y) / max(abs(x), abs(y))
            if d > worst[kind][0]:
                worst[kind] = (d, key)
    return worst


def pil_image(bdir: Path, preset: str) -> Path:
    """The processor-in-the-loop image of a Cortex-M build folder."""
    return bdir / "firmware" / "port" / "cortex_m" / f"pil_{preset}.elf"


def run_image(preset: str, timeout: float = 600) -> subprocess.CompletedProcess[str]:
    """The preset's golden image under qemu-system-arm with semihosting (exit code = verdict),
    with -icount shift=0: one instruction per virtual nanosecond, so its SysTick counts
    instructions (step_count.c)."""
    from tools.build.packages import ensure

    ensure("cortex-m")
    elf = build_dir(preset) / "firmware" / "port" / "cortex_m" / f"golden_{preset}.elf"
    return subprocess.run(["qemu-system-arm", "-M", MACHINES[preset], "-nographic", "-monitor", "none",
                           "-serial", "none", "-icount", "shift=0", "-semihosting-config",
                           "enable=on,target=native", "-kernel", str(elf)],
                          capture_output=True, text=True, timeout=timeout)


def step_costs(output: str) -> dict[str, float]:
    """Instructions per call the image printed, by what was called."""
    return {name: float(n) for name, n in
            re.findall(r"^step cost: (.+?): ticks per call \S+, instructions per call (\S+)$", output, re.M)}
