"""A job's result folder, ``results/<id>/``: its published results and its attempts' scratch.

Attempt ``n`` of a job writes as it runs into ``results/<id>/.attempt-<n>/`` (partial MCAP, MP4,
MOT and JSON points); :func:`service.analysis.publish` moves a finished run's files into
``results/<id>/``. Partial files are never read again once their attempt is over, and an
hour of video leaves gigabytes of them, so they go as soon as nothing can need them:

- when an attempt starts, the earlier attempts' folders (the runner);
- when a job fails (an error, a crash of its worker, the time limit) or is cancelled, its
  whole result folder, which holds nothing published (the runner, the worker supervisor); the
  job's record and error stay;
- when a job succeeds, every attempt folder: the published results stay (the runner);
- when the service starts, whatever the rules above left because a service stopped or died
  between (:func:`tidy`, from the housekeeping's first sweep).
"""

from __future__ import annotations

import gzip
import logging
import os
import shutil
from pathlib import Path

from api_schemas.jobs import JobState
from service.jobs.store import JobRecord

log = logging.getLogger(__name__)

ATTEMPT_PREFIX = ".attempt-"


def gzip_copy(path: Path) -> Path:
    """``path`` + ``.gz``: the JSON result compressed, which the download serves to clients
    that accept gzip (about a seventh of the size)."""
    return path.with_name(path.name + ".gz")


def write_gzip_copy(path: Path) -> None:
    """Write :func:`gzip_copy` of the published ``path``: as ``.partial``, then renamed, so a
    worker killed meanwhile leaves no half file under the name the download serves. Best
    effort: without it the file is served as it is, so a failure (a full disk) is logged and
    leaves no partial file."""
    target = gzip_copy(path)
    partial = target.with_name(target.name + ".partial")
    try:
        with path.open("rb") as source, gzip.open(partial, "wb", compresslevel=6) as packed:
            shutil.copyfileobj(source, packed, 1 << 20)
        os.replace(partial, target)
    except OSError as error:
        partial.unlink(missing_ok=True)
        log.warning("no compressed copy of %s (%s): it is served uncompressed", path, error)


def attempt_folder(result_dir: Path, attempt: int) -> Path:
    """Where attempt number ``attempt`` (1 for the first) writes its partial results."""
    return result_dir / f"{ATTEMPT_PREFIX}{attempt}"


def _attempt_number(path: Path) -> int | None:
    number = path.name.removeprefix(ATTEMPT_PREFIX)
    return int(number) if path.name.startswith(ATTEMPT_PREFIX) and number.isdigit() else None


def remove_attempts(result_dir: Path, before: int | None = None) -> int:
    """Remove the attempt folders in ``result_dir`` (only those numbered below ``before`` when
    it is given); returns how many there were."""
    removed = 0
    if not result_dir.is_dir():
        return removed
    for path in result_dir.iterdir():
        number = _attempt_number(path)
        if number is not None and (before is None or number < before):
            shutil.rmtree(path, ignore_errors=True)
            removed += 1
    return removed


def discard(result_dir: Path) -> None:
    """Remove the result folder of a job that failed or was cancelled, partial files and all
    (once the attempt that wrote them is over)."""
    shutil.rmtree(result_dir, ignore_errors=True)


def tidy(record: JobRecord) -> None:
    """Remove what ``record``'s state leaves no use for: everything of a failed or cancelled
    job; the attempt folders of a succeeded one; of a queued or running job, the folders of
    attempts before its current one.

    Safe while workers run: the attempt a worker may start meanwhile has a higher number than
    any removed here (``record.attempts`` is read before).
    """
    if record.state in (JobState.failed, JobState.cancelled):
        discard(record.result_dir)
    elif record.state == JobState.succeeded:
        remove_attempts(record.result_dir)
    elif record.state == JobState.queued:  # its next attempt is attempts + 1
        remove_attempts(record.result_dir, before=record.attempts + 1)
    else:
        remove_attempts(record.result_dir, before=record.attempts)
