"""Inside a worker process: claim queued jobs from the store and run them, one at a time.

A worker is forked from the service's fork server (:func:`service.worker_processes.worker_context`:
nothing of the service inherited but its arguments) and opens its own database connection.
Between frames it reports progress, which is also where it learns that its job was cancelled or
taken away; and it watches the service: when the service process that started it is gone, it
stops at once and leaves the job to the next service, which requeues it.
"""

from __future__ import annotations

import logging
import os
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

from api_schemas.jobs import JobOptions, JobState
from service.analysis import AnalysisStopped, analyze
from service.frames import FrameSourceError
from service.jobs.database import DATABASE_ERRORS
from service.jobs.files import FolderFiles, JobFiles
from service.jobs.store import JobRecord, JobStore
from service.pipelines import OptionsError, PipelineResources
from service.storage import storage_problem
from service.worker_processes import ignore_stop_signals, service_alive

log = logging.getLogger(__name__)


@dataclass(frozen=True, slots=True)
class WorkerConfig:
    """What a worker process needs (picklable: it crosses the process boundary)."""

    database: str | Path
    """The job database: the SQLite file, or the PostgreSQL URL."""
    files: FolderFiles
    """The jobs' uploads and results (the data folder, which the job database's paths are
    relative to)."""
    poll_interval: float
    resources: PipelineResources
    log_level: str = "info"
    progress_interval: float = 0.5
    instance: str | None = None
    """The service instance the worker belongs to (its claims name it)."""
    lease: float | None = None
    """Seconds a claim holds on a shared database unless the instance renews it."""
    sinks: tuple[str, ...] = ()
    """The sinks (webhooks, the MQTT broker) that hear of every job that ends."""


SHARED_IDLE_WAIT = 2.0
"""Seconds an idle worker of a shared database waits for a notification before it looks at
the queue, its stop flag and its service again."""


class Orphaned(Exception):
    """The service process that started this worker is gone."""


def worker_main(config: WorkerConfig, service_pid: int, stop, ready) -> None:
    """Entry point of a worker process: run jobs until ``stop`` is set or the parent dies.

    ``stop`` and ``ready`` are lock-free shared flags (:func:`service.jobs.workers.shared_flag`).
    """
    ignore_stop_signals()
    logging.basicConfig(
        level=config.log_level.upper(),
        format=f"%(asctime)s %(levelname)s worker[{os.getpid()}] %(name)s: %(message)s",
    )
    service_runs = service_alive(service_pid)
    store = JobStore(config.database, folder=config.files.root, sinks=config.sinks)
    pid = os.getpid()
    # on a shared database a queued job wakes the worker (NOTIFY): it need not look often
    idle_wait = config.poll_interval
    if store.shared:
        idle_wait = max(idle_wait, SHARED_IDLE_WAIT)
    ready.value = True
    try:
        while not stop.value:
            if not service_runs():
                log.warning("the service process is gone; this worker stops")
                return
            try:
                job = store.claim(pid, config.instance, config.lease)
            except DATABASE_ERRORS as error:  # a database server restarting: look again later
                log.warning("the job database is unavailable (%s); looking again", _line(error))
                store.wait_for_work(idle_wait)
                continue
            if job is None:
                store.wait_for_work(idle_wait)
                continue
            try:
                run_job(store, job, config, service_runs)
            except Orphaned:
                log.warning("the service process is gone; job %s is left to be requeued", job.id)
                return
    finally:
        store.close()


