"""The worker pool: N processes that run jobs, and the supervisor that keeps them.

The supervisor (a thread of the service process) checks every ``check_interval`` seconds:

- a worker process that died (a crash, the OOM killer, a ``kill -9``) fails the job it was
  running with the reason, and is replaced by a new process;
- a job that has run longer than ``job_timeout``, or read no frame for ``stall_timeout``
  seconds (a decoder that hangs, a worker stopped with SIGSTOP), is failed with the reason,
  and its worker is killed (and so replaced).

Either way the failed job's partial results are removed once its worker is gone (never
before: a worker still alive could write on).

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
from dataclasses import dataclass
from typing import Any

from service.jobs.result_folders import discard
from service.jobs.runner import WorkerConfig, worker_main
from service.jobs.store import JobRecord, JobStore
from service.worker_processes import (
    StopSignalDeaths,
    describe_exit,
    shared_flag,
    worker_context,
)

log = logging.getLogger(__name__)


@dataclass(slots=True)
class _Slot:
    process: Any
    ready: Any


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
    ) -> None:
        self._store = store
        self._config = config
        self._size = workers
        self._job_timeout = job_timeout
        self._stall_timeout = stall_timeout
        self._check_interval = check_interval
        self._ctx = worker_context()
        self._stop_workers = shared_flag(self._ctx)
        self._stopping = threading.Event()
        self._deaths = StopSignalDeaths(stop_requested)
        self._slots: list[_Slot] = []
        self._lock = threading.Lock()
        self._thread: threading.Thread | None = None
        # jobs failed over the time limit, by the pid of their killed worker: their partial
        # results go once it is dead
        self._timed_out: dict[int, JobRecord] = {}
        self.replaced = 0

    # -- lifecycle -------------------------------------------------------------------------

    def start(self) -> None:
        with self._lock:
            self._slots = [self._spawn(i) for i in range(self._size)]
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
            slots = list(self._slots)
        busy = {job.worker_pid: job for job in self._store.running()}
        for slot in slots:
            if slot.process.is_alive() and slot.process.pid in busy:
                slot.process.kill()  # workers ignore SIGTERM (ignore_stop_signals)
        for slot in slots:
            if not slot.process.is_alive() and slot.process.pid not in busy:
                how = describe_exit(slot.process.exitcode)
                log.info("worker %d had ended (%s) and was not replaced", slot.process.pid, how)
        deadline = time.monotonic() + grace
        for slot in slots:
            slot.process.join(max(deadline - time.monotonic(), 0.1))
            if slot.process.is_alive():
                slot.process.kill()
                slot.process.join(5.0)
        for slot in slots:
            job = busy.get(slot.process.pid)
            if job is not None and self._store.requeue_running(job.id, slot.process.pid):
                log.info("job %s queued again: the service stopped while it ran", job.id)
            slot.process.close()
        with self._lock:
            self._slots = []
        log.info("worker processes stopped")

    # -- state -----------------------------------------------------------------------------

    @property
    def size(self) -> int:
        return self._size

    def pids(self) -> list[int]:
        with self._lock:
            return [s.process.pid for s in self._slots if s.process.pid is not None]

    def alive(self) -> int:
        with self._lock:
            return sum(s.process.is_alive() for s in self._slots)

    def ready(self) -> int:
        """Workers that have started and opened the store."""
        with self._lock:
            return sum(s.process.is_alive() and s.ready.value for s in self._slots)

    # -- supervision -----------------------------------------------------------------------

    def _spawn(self, index: int) -> _Slot:
        ready = shared_flag(self._ctx)
        process = self._ctx.Process(
            target=worker_main,
            args=(self._config, os.getpid(), self._stop_workers, ready),
            name=f"vtrack-worker-{index}",
            daemon=True,
        )
        process.start()
        return _Slot(process, ready)

    def _supervise(self) -> None:
        while not self._stopping.wait(self._check_interval):
            try:
                self._replace_dead()
                self._enforce_time_limit()
            except Exception:
                log.exception("worker supervision failed; trying again")

    def _replace_dead(self) -> None:
        with self._lock:
            for index, slot in enumerate(self._slots):
                if slot.process.is_alive() or self._stopping.is_set():
                    continue
                if not self._deaths.replace_now(slot.process.pid, slot.process.exitcode):
                    continue
                pid, how = slot.process.pid, describe_exit(slot.process.exitcode)
                for job in self._store.running():
                    if job.worker_pid == pid and self._store.fail_running(
                        job.id,
                        f"the worker process running this job died ({how}); the job was "
                        "stopped and the service went on with a new worker",
                        pid,
                    ):
                        log.error("job %s failed: its worker %d died (%s)", job.id, pid, how)
                        discard(job.result_dir)
                if (timed_out := self._timed_out.pop(pid, None)) is not None:
                    discard(timed_out.result_dir)
                slot.process.join(0)
                slot.process.close()
                self._slots[index] = self._spawn(index)
                self.replaced += 1
                log.warning("worker %d died (%s); replaced", pid, how)

    def _enforce_time_limit(self) -> None:
        now = time.time()
        ours = {pid: slot for slot in self._slots if (pid := slot.process.pid) is not None}
        for job in self._store.running():
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
                self._timed_out[slot.process.pid] = job
                slot.process.kill()
