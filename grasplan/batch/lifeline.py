"""A local batch's worker processes end with the batch process that started them.

:func:`bind_to_parent` is the pool's worker initializer. However the batch process ends
(``kill -9`` included), its workers end too: on Linux the kernel sends each SIGKILL
(``prctl(PR_SET_PDEATHSIG)``); a worker whose parent is already gone when it starts (before the
kernel was asked) ends at once, its parent id no longer being the batch's; and a watchdog thread
checks the parent id every :data:`WATCH_S` seconds, where the kernel cannot do it. Signals a
terminal sends to its whole foreground group (SIGINT, SIGQUIT, SIGHUP) are ignored by the
workers: the batch process decides, stops them (SIGTERM) and cleans up (the batch process turns
every catchable ending signal into that cleanup: :func:`grasplan.io.signals_raise`).

The kernel's "parent" is the thread that started the worker: the pool starts its workers from the
thread that runs the batch, which outlives them (the pool is shut down before the batch returns).
"""
from __future__ import annotations

import os
import signal
import sys
import threading
import time

#: how often a worker's watchdog checks that its parent is still the batch process (s)
WATCH_S = 0.5
#: signals a terminal sends to every process of its foreground group: the workers leave them to the batch
_GROUP_SIGNALS = ("SIGINT", "SIGQUIT", "SIGHUP")
_PR_SET_PDEATHSIG = 1


def _parent_death_signal(signum: int) -> bool:
    """Ask the Linux kernel to send ``signum`` to this process when its parent ends (True when set)."""
    if not sys.platform.startswith("linux"):
        return False
    try:
        import ctypes

        libc = ctypes.CDLL(None, use_errno=True)
        return int(libc.prctl(_PR_SET_PDEATHSIG, signum, 0, 0, 0)) == 0
    except (OSError, AttributeError):
        return False


def _watch(parent_pid: int) -> None:
    while True:
        time.sleep(WATCH_S)
        if os.getppid() != parent_pid:
            os.kill(os.getpid(), signal.SIGKILL)


def bind_to_parent(parent_pid: int) -> None:
    """Worker initializer: end this process with the batch process ``parent_pid`` (see the module doc)."""
    for name in _GROUP_SIGNALS:
        signal.signal(getattr(signal, name), signal.SIG_IGN)
    _parent_death_signal(signal.SIGKILL)
    if os.getppid() != parent_pid:  # the parent ended before the kernel was asked to tell us
        os._exit(1)
    threading.Thread(target=_watch, args=(parent_pid,), name="grasplan-parent-watch", daemon=True).start()