def run_job(
    store: JobStore, job: JobRecord, config: WorkerConfig, service_runs: Callable[[], bool]
) -> None:
    """Run one claimed job to its end state; ``service_runs`` says whether the service runs."""
    pid = os.getpid()
    log.info("job %s: attempt %d starts", job.id, job.attempts)
    files = config.files
    # what the earlier attempts left (a restart, a stop of the service) is never read again
    scratch = files.start_attempt(job)
    reported = 0

    def progress(frames_read: int, frames_processed: int, fps: float | None) -> bool:
        nonlocal reported
        if not service_runs():
            raise Orphaned
        try:
            own = store.report_progress(job, pid, frames_read, fps, frames_processed - reported)
        except DATABASE_ERRORS as error:
            # the job goes on; a later report says whether it is still this attempt's
            log.warning("job %s: progress not recorded (%s)", job.id, _line(error))
            return True
        reported = frames_processed
        return own

    try:
        options = JobOptions.from_stored(job.options)
        result = analyze(
            files.video(job),
            options,
            scratch,
            resources=config.resources,
            job_id=job.id,
            filename=job.video_filename,
            progress=progress,
            progress_interval=config.progress_interval,
        )
    except Orphaned:
        raise
    except AnalysisStopped:
        _stopped(store, job, files, scratch)
        return
    except (FrameSourceError, OptionsError, ValueError) as error:
        files.end_attempt(scratch)
        # the client is told of its upload by the name it sent, not where the service keeps it
        name = repr(job.video_filename) if job.video_filename else "the upload"
        _failed(
            store,
            job,
            files,
            f"the job could not run: {str(error).replace(str(job.video_path), name)}",
        )
        log.warning("job %s: failed: %s", job.id, error)
        return
    except Exception as error:
        vanished = not scratch.is_dir()
        # The partial results go first: on a full disk that makes room to record the failure.
        files.end_attempt(scratch)
        problem = storage_problem(error)
        if problem is None and vanished and isinstance(error, FileNotFoundError):
            message = (
                f"the job's results folder {job.result_dir} was removed while the job ran (by "
                "hand, or by a program cleaning the data folder); submit the job again"
            )
            log.error("job %s: failed: %s", job.id, message)
        elif problem is None:
            log.exception("job %s: internal error", job.id)
            message = f"internal error while tracking ({type(error).__name__}: {error})"
        else:
            log.error("job %s: failed: %s", job.id, problem.problem)
            message = (
                f"{problem.problem} while the results were written; the partial results were "
                f"removed: {problem.remedy}, then submit the job again"
            )
        _failed(store, job, files, message)
        return
    fps = result.frames_processed / max(result.seconds, 1e-9)
    if not progress(result.video.frames_read, result.frames_processed, fps):
        _stopped(store, job, files, scratch)
        return
    published = files.publish(job, result)
    _patiently(
        store.finish,
        job,
        pid,
        JobState.succeeded,
        results={fmt.value: name for fmt, name in published.items()},
        warnings=result.warnings,
        frames_total=result.video.frames_read,
        analytics=result.analytics,
    )
    log.info(
        "job %s: succeeded, %d frames in %.1f s", job.id, result.frames_processed, result.seconds
    )
    for warning in result.warnings:  # what a damaged video cost, as its client is told
        log.info("job %s: warning: %s", job.id, warning)


DATABASE_PATIENCE = 120.0
"""Seconds a worker tries to record a job's end while the database is away (a server that
restarts); then the worker gives up and ends, and its supervisor settles the job."""


def _patiently(write: Callable[..., bool], *args, **kwargs) -> bool:
    """``write(*args, **kwargs)``, tried again every second while the database is away."""
    deadline = time.monotonic() + DATABASE_PATIENCE
    while True:
        try:
            return write(*args, **kwargs)
        except DATABASE_ERRORS as error:
            if time.monotonic() > deadline:
                raise
            log.warning("the job database is unavailable (%s); trying again", _line(error))
            time.sleep(1.0)


def _line(error: Exception) -> str:
    """An error's first line (psycopg's messages run over several)."""
    return (str(error).strip().splitlines() or [type(error).__name__])[0]


def _failed(store: JobStore, job: JobRecord, files: JobFiles, error: str) -> None:
    """Record the attempt's failure; the job's result folder goes with it (nothing there was
    published), but only when the job was still this attempt's to fail."""
    if _patiently(store.finish, job, os.getpid(), JobState.failed, error=error):
        files.discard(job)


def _stopped(store: JobStore, job: JobRecord, files: JobFiles, scratch: Path) -> None:
    """The run stopped because the job was cancelled or is no longer this attempt's."""
    files.end_attempt(scratch)
    if store.cancel_requested(job.id):
        if store.finish(job, os.getpid(), JobState.cancelled, error="cancelled on request"):
            files.discard(job)  # the record says it was cancelled; no empty folder
        log.info("job %s: cancelled", job.id)
    else:
        # its folder is the next attempt's now, or the supervisor's to remove
        log.warning("job %s: no longer this worker's (failed or requeued elsewhere)", job.id)
