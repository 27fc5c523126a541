"""What the service's worker processes (job workers, stream workers) and their supervisors share:
the stop signals a worker leaves to the service, a lock-free shared flag, single-threaded BLAS
for spawned processes, and how a process ended, in words."""

from __future__ import annotations

import ctypes
import os
import signal
from typing import Any

__all__ = ["describe_exit", "ignore_stop_signals", "shared_flag", "single_threaded_blas"]


def ignore_stop_signals() -> None:
    """Leave stopping to the service process: ignore SIGINT and SIGTERM in a worker.

    Ctrl-C in a terminal reaches the whole process group, and so does a service manager's
    SIGTERM (systemd's default KillMode stops every process of the unit at once). A worker
    that died of it would be taken for a crash and its job failed; the service process,
    stopping, requeues the jobs its workers were running and ends the workers itself (SIGKILL
    for a busy job worker; a stop flag, then SIGKILL after a grace period, for a stream).
    """
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    signal.signal(signal.SIGTERM, signal.SIG_IGN)


def describe_exit(exitcode: int | None) -> str:
    """'exit code 3', 'killed by SIGKILL'..."""
    if exitcode is None:
        return "still running"
    if exitcode < 0:
        try:
            return f"killed by {signal.Signals(-exitcode).name}"
        except ValueError:
            return f"killed by signal {-exitcode}"
    return f"exit code {exitcode}"


def single_threaded_blas() -> None:
    """Make processes spawned from now on start with one BLAS thread (unless the user set it).

    A spawned worker imports numpy afresh and reads these variables then. Workers already run
    side by side on the cores: BLAS threads on top (the trackers' products) would oversubscribe
    them.
    """
    for name in ("OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
        os.environ.setdefault(name, "1")


def shared_flag(ctx: Any) -> Any:
    """A boolean shared with processes of ``ctx``, read and written as ``.value``, without a lock.

    Not a ``multiprocessing.Event``: a process killed while inside ``Event.wait`` or
    ``Event.is_set`` leaves the Event's lock held or a dead waiter behind, and the service's
    ``Event.set`` then waits for ever when it stops its workers.
    """
    return ctx.RawValue(ctypes.c_bool, False)
