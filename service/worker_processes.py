"""What the service's worker processes (job workers, stream workers) and their supervisors share:
how they are started (:func:`worker_context`) and how a worker knows that its service still runs,
the stop signals a worker leaves to the service (and how a supervisor tells a worker that a stop
signal ended while it started), a lock-free shared flag, single-threaded BLAS in the workers, and
how a process ended, in words."""

from __future__ import annotations

import ctypes
import multiprocessing
import multiprocessing.forkserver
import os
import select
import signal
import threading
import time
from collections.abc import Callable
from multiprocessing.context import ForkServerContext
from typing import Any

__all__ = [
    "StopSignalDeaths",
    "describe_exit",
    "ended_by_stop_signal",
    "ignore_stop_signals",
    "service_alive",
    "shared_flag",
    "single_threaded_blas",
    "start_fork_server",
    "worker_context",
]

WORKER_MODULES = ("service.fork_server", "service.jobs.runner", "service.streams.worker")
"""What the fork server imports before it forks a worker: its own signal settings first."""

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

    A worker forked from the fork server ignores SIGINT and SIGTERM from birth
    (:mod:`service.fork_server`); one started otherwise ignores them only once it runs
    (:func:`ignore_stop_signals`), and while still starting (importing, for a second or two)
    dies of the stop signal that a service manager or Ctrl-C sends to the whole process group.
    Replacing it would start processes while the service stops, with a warning of a death that
    was none. So: no replacement once ``stop_requested`` is set (by the service's signal
    handler), and a worker ended by SIGINT or SIGTERM is replaced only after
    :data:`STOP_SIGNAL_GRACE` seconds without a stop (a signal sent to that worker alone), as
    the group's signal may reach the worker first.
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
    """Make processes started from now on use one BLAS thread (unless the user set it).

    The fork server reads these variables as it imports numpy, and its workers inherit that.
    Workers already run side by side on the cores: BLAS threads on top (the trackers' products)
    would oversubscribe them. A fork server with no BLAS threads also forks no half-copied
    thread pool.
    """
    for name in ("OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
        os.environ.setdefault(name, "1")


def worker_context() -> ForkServerContext:
    """How the service starts its job and stream workers: forked from a fork server that imported
    the tracking code once (:data:`WORKER_MODULES`).

    A spawned worker imported numpy, OpenCV, numba and the trackers afresh, 1.6 s of CPU on our
    2-core machine before a camera's stream could take its first frame, and again for every
    worker replaced. The fork server, a process of its own started with the first worker,
    imports them once (nothing they import starts a thread) and forks each worker from that
    state in a few milliseconds; the workers share its pages until they write them. A worker
    inherits nothing of the service process: no thread, lock, socket or open database.
    """
    single_threaded_blas()
    context = multiprocessing.get_context("forkserver")
    context.set_forkserver_preload(list(WORKER_MODULES))
    return context


def start_fork_server() -> None:
    """Start the fork server now, without a worker: it imports the tracking code on one core
    while the service imports its own on the other (each about 1.5 s), instead of after it.

    The environment the workers are to inherit (:func:`service.logs.quiet_ffmpeg`) must be set
    before: the fork server keeps the one it started with.
    """
    worker_context()
    multiprocessing.forkserver.ensure_running()


def service_alive(pid: int) -> Callable[[], bool]:
    """For a worker of the service process ``pid``: a check, cheap enough for every frame, that
    the service still runs.

    Not ``os.getppid() == pid``: a worker's parent is the fork server, which lives on after the
    service while a worker holds its end of the fork server's pipe. A pidfd becomes readable
    when its process ends (Linux 5.3); where there is none, the pid is probed with signal 0.
    """
    try:
        pidfd = os.pidfd_open(pid)
    except ProcessLookupError:
        return lambda: False
    except (AttributeError, OSError):
        return lambda: _exists(pid)
    poller = select.poll()
    poller.register(pidfd, select.POLLIN)
    return lambda: not poller.poll(0)


def _exists(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except (ProcessLookupError, PermissionError):  # gone, or the pid is now someone else's
        return False
    return True


def shared_flag(ctx: Any) -> Any:
    """A boolean shared with processes of ``ctx``, read and written as ``.value``, without a lock.

    Not a ``multiprocessing.Event``: a process killed while inside ``Event.wait`` or
    ``Event.is_set`` leaves the Event's lock held or a dead waiter behind, and the service's
    ``Event.set`` then waits for ever when it stops its workers.
    """
    return ctx.RawValue(ctypes.c_bool, False)
