"""A job's files, behind one interface: its upload, its attempts' scratch and its results.

Every instance of the service reaches the same storage (scale-out, issue 79). The service
handles a job's files only through :class:`JobFiles`; :class:`FolderFiles` keeps them in a
folder (the data folder, a network file system mount that instances share):

- ``uploads/<id>.receiving`` while an upload arrives, then ``uploads/<id>.<ext>``;
- ``results/<id>/``: the published results, and ``results/<id>/.attempt-<n>/`` where attempt
  ``n`` writes as it runs (partial MCAP, MP4, MOT and JSON points).

Partial files are never read again once their attempt is over, and an hour of video leaves
gigabytes of them, so they go as soon as nothing can need them:

- when an attempt starts, the earlier attempts' folders (:meth:`JobFiles.start_attempt`);
- when a job fails (an error, a crash of its worker, the time limit) or is cancelled, its
  whole result folder, which holds nothing published (:meth:`JobFiles.discard`); the job's
  record and error stay;
- when a job succeeds, every attempt folder: the published results stay
  (:meth:`JobFiles.publish`);
- when the service starts, whatever the rules above left because a service stopped or died
  between (:meth:`JobFiles.tidy`, from the housekeeping's first sweep).

Tracking needs local paths (OpenCV, PyAV and the MCAP and MP4 writers open files by name), so
the interface hands out local paths where a run reads and writes. An S3-compatible store would
fit behind it as follows, without a change to its callers: :meth:`~JobFiles.keep_upload`
uploads the received file as the object ``uploads/<id>.<ext>`` (and removes the local one);
:meth:`~JobFiles.video` downloads it to a local scratch file before the run;
:meth:`~JobFiles.start_attempt` gives a local scratch folder, whose files
:meth:`~JobFiles.publish` uploads as ``results/<id>/<name>``; :meth:`~JobFiles.result_file`
gives what a download serves (a presigned URL to redirect to, or a stream, rather than a
path); the listing and removal methods map to listing and deleting objects by prefix.
"""

from __future__ import annotations

import gzip
import logging
import os
import shutil
import time
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Protocol

from api_schemas.jobs import JobState, OutputFormat

if TYPE_CHECKING:  # the store records where job files are with portable(): no cycle
    from service.analysis import AnalysisResult
    from service.jobs.store import JobRecord

__all__ = ["ATTEMPT_PREFIX", "FolderFiles", "JobFiles"]

log = logging.getLogger(__name__)

ATTEMPT_PREFIX = ".attempt-"
_UPLOADS = "uploads"
_RESULTS = "results"
_JOB_FILES = (_UPLOADS, _RESULTS)
"""The folder's subfolders holding a job's files, one entry per job: its upload and its
results folder."""

VIDEO_SUFFIXES = {".avi", ".mp4", ".mov", ".mkv", ".webm", ".mpg", ".mpeg", ".m4v", ".wmv"}
"""The client's file name suffixes an upload keeps; any other is stored as ``.video``."""


