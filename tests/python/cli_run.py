"""armctl as a user types it, from a test: tools/armctl itself (the bash bootstrap and the CLI)."""

from __future__ import annotations

import signal
import subprocess

from gen.lib.paths import REPO
from tools.run.procs import communicate_or_kill

ARMCTL = str(REPO / "tools" / "armctl")


def armctl(*args: str, timeout: float = 900.0) -> subprocess.CompletedProcess[str]:
    """armctl, stopped with SIGTERM on a timeout: it then stops its own children (tools/run/procs.py),
    so a hung command fails this test and leaves no process behind to fail the others."""
    p = subprocess.Popen([ARMCTL, *args], cwd=REPO, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        out, err = p.communicate(timeout=timeout)
    except subprocess.TimeoutExpired:
        p.send_signal(signal.SIGTERM)
        out, err = communicate_or_kill(p, 60)
        raise AssertionError(f"armctl {' '.join(args)}: no end after {timeout:g} s\n{out}\n{err[-3000:]}") from None
    return subprocess.CompletedProcess(p.args, p.returncode, out, err)
