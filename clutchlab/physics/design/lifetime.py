"""Worker processes that die with the sweep that started them, and leave Ctrl-C to it.

On Linux every local worker, and the fork server they are forked from, asks the kernel for
SIGKILL when its parent dies (``prctl(PR_SET_PDEATHSIG)``): a sweep killed with SIGKILL
leaves no fork server or worker running. Elsewhere this is a no-op.
"""

from __future__ import annotations

import ctypes
import os
import signal
import sys

__all__ = ["FORKSERVER_ENV", "die_with_parent", "init_worker"]

#: Set to the sweep's PID while its fork server starts; the server, whose parent that is,
#: then arranges to die with it when it imports this module (its preload).
FORKSERVER_ENV = "CLUTCHLAB_DIE_WITH_PARENT"


def die_with_parent() -> None:
    """Ask for SIGKILL when the parent process dies (Linux); exit if it is already gone."""
    if not sys.platform.startswith("linux"):
        return
    parent = os.getppid()
    try:
        libc = ctypes.CDLL(None, use_errno=True)
        libc.prctl(1, int(signal.SIGKILL), 0, 0, 0)  # PR_SET_PDEATHSIG = 1
    except (OSError, AttributeError):
        return
    if os.getppid() != parent:  # the parent died before the request took effect
        os._exit(1)


if os.environ.get(FORKSERVER_ENV) == str(os.getppid()):
    die_with_parent()  # this process is the fork server of that sweep


def init_worker() -> None:
    """Initializer of a local worker process: die with the sweep, leave Ctrl-C to it.

    Ctrl-C in a terminal sends SIGINT to every process of the foreground group; a worker
    ignores it (no traceback per worker), and the sweep stops its workers itself.
    """
    die_with_parent()
    signal.signal(signal.SIGINT, signal.SIG_IGN)