class JobFiles(Protocol):
    """Where a job's upload and results are kept, and what the service does with them."""

    def receiving(self, job_id: str) -> Path:
        """The local file an upload for ``job_id`` is received into, before it is checked."""
        ...

    def keep_upload(self, job_id: str, received: Path, filename: str | None) -> Path:
        """Keep the checked upload ``received`` as the job's video; returns where it is kept
        (recorded with the job). ``filename`` is the client's, for the suffix."""
        ...

    def result_folder(self, job_id: str) -> Path:
        """Where the results of ``job_id`` go (recorded with the job)."""
        ...

    def video(self, record: JobRecord) -> Path:
        """The local path a worker reads the job's video from."""
        ...

    def start_attempt(self, record: JobRecord) -> Path:
        """The local scratch folder the job's current attempt writes into; what earlier
        attempts left is removed."""
        ...

    def end_attempt(self, scratch: Path) -> None:
        """Remove the scratch folder of an attempt that published nothing."""
        ...

    def publish(self, record: JobRecord, result: AnalysisResult) -> dict[OutputFormat, str]:
        """Make a finished run's files the job's results; returns their names by format. The
        attempts' scratch goes."""
        ...

    def result_file(self, record: JobRecord, name: str, *, compressed: bool = False) -> Path | None:
        """The published result ``name`` of the job to serve (``compressed``: its gzip copy),
        or None when it is not there."""
        ...

    def discard(self, record: JobRecord) -> None:
        """Remove the results of a job that failed or was cancelled, partial files and all."""
        ...

    def remove(self, record: JobRecord) -> None:
        """Remove the job's upload and results (raises ``OSError`` when they cannot go)."""
        ...

    def tidy(self, record: JobRecord) -> None:
        """Remove what the job's state leaves no use for (see the module's docstring)."""
        ...

    def uploads(self) -> list[str]:
        """The names of the stored uploads (each starts with its job's id and a dot)."""
        ...

    def upload_idle(self, name: str) -> float | None:
        """Seconds since the upload ``name`` was last written; None when it is gone."""
        ...

    def remove_upload(self, name: str) -> None:
        """Remove the upload ``name``, if it is still there."""
        ...

    def result_folders(self) -> list[str]:
        """The ids of the jobs that have a result folder."""
        ...

    def unwritable(self) -> Path | None:
        """Where uploads or results cannot be written now, or None."""
        ...

    def results_location(self) -> str:
        """Where the results are, as an operator would look for them (for the log)."""
        ...

    def portable(self, path: Path) -> str:
        """How the job database records ``path`` (an upload, a result folder) of these files:
        independent of where the storage is mounted now."""
        ...

    def located(self, stored: str) -> Path:
        """Where a job's file recorded as ``stored`` (:meth:`portable`) is now."""
        ...


