"""The worker pool: N processes that run jobs, and the supervisor that keeps them.

The supervisor (a thread of the service process) checks every ``check_interval`` seconds:

- a worker process that died (a crash, the OOM killer, a ``kill -9``) fails the job it was
  running with the reason, and is replaced by a new process;
- a worker that died with its fork server (the fork server killed: every process it forked
  gets SIGKILL, :mod:`service.fork_server`) leaves its job to run again from its start, as a
  stop of the service does: the job did nothing wrong. The first replacement starts a new fork
  server;
- a job that has run longer than ``job_timeout``, or read no frame for ``stall_timeout``
  seconds (a decoder that hangs, a worker stopped with SIGSTOP), is failed with the reason,
  and its worker is killed (and so replaced).

Either way the failed job's partial results are removed once its worker is gone (never
before: a worker still alive could write on).

A worker is dead when its process has ended (:class:`~service.worker_processes.ProcessWatch`),
not when :mod:`multiprocessing` says so: with its fork server gone, that says exit code 255 of
a worker that may still run. Its job is settled, and its replacement started, only once it has
ended: a job whose worker runs is never failed for its death, and no more than ``workers``
workers run at any moment.

On a clean stop, idle workers leave at a flag, busy ones are killed, and the jobs they were
running go back to the queue. Workers ignore the stop signals the whole group gets from birth
(they are forked from a fork server that ignores them); none is replaced once the service stops
(:class:`~service.worker_processes.StopSignalDeaths`).
"""

from __future__ import annotations

import logging
import os
import threading
import time
from contextlib import suppress
from dataclasses import dataclass
from typing import Any

from api_schemas.jobs import JobState
from service.jobs.database import DATABASE_ERRORS
from service.jobs.runner import WorkerConfig, worker_main
from service.jobs.store import JobRecord, JobStore
from service.worker_processes import (
    ProcessWatch,
    StopSignalDeaths,
    describe_exit,
    fork_server_pid,
    shared_flag,
    worker_context,
)

log = logging.getLogger(__name__)

SPAWN_RETRY = 1.0
"""Seconds before a worker that could not be started is tried again (a fork server that died
a moment ago may still refuse; its successor then starts)."""


LOST_FORK_SERVER = 255
"""The exit code :mod:`multiprocessing` gives a worker whose fork server ended before it could
tell the worker's own."""


@dataclass(slots=True)
class _Slot:
    process: Any
    ready: Any
    watch: ProcessWatch  # the worker's own end, whoever its parent is now
    fork_server: int | None  # the pid of the fork server that forked it

    @property
    def pid(self) -> int:
        return self.watch.pid


