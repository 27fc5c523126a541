"""What the service's worker processes (job workers, stream workers) and their supervisors share:
how they are started (:func:`worker_context`) and how a worker knows that its service still runs,
the stop signals a worker leaves to the service (and how a supervisor tells a worker that a stop
signal ended while it started), a lock-free shared flag, single-threaded BLAS in the workers, and
how a process ended, in words.

Supervision that survives a death (issue 78). The service process starts the fork server; the
fork server forks every worker, so a worker's parent is the fork server, not the service. Two
deaths, one chain (:mod:`service.fork_server` sets it up, in the fork server and in every process
it forks):

- the fork server dies (``kill -9``, the OOM killer): its workers die with it at once, by a
  parent-death signal (SIGKILL). A worker left running would be an orphan (parent PID 1) that
  claims jobs beyond the worker limit, with no supervisor to time it out. Its supervisor
  (:class:`service.jobs.workers.WorkerPool`) no longer gets its exit status from the fork server
  (:mod:`multiprocessing` reports exit code 255, though the worker may still run); it waits,
  with a :class:`ProcessWatch` on the worker's pid, until the worker has really ended before it
  settles its job and starts the replacement, which starts a new fork server
  (:func:`multiprocessing.forkserver.ensure_running` relaunches one whose pid has ended);
- the service dies: the fork server, whose parent-death signal is :data:`SERVICE_DEATH_SIGNAL`,
  ends, and its workers with it. That signal is caught, not SIGKILL: Linux sends it when the
  *thread* that started the fork server ends, and the service starts a new fork server from
  whichever thread needs a worker first (a supervisor, a request's thread of a pool that ends
  idle threads); the handler ends the fork server only when its parent process is another.

A parent-death signal, rather than a pipe each worker watches: it reaches a worker busy inside
a frame (a decoder that takes seconds, a process stopped with SIGSTOP) and needs no thread in
the fork server (which forks from a single-threaded state) nor any check in the workers' loops.
Where there is none (not Linux), the workers still stop between frames once the service is gone
(:func:`service_alive`) and a supervisor kills a worker whose fork server is gone.
"""

from __future__ import annotations

import ctypes
import multiprocessing
import multiprocessing.forkserver
import os
import select
import signal
import sys
import threading
import time
from collections.abc import Callable
from multiprocessing.context import ForkServerContext
from typing import Any

__all__ = [
    "SERVICE_DEATH_SIGNAL",
    "ProcessWatch",
    "StopSignalDeaths",
    "describe_exit",
    "ended_by_stop_signal",
    "fork_server_pid",
    "ignore_stop_signals",
    "service_alive",
    "set_parent_death_signal",
    "shared_flag",
    "single_threaded_blas",
    "start_fork_server",
    "worker_context",
]

WORKER_MODULES = ("service.fork_server", "service.jobs.runner", "service.streams.worker")
"""What the fork server imports before it forks a worker: its own signal settings first."""

SERVICE_DEATH_SIGNAL = signal.SIGUSR1
"""The fork server's parent-death signal: caught, to tell the end of the thread that started it
from the end of the service (:mod:`service.fork_server`)."""

_PR_SET_PDEATHSIG = 1  # <linux/prctl.h>

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


def fork_server_pid() -> int | None:
    """The pid of the fork server this process starts its workers from, ``None`` before the
    first (:mod:`multiprocessing.forkserver` keeps it in its module state, unexported)."""
    server = getattr(multiprocessing.forkserver, "_forkserver", None)
    return getattr(server, "_forkserver_pid", None)


def set_parent_death_signal(signum: int) -> bool:
    """Have Linux send ``signum`` to this process when its parent ends (``prctl``
    ``PR_SET_PDEATHSIG``); ``False`` where that cannot be set (not Linux).

    Linux's "parent" is the thread that started the process: the signal also comes when that
    thread ends while its process lives on (then caught, see :data:`SERVICE_DEATH_SIGNAL`).
    Cleared in a process's children, and kept after the signal came. The caller checks
    ``os.getppid()`` after setting it: a parent that ended before sends nothing.
    """
    if not sys.platform.startswith("linux"):
        return False
    try:
        prctl = ctypes.CDLL(None, use_errno=True).prctl
    except (OSError, AttributeError):
        return False
    # prctl is variadic and reads its arguments as unsigned long: passed as such, not as int
    arguments = (ctypes.c_ulong(signum), ctypes.c_ulong(0), ctypes.c_ulong(0), ctypes.c_ulong(0))
    return prctl(ctypes.c_int(_PR_SET_PDEATHSIG), *arguments) == 0


class ProcessWatch:
    """Whether a process still runs, for a supervisor that is not its parent (a worker is the
    fork server's child), and a kill that cannot reach another process given its pid since.

    A pidfd (Linux 5.3) refers to the process itself: it becomes readable when the process
    ends, whoever reaps it. Where there is none, the pid is probed with signal 0. Open it while
    the process surely runs (just after it started); :meth:`close` it when done.
    """

    def __init__(self, pid: int) -> None:
        self.pid = pid
        self._fd: int | None = None
        self._ended = False
        try:
            self._fd = os.pidfd_open(pid)
        except ProcessLookupError:
            self._ended = True
        except (AttributeError, OSError):
            pass

    def alive(self) -> bool:
        """Whether the process runs (a zombie has ended)."""
        return not self.wait(0)

    def wait(self, timeout: float) -> bool:
        """Wait up to ``timeout`` seconds for the process to end; whether it has."""
        deadline = time.monotonic() + timeout
        while not self._ended:
            if self._fd is not None:
                # a poll object of its own: one is not to be polled by two threads at once
                poller = select.poll()
                poller.register(self._fd, select.POLLIN)
                left = max(deadline - time.monotonic(), 0.0)
                self._ended = bool(poller.poll(round(left * 1000)))
                return self._ended
            if not _exists(self.pid):
                self._ended = True
            elif time.monotonic() >= deadline:
                return False
            else:
                time.sleep(0.02)
        return True

    def kill(self) -> None:
        """SIGKILL the process, if it still runs."""
        if self._ended:
            return
        try:
            if self._fd is not None:
                signal.pidfd_send_signal(self._fd, signal.SIGKILL)
            else:
                os.kill(self.pid, signal.SIGKILL)
        except ProcessLookupError:
            self._ended = True

    def close(self) -> None:
        """Close the pidfd (a watch still in use then probes the pid)."""
        if self._fd is not None:
            os.close(self._fd)
            self._fd = None


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
