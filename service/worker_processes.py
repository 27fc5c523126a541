"""What the service's worker processes (job workers, stream workers) and their supervisors share:
the stop signals a worker leaves to the service (and how a supervisor tells a worker that a stop
signal ended while it started), a lock-free shared flag, single-threaded BLAS for spawned
processes, and how a process ended, in words."""

from __future__ import annotations

import ctypes
import os
import signal
import threading
import time
from typing import Any

__all__ = [
    "StopSignalDeaths",
    "describe_exit",
    "ended_by_stop_signal",
    "ignore_stop_signals",
    "shared_flag",
    "single_threaded_blas",
]

STOP_SIGNAL_GRACE = 3.0
"""Seconds a supervisor holds back the replacement of a worker that a stop signal ended: long
enough for the service's own handler to run and say that the service stops."""


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


def ended_by_stop_signal(exitcode: int | None) -> bool:
    """Whether a process ended by SIGINT or SIGTERM: a worker or helper still starting, which
    does not ignore them yet (:func:`ignore_stop_signals`), dies of the group's stop signal."""
    return exitcode in (-signal.SIGINT, -signal.SIGTERM)


class StopSignalDeaths:
    """Whether a supervisor should replace a dead worker, given how the service is stopping.

    A worker ignores SIGINT and SIGTERM only once it runs (:func:`ignore_stop_signals`); one
    still starting (importing, for a second or two) dies of the stop signal that a service
    manager or Ctrl-C sends to the whole process group. Replacing it would start processes
    while the service stops, with a warning of a death that was none. So: no replacement once
    ``stop_requested`` is set (by the service's signal handler), and a worker ended by SIGINT
    or SIGTERM is replaced only after :data:`STOP_SIGNAL_GRACE` seconds without a stop (a
    signal sent to that worker alone), as the group's signal may reach the worker first.
    """

    def __init__(
        self, stop_requested: threading.Event | None = None, grace: float = STOP_SIGNAL_GRACE
    ) -> None:
        self._stop_requested = stop_requested if stop_requested is not None else threading.Event()
        self._grace = grace
        self._first_seen: dict[int, float] = {}  # pid -> when seen dead of a stop signal

    def replace_now(self, pid: int | None, exitcode: int | None) -> bool:
        """Whether the dead worker ``pid`` that ended with ``exitcode`` is to be replaced now."""
        if self._stop_requested.is_set():
            return False
        if not ended_by_stop_signal(exitcode) or pid is None:
            return True
        now = time.monotonic()
        if now - self._first_seen.setdefault(pid, now) < self._grace:
            return False
        del self._first_seen[pid]
        return True


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
