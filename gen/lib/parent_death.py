"""A child that dies with its parent: the kernel sends it a SIGTERM when the parent goes, even a
SIGKILLed one (PR_SET_PDEATHSIG). Shared by every process armctl starts, its own (tools/run/procs.py)
and the qemu VM's (tools/vm/run.py)."""

from __future__ import annotations

import ctypes
import os
import signal
from collections.abc import Callable

PR_SET_PDEATHSIG = 1  # <linux/prctl.h>
_libc = ctypes.CDLL(None, use_errno=True)


def dies_with_parent(parent: int, then: Callable[[], None] | None = None) -> Callable[[], None]:
    """A preexec_fn: SIGTERM to the child when armctl dies. The kernel sends it when the thread
    that forked the child ends, which is the thread that waits for it here (run_hil), so it comes
    no earlier than armctl's own end of the run. A parent already gone before the prctl: exit."""
    def setup() -> None:
        if _libc.prctl(PR_SET_PDEATHSIG, signal.SIGTERM, 0, 0, 0) != 0 or os.getppid() != parent:
            os._exit(1)
        if then is not None:
            then()
    return setup