class WorkerPool:
    """``workers`` processes forked from the fork server (:func:`worker_context`), supervised.

    ``stop_requested`` is set by the service's stop-signal handler, before :meth:`stop` runs
    (the service first waits for its open requests): from then on no worker is replaced.
    """

    def __init__(
        self,
        store: JobStore,
        config: WorkerConfig,
        workers: int,
        job_timeout: float,
        stall_timeout: float = 600.0,
        check_interval: float = 0.25,
        stop_requested: threading.Event | None = None,
        max_attempts: int = 3,
    ) -> None:
        self._store = store
        self._max_attempts = max_attempts
        # on a shared database: the leases of this instance's jobs, renewed; other instances'
        # expired ones, queued again
        self._instance = config.instance if store.shared and config.lease else None
        self._lease = config.lease or 0.0
        self._leases_due = 0.0
        self._database_said = 0.0  # when an unavailable database may be logged again
        self._config = config
        self._size = workers
        self._job_timeout = job_timeout
        self._stall_timeout = stall_timeout
        self._check_interval = check_interval
        self._ctx = worker_context()
        self._stop_workers = shared_flag(self._ctx)
        self._stopping = threading.Event()
        self._deaths = StopSignalDeaths(stop_requested)
        # None: a place whose worker has ended and whose replacement could not start yet. Only
        # the supervisor thread changes the list (start and stop do while it does not run); the
        # lock is for the readers in other threads.
        self._slots: list[_Slot | None] = []
        self._lock = threading.Lock()
        self._thread: threading.Thread | None = None
        self._fork_server: int | None = None  # the fork server the last worker came from
        self._spawn_retry_at = 0.0
        # jobs failed over the time limit, by the pid of their killed worker: their partial
        # results go once it is dead
        self._timed_out: dict[int, JobRecord] = {}
        self.replaced = 0

    # -- lifecycle -------------------------------------------------------------------------

    def start(self) -> None:
        slots: list[_Slot | None] = [self._spawn(i) for i in range(self._size)]
        with self._lock:
            self._slots = slots
        self._thread = threading.Thread(target=self._supervise, name="vtrack-supervisor")
        self._thread.daemon = True
        self._thread.start()
        log.info("started %d worker processes", self._size)

    def stop(self, grace: float = 5.0) -> None:
        """Stop the workers; the jobs they were running are queued again."""
        self._stopping.set()
        if self._thread is not None:
            self._thread.join()
        self._stop_workers.value = True
        with self._lock:
            slots = [slot for slot in self._slots if slot is not None]
        busy = {job.worker_pid: job for job in self._running()}
        for slot in slots:
            if slot.pid in busy:
                slot.watch.kill()  # workers ignore SIGTERM (ignore_stop_signals)
        for slot in slots:
            if not slot.watch.alive() and slot.pid not in busy:
                how = _exit_status(slot)
                log.info("worker %d had ended (%s) and was not replaced", slot.pid, how)
        deadline = time.monotonic() + grace
        for slot in slots:
            if not slot.watch.wait(max(deadline - time.monotonic(), 0.1)):
                slot.watch.kill()
                slot.watch.wait(5.0)
        for slot in slots:
            job = busy.get(slot.pid)
            if job is not None and self._store.requeue_running(job.id, slot.pid):
                log.info("job %s queued again: the service stopped while it ran", job.id)
            _exit_code(slot)  # the fork server's report, which frees the process object
            _release(slot)
        with self._lock:
            self._slots = []
        log.info("worker processes stopped")

    # -- state -----------------------------------------------------------------------------

    @property
    def size(self) -> int:
        return self._size

    def pids(self) -> list[int]:
        with self._lock:
            return [slot.pid for slot in self._slots if slot is not None]

    def alive(self) -> int:
        with self._lock:
            return sum(slot.watch.alive() for slot in self._slots if slot is not None)

    def ready(self) -> int:
        """Workers that have started and opened the store."""
        with self._lock:
            slots = [slot for slot in self._slots if slot is not None]
            return sum(slot.watch.alive() and slot.ready.value for slot in slots)

    # -- supervision -----------------------------------------------------------------------

    def _spawn(self, index: int) -> _Slot:
        """Start a worker; also starts a new fork server if the last one has ended."""
        ready = shared_flag(self._ctx)
        process = self._ctx.Process(
            target=worker_main,
            args=(self._config, os.getpid(), self._stop_workers, ready),
            name=f"vtrack-worker-{index}",
            daemon=True,
        )
        process.start()
        assert process.pid is not None, "a started process has its pid"
        # opened at once: should the worker end before, its pid is not someone else's yet
        watch = ProcessWatch(process.pid)
        server = fork_server_pid()
        if server != self._fork_server:
            if self._fork_server is not None:
                log.warning(
                    "the fork server %d had ended; a new one (pid %s) forks the workers",
                    self._fork_server,
                    server,
                )
            self._fork_server = server
        return _Slot(process, ready, watch, server)

    def _supervise(self) -> None:
        while not self._stopping.wait(self._check_interval):
            try:
                self._keep_leases()
                self._replace_dead()
                self._enforce_time_limit()
            except DATABASE_ERRORS as error:  # a server restarting: no traceback 4 times a second
                if time.monotonic() >= self._database_said:
                    log.warning("the job database is unavailable (%s); trying again", error)
                    self._database_said = time.monotonic() + 10.0
            except Exception:
                log.exception("worker supervision failed; trying again")

    def _keep_leases(self) -> None:
        """On a shared database: renew this instance's claims a few times within a lease, and
        queue again the jobs of instances that stopped renewing theirs (a dead machine)."""
        if self._instance is None or time.monotonic() < self._leases_due:
            return
        self._leases_due = time.monotonic() + self._lease / 3
        self._store.renew_leases(self._instance, self._lease)
        requeued, failed = self._store.requeue_expired(self._max_attempts)
        for job_id in requeued:
            log.warning("job %s queued again: the instance running it was lost", job_id)
        for job_id in failed:
            log.error("job %s failed: the instances running it were lost too often", job_id)

    def _running(self) -> list[JobRecord]:
        """The running jobs of this instance (of the database, when it is not shared)."""
        return self._store.running(self._instance)

    def _replace_dead(self) -> None:
        # every ended worker's job first: starting a replacement may take seconds (a new fork
        # server imports the tracking code)
        for index, slot in enumerate(list(self._slots)):
            if slot is None or self._stopping.is_set() or not _ended(slot):
                continue
            exitcode = _exit_code(slot)
            if not self._deaths.replace_now(slot.pid, exitcode):
                continue
            with self._lock:  # out of the readers' sight before its watch is closed
                self._slots[index] = None
            try:
                self._settle(slot, exitcode)
            except Exception:  # the store, say: settled at the next look
                with self._lock:
                    self._slots[index] = slot
                raise
            self.replaced += 1
        for index, slot in enumerate(list(self._slots)):
            if slot is not None or self._stopping.is_set():
                continue
            if time.monotonic() < self._spawn_retry_at:
                return
            try:
                new = self._spawn(index)
            except Exception as error:  # a fork server dying, or one that cannot start
                log.warning(
                    "worker vtrack-worker-%d could not start (%s: %s); trying again in %g s",
                    index,
                    type(error).__name__,
                    error,
                    SPAWN_RETRY,
                )
                self._spawn_retry_at = time.monotonic() + SPAWN_RETRY
                return
            with self._lock:
                self._slots[index] = new
            log.info("worker %d started in place of the one that ended", new.pid)

    def _settle(self, slot: _Slot, exitcode: int | None) -> None:
        """The ended worker's job and results; its process's resources."""
        pid = slot.pid
        how = describe_exit(exitcode) if exitcode is not None else "exit status unknown"
        server = slot.fork_server
        with_fork_server = exitcode == LOST_FORK_SERVER and not _fork_server_runs(server)
        for job in self._running():
            if job.worker_pid != pid:
                continue
            if with_fork_server:
                # like a death of the service: it starts again from the beginning, unless the
                # fork server has died under it VTRACK_MAX_ATTEMPTS times (a job whose memory
                # makes the OOM killer take the fork server must not do so forever)
                state = self._store.requeue_dead(job.id, pid, self._max_attempts)
                if state is JobState.queued:
                    log.warning(
                        "job %s queued again: the fork server %s died and its worker %d with it",
                        job.id,
                        server,
                        pid,
                    )
                elif state is JobState.failed:
                    log.error("job %s failed: the fork server died under it too often", job.id)
                    self._config.files.discard(job)
            elif self._store.fail_running(
                job.id,
                f"the worker process running this job died ({how}); the job was "
                "stopped and the service went on with a new worker",
                pid,
            ):
                log.error("job %s failed: its worker %d died (%s)", job.id, pid, how)
                self._config.files.discard(job)
        if (timed_out := self._timed_out.pop(pid, None)) is not None:
            self._config.files.discard(timed_out)
        _release(slot)
        if with_fork_server:
            log.warning("worker %d ended with the fork server %s; a new one starts", pid, server)
        else:
            log.warning("worker %d died (%s); a new one starts", pid, how)

    def _enforce_time_limit(self) -> None:
        now = time.time()
        with self._lock:
            ours = {slot.pid: slot for slot in self._slots if slot is not None}
        for job in self._running():
            slot = ours.get(job.worker_pid or -1)
            if slot is None or job.started_at is None:
                continue
            if now - job.started_at > self._job_timeout:
                reason = (
                    f"the job exceeded the time limit of {self._job_timeout:g} s "
                    "(VTRACK_JOB_TIMEOUT) and was stopped"
                )
            elif now - (job.progressed_at or job.started_at) > self._stall_timeout:
                reason = (
                    f"the job read no frame for {self._stall_timeout:g} s "
                    "(VTRACK_JOB_STALL_TIMEOUT): its worker was stopped (a video that hangs "
                    "the decoder, or a worker process stopped from outside)"
                )
            else:
                continue
            if self._store.fail_running(job.id, reason, job.worker_pid):
                log.error("job %s failed: %s; killing its worker", job.id, reason)
                self._timed_out[slot.pid] = job
                slot.watch.kill()