@dataclass(frozen=True, slots=True)
class FolderFiles:
    """:class:`JobFiles` in the folder ``root`` (``uploads/``, ``results/``), which every
    instance mounts. Picklable: worker processes get it in their configuration."""

    root: Path

    @property
    def uploads_dir(self) -> Path:
        return self.root / _UPLOADS

    @property
    def results_dir(self) -> Path:
        return self.root / _RESULTS

    def receiving(self, job_id: str) -> Path:
        self.uploads_dir.mkdir(parents=True, exist_ok=True)
        return self.uploads_dir / f"{job_id}.receiving"

    def keep_upload(self, job_id: str, received: Path, filename: str | None) -> Path:
        suffix = Path(filename or "").suffix.lower()
        kept = self.uploads_dir / f"{job_id}{suffix if suffix in VIDEO_SUFFIXES else '.video'}"
        received.rename(kept)
        return kept

    def result_folder(self, job_id: str) -> Path:
        return self.results_dir / job_id

    def video(self, record: JobRecord) -> Path:
        return record.video_path

    def start_attempt(self, record: JobRecord) -> Path:
        _remove_attempts(record.result_dir, before=record.attempts)
        return record.result_dir / f"{ATTEMPT_PREFIX}{record.attempts}"

    def end_attempt(self, scratch: Path) -> None:
        shutil.rmtree(scratch, ignore_errors=True)

    def publish(self, record: JobRecord, result: AnalysisResult) -> dict[OutputFormat, str]:
        from service.analysis import publish  # tracking's imports: only where a run ends

        files = publish(result, record.result_dir)
        if OutputFormat.json in files:
            _write_gzip_copy(files[OutputFormat.json])
        _remove_attempts(record.result_dir)
        return {fmt: path.name for fmt, path in files.items()}

    def result_file(self, record: JobRecord, name: str, *, compressed: bool = False) -> Path | None:
        path = record.result_dir / name
        if compressed:
            path = _gzip_copy(path)
        return path if path.is_file() else None

    def discard(self, record: JobRecord) -> None:
        shutil.rmtree(record.result_dir, ignore_errors=True)

    def remove(self, record: JobRecord) -> None:
        record.video_path.unlink(missing_ok=True)
        # never outside the data folder (the store reads job files as its own), whatever a row says
        inside = record.result_dir.resolve().is_relative_to(self.results_dir.resolve())
        if inside and record.result_dir.exists():
            shutil.rmtree(record.result_dir)

    def tidy(self, record: JobRecord) -> None:
        # Safe while workers run: the attempt a worker may start meanwhile has a higher number
        # than any removed here (``record.attempts`` is read before).
        if record.state in (JobState.failed, JobState.cancelled):
            self.discard(record)
        elif record.state == JobState.succeeded:
            _remove_attempts(record.result_dir)
        elif record.state == JobState.queued:  # its next attempt is attempts + 1
            _remove_attempts(record.result_dir, before=record.attempts + 1)
        else:
            _remove_attempts(record.result_dir, before=record.attempts)

    def uploads(self) -> list[str]:
        if not self.uploads_dir.is_dir():
            return []
        return [path.name for path in self.uploads_dir.iterdir()]

    def upload_idle(self, name: str) -> float | None:
        try:
            return time.time() - (self.uploads_dir / name).stat().st_mtime
        except FileNotFoundError:
            return None

    def remove_upload(self, name: str) -> None:
        (self.uploads_dir / name).unlink(missing_ok=True)

    def result_folders(self) -> list[str]:
        if not self.results_dir.is_dir():
            return []
        return [path.name for path in self.results_dir.iterdir() if path.is_dir()]

    def unwritable(self) -> Path | None:
        for folder in (self.uploads_dir, self.results_dir):
            folder = folder if folder.exists() else self.root  # made by the first job
            if not os.access(folder, os.W_OK):
                return folder
        return None

    def results_location(self) -> str:
        return str(self.results_dir)

    def portable(self, path: Path) -> str:
        # ``results/<id>`` for one in the folder, so that a data folder moved or restored
        # elsewhere keeps its jobs' files; other paths whole
        if path.parent.name in _JOB_FILES and path.parent.parent == self.root:
            return f"{path.parent.name}/{path.name}"
        return str(path)

    def located(self, stored: str) -> Path:
        # Earlier versions stored the whole path as the service then saw it (absolute, or
        # relative to its working folder): read by its last two parts, it is found wherever
        # the folder is now.
        path = Path(stored)
        if path.parent.name in _JOB_FILES:
            return self.root / path.parent.name / path.name
        return path


def _gzip_copy(path: Path) -> Path:
    """``path`` + ``.gz``: the JSON result compressed, which the download serves to clients
    that accept gzip (about a seventh of the size)."""
    return path.with_name(path.name + ".gz")


def _write_gzip_copy(path: Path) -> None:
    """Write :func:`_gzip_copy` of the published ``path``: as ``.partial``, then renamed, so a
    worker killed meanwhile leaves no half file under the name the download serves. Best
    effort: without it the file is served as it is, so a failure (a full disk) is logged and
    leaves no partial file."""
    target = _gzip_copy(path)
    partial = target.with_name(target.name + ".partial")
    try:
        with path.open("rb") as source, gzip.open(partial, "wb", compresslevel=6) as packed:
            shutil.copyfileobj(source, packed, 1 << 20)
        os.replace(partial, target)
    except OSError as error:
        partial.unlink(missing_ok=True)
        log.warning("no compressed copy of %s (%s): it is served uncompressed", path, error)


def _attempt_number(path: Path) -> int | None:
    number = path.name.removeprefix(ATTEMPT_PREFIX)
    return int(number) if path.name.startswith(ATTEMPT_PREFIX) and number.isdigit() else None


def _remove_attempts(result_dir: Path, before: int | None = None) -> int:
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
