"""A camera's recordings: its tracked frames, their annotations and tracks, as MCAP segments.

Each segment is written by the uploads' :class:`~service.outputs.mcap_out.McapWriter` in stream
mode (:meth:`~service.outputs.base.StreamInfo.of_stream`) into ``<camera>-<UTC time>.mcap
.partial``, renamed to ``.mcap`` once finished. A segment holds one run of tracks: it ends
after ``record_segment`` seconds of stream time and whenever the tracks start over. The oldest
finished ones beyond ``record_keep`` are deleted. What a killed worker left unfinished is
salvaged by the next one (:func:`~service.outputs.mcap_out.salvage`).
"""

from __future__ import annotations

import logging
import os
import time
from collections.abc import Callable, Sequence
from pathlib import Path

import numpy as np

from api_schemas.analytics import AnalyticsEvent
from api_schemas.jobs import JobOptions
from api_schemas.streams import StreamSpec, StreamTracksMessage
from service.frames import TimedFrame
from service.outputs.base import RunSummary, StreamInfo
from service.outputs.mcap_out import McapWriter, salvage
from service.storage import storage_problem
from tracking.analytics import AnalyticsConfig

log = logging.getLogger(__name__)


class Recording:
    """The recordings of the stream ``spec`` in ``folder`` (None: the service records none).

    Parameters
    ----------
    spec:
        The stream: whether it records, its images, segment length and how many to keep.
    folder:
        Where the camera's recordings go.
    note_error:
        Told, with a log level, why a recording paused (tracking goes on).
    """

    def __init__(
        self,
        spec: StreamSpec,
        folder: Path | None,
        note_error: Callable[[str, int], None],
    ) -> None:
        self._spec = spec
        self._camera = spec.camera
        self._dir = folder
        self._folder = folder if spec.record else None  # where this worker records
        self._note_error = note_error
        self._run: tuple[tuple[str, ...], tuple[tuple[str, str], ...], JobOptions] | None = None
        self._writer: McapWriter | None = None
        self._path: Path | None = None  # the finished segment's name
        self._segment_start = 0.0  # capture time of the segment's first frame
        self._frames = 0  # in the segment
        self._last_timestamp = 0.0  # of the last frame written
        self._resumes: float | None = None  # stream time a paused recording resumes

    def new_run(
        self,
        part_names: tuple[str, ...],
        skeleton: tuple[tuple[str, str], ...],
        options: JobOptions,
    ) -> None:
        """A new tracker takes over (the options as they run): the segment of the tracks that
        ended is finished; the next frame starts one of the new tracks."""
        self.close()
        self._run = (part_names, skeleton, options)
        self._resumes = None  # stream time may start over

    def write(
        self,
        image: np.ndarray,
        message: StreamTracksMessage,
        events: Sequence[AnalyticsEvent] = (),
        zones: AnalyticsConfig | None = None,
    ) -> None:
        """Record one tracked frame (RGB ``image``), its ``message`` as published and the
        ``events`` of the ``zones`` and lines watched."""
        if self._folder is None:
            return
        if self._resumes is not None and message.timestamp < self._resumes:
            return
        try:
            self._write(self._folder, image, message, events, zones)
        except OSError as error:
            self._pause(error, message.timestamp)
        else:
            self._resumes = None

    def close(self) -> None:
        """Finish the current segment (the ``.mcap.partial`` becomes ``.mcap``), then delete
        the oldest finished ones beyond ``record_keep``."""
        if self._writer is None or self._path is None:
            return
        try:
            self._writer.close(RunSummary(video=None, frames_processed=self._frames))
        except OSError as error:  # the summary did not fit either
            self._pause(error, self._last_timestamp)
            return
        os.replace(self._writer.path, self._path)
        log.info("camera %s: recording saved to %s", self._camera, self._path)
        self._writer = None
        keep = self._spec.record_keep
        if keep:
            for old in sorted(self._path.parent.glob("*.mcap"))[:-keep]:
                old.unlink(missing_ok=True)
                log.info("camera %s: recording %s deleted (record_keep)", self._camera, old)

    def salvage(self) -> None:
        """Finish the recordings a killed predecessor left as ``.mcap.partial`` (whether this
        worker records or not): what it had written (all but its open chunk) becomes a
        ``.mcap`` like any other."""
        if self._dir is None or not self._dir.is_dir():
            return
        for partial in sorted(self._dir.glob("*.mcap.partial")):
            target = partial.with_suffix("")  # x.mcap.partial -> x.mcap
            try:
                kept = salvage(partial, target)
            except Exception:  # a file we cannot read must not keep the camera from starting
                log.exception("camera %s: could not salvage %s", self._camera, partial)
                partial.rename(partial.with_suffix(".broken"))  # x.mcap.broken: not retried
                continue
            partial.unlink()
            if kept:
                log.warning(
                    "camera %s: salvaged %d messages of an unfinished recording into %s",
                    self._camera,
                    kept,
                    target,
                )
            else:
                target.unlink()

    def _write(
        self,
        folder: Path,
        image: np.ndarray,
        message: StreamTracksMessage,
        events: Sequence[AnalyticsEvent],
        zones: AnalyticsConfig | None,
    ) -> None:
        if (
            self._writer is not None
            and message.timestamp - self._segment_start >= self._spec.record_segment
        ):
            self.close()
        if self._writer is None:
            folder.mkdir(parents=True, exist_ok=True)
            self._path = _recording_name(folder, self._camera)
            part_names, skeleton, options = self._run or ((), (), JobOptions())
            info = StreamInfo.of_stream(
                width=image.shape[1],
                height=image.shape[0],
                part_names=part_names,
                skeleton=skeleton,
                options=options,
                images=self._spec.record_images,
                analytics=zones,
            )
            self._writer = McapWriter(self._path.with_suffix(".mcap.partial"), info)
            self._segment_start = message.timestamp
            self._frames = 0
        frame = TimedFrame(message.frame_index, message.timestamp, image)
        self._writer.write(frame, message, events)
        self._frames += 1
        self._last_timestamp = message.timestamp

    def _pause(self, error: OSError, timestamp: float) -> None:
        """A recording that cannot be written (a full disk) stops; tracking goes on, and the
        recording starts again ``record_segment`` seconds of stream time later. What it had
        written stays as ``.mcap.partial``, finished when a worker next starts."""
        if self._writer is not None:
            self._writer.abort()
            self._writer = None
        segment = self._spec.record_segment
        self._resumes = timestamp + segment
        found = storage_problem(error)
        problem = found.problem if found else f"{type(error).__name__}: {error}"
        self._note_error(
            f"recording paused: {problem}; tracking goes on and recording tries again in "
            f"{segment:g} s",
            logging.ERROR,
        )


def _recording_name(folder: Path, camera: str) -> Path:
    """``<camera>-<UTC time to the millisecond>.mcap``, names that sort in time order (a name
    taken already moves on by a millisecond)."""
    millis = int(time.time() * 1000)
    while True:
        stamp = time.strftime("%Y%m%dT%H%M%S", time.gmtime(millis // 1000))
        path = folder / f"{camera}-{stamp}{millis % 1000:03d}Z.mcap"
        if not (path.exists() or path.with_suffix(".mcap.partial").exists()):
            return path
        millis += 1