def _ended(slot: _Slot) -> bool:
    """Whether the slot's worker process has ended. One that :mod:`multiprocessing` takes for
    ended while it runs has lost its fork server: killed (its parent-death signal does that
    already, where there is one)."""
    if slot.watch.alive():
        if not slot.process.is_alive():
            slot.watch.kill()
        return False
    return True


def _exit_code(slot: _Slot, timeout: float = 1.0) -> int | None:
    """An ended worker's exit code, as its fork server reports it (at once, normally: the
    fork server reaps its children as they end); ``None`` if it reports none in ``timeout``
    seconds."""
    slot.process.join(timeout)
    return slot.process.exitcode


def _exit_status(slot: _Slot) -> str:
    exitcode = _exit_code(slot)
    return describe_exit(exitcode) if exitcode is not None else "exit status unknown"


def _fork_server_runs(pid: int | None) -> bool:
    """Whether the fork server ``pid`` is the current one and runs (it is this process's child:
    its pid is not reused before it is reaped, which starting its successor does)."""
    if pid is None or pid != fork_server_pid():
        return False
    watch = ProcessWatch(pid)
    try:
        return watch.alive()
    finally:
        watch.close()


def _release(slot: _Slot) -> None:
    """Free an ended worker's process object and watch."""
    with suppress(ValueError):  # its fork server told no exit status: freed when collected
        slot.process.close()
    slot.watch.close()
