"""Inside a stream worker process: frames from Zenoh in, tracks to Zenoh out, live.

One process per stream, forked from the service's fork server
(:func:`service.worker_processes.worker_context`); it opens its own Zenoh session. Zenoh
delivers samples on its own threads; the subscriber callbacks only check the attachment and drop
the sample into a one-frame slot (:class:`LatestFrame`), so the frame the tracker takes next is
always the newest and a slow tracker skips frames instead of queueing them. The main thread
tracks, publishes, and reports its status to the service process over a pipe a few times per
second.
"""

from __future__ import annotations

import collections
import contextlib
import ctypes
import logging
import os
import statistics
import threading
import time
from dataclasses import dataclass, field
from multiprocessing.connection import Connection
from pathlib import Path
from typing import Any

import numpy as np
import zenoh

from api_schemas.jobs import JobOptions
from api_schemas.streams import (
    FrameAttachment,
    StreamCounters,
    StreamSpec,
    StreamState,
    StreamTracksEnded,
    StreamTracksMessage,
)
from api_schemas.tracks import VideoInfo
from service.convert import track_state
from service.frames import TimedFrame
from service.jobs.database import DATABASE_ERRORS
from service.outputs.base import RunSummary, StreamInfo
from service.outputs.mcap_out import McapWriter, salvage
from service.pipelines import (
    PipelineResources,
    build_pipeline,
    enlargement_problem,
    resolved_options,
)
from service.storage import storage_problem
from service.streams.keys import StreamKeys
from service.streams.payloads import (
    H264Frames,
    PayloadError,
    check_frame_size,
    decode_frame,
    frame_attachment,
    is_h264,
    parse_attachment,
    parse_detections,
    to_detections,
)
from service.streams.session import ZenohOptions, ZenohUnavailable, open_session
from service.streams.store import StreamStore
from service.worker_processes import ignore_stop_signals, service_alive
from tracking.detection.base import Detections
from tracking.pipeline import FramePipeline

log = logging.getLogger(__name__)

UPSTREAM_ACTIVE = 5.0
"""Seconds after the last upstream detections message during which the camera counts as having
an upstream detector (and frames wait ``detections_wait`` for theirs)."""

RECENT = 100
"""Frames over which latency percentiles and the frame rate are computed."""

RECORDING_CHUNK_BYTES = 256 * 1024
"""Message bytes per compressed MCAP chunk of a recording (about 16 frames of 360-px H.264 with
their annotations and tracks, 1.6 s at 10 fps): a worker killed mid-recording loses its open
chunk only."""

ID_BLOCK = 100
"""Track ids reserved in the database at a time. The reservation is written before the first
id beyond the last one is published, so the database is written once per this many new people
(not per frame) and a worker that starts again continues above every id that may have gone out;
the price is a gap of up to this many ids after a restart."""

STAMP_GAP = 5.0
"""Seconds between the stamps of consecutive tracked frames from which, if the frames arrived
at least 20 times closer together, the stream warns that the timestamps are not in seconds
(milliseconds make every frame a gap that ends the tracks, and nobody is ever tracked)."""

RESERVE_RETRY = 5.0
"""Seconds before a reservation that failed (a full disk, a locked database) is tried again;
tracking goes on meanwhile."""

DATABASE_TIMEOUT = 5.0
"""Seconds the tracking thread waits for the database's lock (the service writes it too)."""


@dataclass(frozen=True, slots=True)
class StreamContext:
    """What a stream worker needs (picklable: it crosses the process boundary)."""

    spec: StreamSpec
    prefix: str
    zenoh: ZenohOptions
    instance: str
    resources: PipelineResources = field(default_factory=PipelineResources)
    recordings_dir: Path | None = None
    database: str | Path | None = None
    """The service's database (``stream_track_ids``); None: ids start at 1 with each worker."""
    frame_limit: int = 32 * 1024**2
    log_level: str = "info"
    status_interval: float = 0.25


@dataclass(slots=True)
class Incoming:
    """A frame sample as it arrived, attachment checked; ``image`` is already decoded for
    H.264 (every unit is decoded on arrival), else ``None``: decoded when taken."""

    payload: bytes
    encoding: str
    attachment: FrameAttachment
    arrived: float  # time.perf_counter()
    image: np.ndarray | None = None


class LatestFrame:
    """A one-frame slot: a new frame replaces an untaken one, which counts as skipped."""

    def __init__(self) -> None:
        self._ready = threading.Condition()
        self._frame: Incoming | None = None
        self.skipped = 0
        self.skipped_before_taken = 0  # of them, those before the frame taken last

    def offer(self, frame: Incoming) -> None:
        with self._ready:
            if self._frame is not None:
                self.skipped += 1
            self._frame = frame
            self._ready.notify()

    def take(self, timeout: float) -> Incoming | None:
        with self._ready:
            if self._frame is None:
                self._ready.wait(timeout)
            frame, self._frame = self._frame, None
            if frame is not None:  # those skipped later came after it
                self.skipped_before_taken = self.skipped
            return frame

    def count_skipped(self) -> None:
        """Count a frame the tracker took but did not track as skipped."""
        with self._ready:
            self.skipped += 1


class UpstreamBuffer:
    """Upstream detections by frame sequence number, the newest ``capacity`` kept."""

    def __init__(self, capacity: int = 256) -> None:
        self._arrived = threading.Condition()
        self._by_sequence: collections.OrderedDict[int, Detections] = collections.OrderedDict()
        self._arrived_at: dict[int, float] = {}  # time.perf_counter(), by sequence
        self._capacity = capacity
        self.last_seen: float | None = None  # time.monotonic()
        self.received = 0

    def offer(self, sequence: int, detections: Detections) -> None:
        with self._arrived:
            self._by_sequence[sequence] = detections
            self._by_sequence.move_to_end(sequence)
            self._arrived_at[sequence] = time.perf_counter()
            while len(self._by_sequence) > self._capacity:
                oldest, _ = self._by_sequence.popitem(last=False)
                self._arrived_at.pop(oldest, None)
            self.last_seen = time.monotonic()
            self.received += 1
            self._arrived.notify_all()

    def active(self) -> bool:
        seen = self.last_seen
        return seen is not None and time.monotonic() - seen < UPSTREAM_ACTIVE

    def take(self, sequence: int, wait: float) -> Detections | None:
        """The detections of frame ``sequence``, waiting up to ``wait`` s for them to arrive."""
        with self._arrived:
            self._arrived.wait_for(lambda: sequence in self._by_sequence, timeout=wait)
            self._arrived_at.pop(sequence, None)
            return self._by_sequence.pop(sequence, None)

    def forget_before(self, moment: float) -> None:
        """Drop the detections that arrived before ``moment`` (``time.perf_counter()``): after
        the camera started over, they belong to frames of its previous run whose sequence
        numbers the new run reuses."""
        with self._arrived:
            for sequence in [s for s, t in self._arrived_at.items() if t < moment]:
                del self._arrived_at[sequence]
                del self._by_sequence[sequence]


class StreamWorker:
    """One camera's live tracking loop; :meth:`run` returns once ``stop.value`` is true."""

    def __init__(self, context: StreamContext, report) -> None:
        self.context = context
        self.spec = context.spec
        self.keys = StreamKeys(context.prefix, context.spec.camera)
        self._report = report
        self._latest = LatestFrame()
        self._upstream = UpstreamBuffer()
        self._lock = threading.Lock()  # guards the counters the Zenoh threads touch
        self._frames_in = 0
        self._malformed = 0
        self._h264 = H264Frames()
        self._h264_lock = threading.Lock()
        self._processed = 0
        self._used_upstream = 0
        self._restarts = 0
        self._skipped_reported = 0
        self._errors: collections.deque[str] = collections.deque(maxlen=5)
        self._latencies: collections.deque[float] = collections.deque(maxlen=RECENT)
        self._done_at: collections.deque[float] = collections.deque(maxlen=RECENT)
        self._arrived_at: collections.deque[float] = collections.deque(maxlen=RECENT)
        self._last_arrival: float | None = None  # time.monotonic()
        self._last_frame_wall: float | None = None
        self._last_timestamp: float | None = None
        self._last_sequence: int | None = None
        self._last_tracked_arrival = 0.0  # time.perf_counter() of the last frame tracked
        self._stamps_warned = False  # about timestamps that look like another unit
        self._frame_size: tuple[int, int] | None = None  # (width, height) of this run's frames
        # A frame of another size than this run's, not tracked until the next frame says
        # whether the camera changed resolution (same size) or it was a bad one (the old size).
        self._odd_frame: tuple[int, tuple[int, int]] | None = None  # (sequence, (w, h))
        self._id_offset = 0  # added to the tracker's ids (which start at 1 with each tracker)
        self._max_id = 0  # the highest id that may have been published
        self._store: StreamStore | None = None
        self._reserved = 0  # ids up to this are reserved in the database
        self._reserve_retry_at = 0.0  # time.monotonic()
        self._current: StreamTracksMessage | None = None  # the latest tracks message
        self._current_json: bytes | None = None  # the same as published
        self._ended: zenoh.Publisher | None = None  # says when the tracks end
        self._no_tracks = "has no tracks yet"  # the query's answer without one
        self._state = StreamState.waiting
        self._pipeline: FramePipeline | None = None
        self._options = job_options(self.spec)  # what runs: 'auto' resolved by the pipeline
        self._recorder: McapWriter | None = None
        self._recording_path: Path | None = None
        self._segment_start = 0.0  # capture time of the recording's first frame
        self._segment_frames = 0
        self._recording_resumes: float | None = None  # stream time a paused recording resumes
        self._last_report = 0.0

    # -- Zenoh callbacks (Zenoh's threads) ---------------------------------------------------

    def _on_frame(self, sample: zenoh.Sample) -> None:
        arrived = time.perf_counter()
        with self._lock:
            self._frames_in += 1
            self._arrived_at.append(arrived)
            self._last_arrival = time.monotonic()
            self._last_frame_wall = time.time()
        try:
            size = len(sample.payload)
            if size > self.context.frame_limit:
                raise PayloadError(
                    f"frame payload of {size} bytes is over the limit of "
                    f"{self.context.frame_limit} (VTRACK_STREAM_FRAME_LIMIT)"
                )
            raw = sample.attachment.to_bytes() if sample.attachment is not None else None
            attachment = parse_attachment(raw)
        except PayloadError as error:
            self._malformed_sample(str(error))
            return
        payload, encoding = sample.payload.to_bytes(), str(sample.encoding)
        image = None
        if is_h264(encoding):
            # Each unit is coded against the ones before it: all are decoded, in arrival
            # order, before the slot below drops frames the tracker cannot follow.
            try:
                with self._h264_lock:
                    image = self._h264.decode(payload)
            except PayloadError as error:
                self._malformed_sample(f"frame {attachment.sequence}: {error}")
                return
        self._latest.offer(Incoming(payload, encoding, attachment, arrived, image))

    def _on_detections(self, sample: zenoh.Sample) -> None:
        try:
            message = parse_detections(sample.payload.to_bytes())
            detections = to_detections(message)
        except (PayloadError, ValueError) as error:
            self._malformed_sample(str(error))
            return
        self._upstream.offer(message.sequence, detections)

    def _on_query(self, query: zenoh.Query) -> None:
        current = self._current_json
        if current is None:
            query.reply_err(f"camera {self.spec.camera} {self._no_tracks}")
        else:
            query.reply(self.keys.current, current, encoding=zenoh.Encoding.APPLICATION_JSON)

    def _malformed_sample(self, reason: str) -> None:
        with self._lock:
            self._malformed += 1
        self._note_error(reason, logging.WARNING)

    def _note_error(self, reason: str, level: int) -> None:
        """Keep ``reason`` among the status's last errors, and log it."""
        with self._lock:
            self._errors.append(reason)
        log.log(level, "camera %s: %s", self.spec.camera, reason)

    # -- the loop ----------------------------------------------------------------------------

    def run(self, stop: ctypes.c_bool, service_runs=lambda: True) -> None:
        self._salvage_recordings()
        self._open_id_store()
        self._pipeline = self._new_pipeline()
        try:
            session = open_session(self.context.zenoh.member_config())
        except BaseException:
            self._close_id_store()
            raise
        try:
            # Kept referenced: Zenoh undeclares what is garbage collected (the token at least).
            declared = (
                session.declare_subscriber(self.keys.frames, self._on_frame),
                session.declare_subscriber(self.keys.detections, self._on_detections),
                session.declare_queryable(self.keys.current, self._on_query),
                session.liveliness().declare_token(self.keys.tracker_token(self.context.instance)),
            )
            publisher = session.declare_publisher(
                self.keys.tracks, encoding=zenoh.Encoding.APPLICATION_JSON
            )
            # Blocking: the message that tracks ended is sent once and goes out last, just
            # before the session closes when tracking stops.
            self._ended = session.declare_publisher(
                self.keys.ended,
                encoding=zenoh.Encoding.APPLICATION_JSON,
                congestion_control=zenoh.CongestionControl.BLOCK,
            )
            log.info("camera %s: listening on %s", self.spec.camera, self.keys.frames)
            self.report(force=True)
            while not stop.value and service_runs():
                frame = self._latest.take(timeout=0.1)
                if frame is not None:
                    self._track(frame, publisher)
                else:
                    self._check_idle()
                self.report()
            self._announce_end(f"tracking of camera {self.spec.camera} stopped on this instance")
            for entity in declared:
                entity.undeclare()
        finally:
            self._close_recording()
            session.close()
            self._close_id_store()
        self.report(force=True)

    def _open_id_store(self) -> None:
        """Continue above every id an earlier worker of this stream may have published."""
        if self.context.database is None:
            return
        self._store = StreamStore(self.context.database, timeout=DATABASE_TIMEOUT)
        self._reserved = self._store.reserved_track_ids(self.spec.camera)
        self._id_offset = self._max_id = self._reserved
        if self._reserved:
            log.info("camera %s: track ids continue above %d", self.spec.camera, self._reserved)

    def _close_id_store(self) -> None:
        if self._store is not None:
            self._store.close()
            self._store = None

    def _reserve_ids(self, highest: int) -> None:
        """Reserve ids beyond ``highest`` in the database before ``highest`` is published."""
        if self._store is None or highest <= self._reserved:
            return
        now = time.monotonic()
        if now < self._reserve_retry_at:
            return
        up_to = highest + ID_BLOCK
        try:
            self._store.reserve_track_ids(self.spec.camera, up_to)
        except DATABASE_ERRORS as error:
            self._reserve_retry_at = now + RESERVE_RETRY
            self._note_error(
                f"track ids could not be reserved in the database ({error}); tracking goes on, "
                f"but ids above {self._reserved} may be given again if the stream restarts",
                logging.ERROR,
            )
            return
        self._reserved = up_to

    def _new_pipeline(self) -> FramePipeline:
        self._options = job_options(self.spec, self.context.resources)
        return build_pipeline(self._options, self.context.resources)

    def _check_stamp_spacing(self, attachment: FrameAttachment, arrived: float) -> None:
        """Warn once per worker when consecutive frames are stamped far further apart than
        they arrived: timestamps in milliseconds (or another unit) instead of seconds."""
        if self._stamps_warned or self._last_timestamp is None or self._last_sequence is None:
            return
        stamped = attachment.timestamp - self._last_timestamp
        between = arrived - self._last_tracked_arrival
        if stamped > STAMP_GAP and stamped > 20 * between:
            self._stamps_warned = True
            self._note_error(
                f"frames {self._last_sequence} and {attachment.sequence} are stamped "
                f"{stamped:.3g} s apart but arrived {between:.3f} s apart: attachment timestamps "
                "are seconds (Unix time), and a gap that long ends every track; milliseconds?",
                logging.WARNING,
            )

    def _restart(self, why: str, camera_restarted_at: float | None = None) -> None:
        """Start the tracker over; ids keep counting up so no id is ever reused.

        ``camera_restarted_at`` (``time.perf_counter()``): the camera started counting from
        zero again; upstream detections that arrived before then are its previous run's.
        """
        log.info("camera %s: tracks end: %s", self.spec.camera, why)
        self._close_recording()  # a recording holds one run of tracks
        self._pipeline = self._new_pipeline()
        self._id_offset = self._max_id
        self._last_timestamp = None
        self._last_sequence = None
        self._frame_size = None
        if self._odd_frame is not None:
            # Taken but never tracked; whether it was bad cannot be known any more.
            self._odd_frame = None
            self._latest.count_skipped()
        if camera_restarted_at is not None:
            # Otherwise a frame of the new run would take the old run's detections of the
            # same sequence number (those of frames that were skipped, never taken).
            self._upstream.forget_before(camera_restarted_at)
        self._recording_resumes = None  # stream time may start over
        if self._current is not None:
            self._no_tracks = f"has no tracks: they ended ({why})"
        self._announce_end(why)
        self._restarts += 1

    def _announce_end(self, why: str) -> None:
        """Tell the ``tracks/ended`` key that this run's tracks ended, if it published any."""
        current, self._current, self._current_json = self._current, None, None
        if current is None or self._ended is None:
            return
        message = StreamTracksEnded(
            camera=self.spec.camera,
            reason=why,
            sequence=current.sequence,
            timestamp=current.timestamp,
            track_ids=[track.track_id for track in current.tracks],
        )
        try:
            self._ended.put(message.model_dump_json().encode())
        except zenoh.ZError as error:  # a closing session: the liveliness token tells the rest
            log.warning("camera %s: could not say that tracks ended: %s", self.spec.camera, error)

    def _check_idle(self) -> None:
        if self._last_arrival is None:
            return
        silent = time.monotonic() - self._last_arrival
        if silent >= self.spec.end_tracks_after and (
            self._last_timestamp is not None or self._odd_frame is not None
        ):
            # The camera may come back counting from zero: its detections then start over too.
            self._restart(f"no frame for {silent:.1f} s", camera_restarted_at=time.perf_counter())
        if silent >= self.spec.idle_after:
            self._state = StreamState.idle

    def _detections_for(self, sequence: int) -> tuple[Detections | None, str]:
        if not self._upstream.active():
            return None, "service"
        found = self._upstream.take(sequence, self.spec.detections_wait)
        return (found, "upstream") if found is not None else (None, "service")

    def _track(self, frame: Incoming, publisher: zenoh.Publisher) -> None:
        attachment = frame.attachment
        image = frame.image
        try:
            if image is None:
                image = decode_frame(frame.payload, frame.encoding, attachment)
            # Before anything below looks at it: a bad frame leaves the tracker as it was.
            check_frame_size(image)
        except PayloadError as error:
            self._malformed_sample(f"frame {attachment.sequence}: {error}")
            return
        self._state = StreamState.running  # not for frames it cannot read: it is not tracking
        if self._last_sequence is not None and attachment.sequence < self._last_sequence:
            # A publisher that started again counts from zero but stamps with the clock,
            # so its timestamps need not go back.
            self._restart(
                f"frame {attachment.sequence} comes after frame {self._last_sequence}: the "
                "camera (or its publisher) started over",
                camera_restarted_at=frame.arrived,
            )
        elif self._last_timestamp is not None and attachment.timestamp < self._last_timestamp:
            self._restart(
                f"frame {attachment.sequence} is stamped {attachment.timestamp:.3f}, before the "
                f"previous frame ({self._last_timestamp:.3f}): the camera started over",
                camera_restarted_at=frame.arrived,
            )
        size = (image.shape[1], image.shape[0])
        if problem := enlargement_problem(self.spec.detector.upscale, size):
            self._malformed_sample(f"frame {attachment.sequence}: {problem}")
            return
        if not self._same_size(attachment.sequence, size):
            return
        self._check_stamp_spacing(attachment, frame.arrived)
        detections, source = self._detections_for(attachment.sequence)
        assert self._pipeline is not None
        try:
            tracked = self._pipeline.process(image, attachment.timestamp, detections)
        except ValueError as error:
            self._malformed_sample(f"frame {attachment.sequence}: {error}")
            self._restart("the tracker rejected a frame")
            return
        self._last_timestamp = attachment.timestamp
        self._last_sequence = attachment.sequence
        self._last_tracked_arrival = frame.arrived
        tracks = [track_state(t) for t in tracked.tracks]
        for track in tracks:
            track.track_id += self._id_offset
            self._max_id = max(self._max_id, track.track_id)
        self._reserve_ids(self._max_id)
        # the frames between the previous message's and this one (skipped while this one was
        # tracked, later frames replaced each other: they count in the next message)
        skipped = self._latest.skipped_before_taken
        message = StreamTracksMessage(
            frame_index=self._processed,
            timestamp=attachment.timestamp,
            tracks=tracks,
            camera=self.spec.camera,
            sequence=attachment.sequence,
            latency=time.perf_counter() - frame.arrived,
            frames_skipped=skipped - self._skipped_reported,
            detections=source,
        )
        self._skipped_reported = skipped
        body = message.model_dump_json().encode()
        # The attachment repeats the frame's sequence number and capture time, so a consumer
        # can pair tracks with frames without parsing the JSON.
        publisher.put(body, attachment=frame_attachment(attachment.sequence, attachment.timestamp))
        done = time.perf_counter()
        self._current, self._current_json = message, body
        self._processed += 1
        self._used_upstream += source == "upstream"
        self._latencies.append(done - frame.arrived)
        self._done_at.append(done)
        self._record(image, message)

    def _same_size(self, sequence: int, size: tuple[int, int]) -> bool:
        """Whether frame ``sequence`` of ``size`` (width, height) is to be tracked; starts the
        tracker over when the camera changed resolution.

        A new geometry invalidates positions and appearance models (and a recording holds
        frames of one size), so a lasting change starts over. One frame is not enough to tell:
        the first frame of another size waits for the next one. If that one has the same size,
        the camera changed resolution (the first one counts as skipped); if it has the old
        size, the odd frame was a bad one (malformed) and the tracks go on untouched.
        """
        odd, self._odd_frame = self._odd_frame, None
        current = self._frame_size
        if current is None:  # the first frame of this run
            self._frame_size = size
            return True
        if size == current:
            if odd is not None:
                (w, h) = odd[1]
                self._malformed_sample(
                    f"frame {odd[0]}: {w}x{h} between frames of {current[0]}x{current[1]}; dropped"
                )
            return True
        if odd is None or odd[1] != size:
            if odd is not None:
                (w, h) = odd[1]
                self._malformed_sample(
                    f"frame {odd[0]}: {w}x{h}, then a frame of another size; dropped"
                )
            self._odd_frame = (sequence, size)
            return False
        self._latest.count_skipped()  # the first frame of the new size, not tracked
        self._restart(
            f"frames {odd[0]} and {sequence} are {size[0]}x{size[1]}, the frames before them "
            f"{current[0]}x{current[1]}: the camera changed resolution"
        )
        self._frame_size = size
        return True

    # -- recording ---------------------------------------------------------------------------

    def _record(self, image, message: StreamTracksMessage) -> None:
        folder = self.context.recordings_dir
        if not self.spec.record or folder is None:
            return
        if self._recording_resumes is not None and message.timestamp < self._recording_resumes:
            return
        try:
            self._record_frame(folder, image, message)
        except OSError as error:
            self._pause_recording(error, message.timestamp)
        else:
            self._recording_resumes = None

    def _pause_recording(self, error: OSError, timestamp: float) -> None:
        """A recording that cannot be written (a full disk) stops; tracking goes on, and the
        recording starts again ``record_segment`` seconds of stream time later. What it had
        written stays as ``.mcap.partial``, finished when a worker next starts."""
        if self._recorder is not None:
            self._recorder.abort()
            self._recorder = None
        segment = self.spec.record_segment
        self._recording_resumes = timestamp + segment
        found = storage_problem(error)
        problem = found.problem if found else f"{type(error).__name__}: {error}"
        self._note_error(
            f"recording paused: {problem}; tracking goes on and recording tries again in "
            f"{segment:g} s",
            logging.ERROR,
        )

    def _record_frame(self, folder: Path, image, message: StreamTracksMessage) -> None:
        if (
            self._recorder is not None
            and message.timestamp - self._segment_start >= self.spec.record_segment
        ):
            self._close_recording()
        if self._recorder is None:
            folder.mkdir(parents=True, exist_ok=True)
            self._recording_path = _recording_name(folder, self.spec.camera)
            info = StreamInfo(
                width=image.shape[1],
                height=image.shape[0],
                fps=0.0,
                frame_step=1,
                part_names=tuple(self._pipeline.part_names) if self._pipeline else (),
                skeleton=tuple(self._pipeline.skeleton) if self._pipeline else (),
                mode="people",
                options=self._options,
                mcap_images=self.spec.record_images,
            )
            partial = self._recording_path.with_suffix(".mcap.partial")
            # Small chunks: a worker that dies loses at most its open chunk (a second or two).
            self._recorder = McapWriter(
                partial, info, StreamTracksMessage, chunk_size=RECORDING_CHUNK_BYTES
            )
            self._segment_start = message.timestamp
            self._segment_frames = 0
        frame = TimedFrame(message.frame_index, message.timestamp, image)
        self._recorder.write(frame, message)
        self._segment_frames += 1

    def _close_recording(self) -> None:
        """Finish the current recording (the ``.mcap.partial`` becomes ``.mcap``), then delete
        the oldest finished ones beyond ``record_keep``."""
        if self._recorder is None or self._recording_path is None:
            return
        video = VideoInfo(
            width=1,
            height=1,
            frames_announced=0,
            frames_read=self._segment_frames,
            frame_step=1,
        )
        try:
            self._recorder.close(RunSummary(video=video, frames_processed=self._segment_frames))
        except OSError as error:  # the summary did not fit either
            self._pause_recording(error, self._last_timestamp or 0.0)
            return
        os.replace(self._recorder.path, self._recording_path)
        log.info("camera %s: recording saved to %s", self.spec.camera, self._recording_path)
        self._recorder = None
        keep = self.spec.record_keep
        if keep:
            for old in sorted(self._recording_path.parent.glob("*.mcap"))[:-keep]:
                old.unlink(missing_ok=True)
                log.info("camera %s: recording %s deleted (record_keep)", self.spec.camera, old)

    def _salvage_recordings(self) -> None:
        """Finish the recordings a killed predecessor left as ``.mcap.partial``: what it had
        written (all but its open chunk) becomes a ``.mcap`` like any other."""
        folder = self.context.recordings_dir
        if folder is None or not folder.is_dir():
            return
        for partial in sorted(folder.glob("*.mcap.partial")):
            target = partial.with_suffix("")  # x.mcap.partial -> x.mcap
            try:
                kept = salvage(partial, target)
            except Exception:  # a file we cannot read must not keep the camera from starting
                log.exception("camera %s: could not salvage %s", self.spec.camera, partial)
                partial.rename(partial.with_suffix(".broken"))  # x.mcap.broken: not retried
                continue
            partial.unlink()
            if kept:
                log.warning(
                    "camera %s: salvaged %d messages of an unfinished recording into %s",
                    self.spec.camera,
                    kept,
                    target,
                )
            else:
                target.unlink()

    # -- status ------------------------------------------------------------------------------

    def status(self) -> dict[str, Any]:
        """Counters and recent figures, as plain data for the service process."""
        with self._lock:
            counters = StreamCounters(
                frames_in=self._frames_in,
                frames_processed=self._processed,
                frames_skipped=self._latest.skipped,
                malformed=self._malformed,
                detections_in=self._upstream.received,
                detections_used=self._used_upstream,
                restarts=self._restarts,
            )
            errors = list(self._errors)
            last_frame = self._last_frame_wall
            arrived = list(self._arrived_at)
        latencies = sorted(self._latencies)
        return {
            "state": self._state.value,
            "counters": counters.model_dump(),
            "fps": _recent_rate(list(self._done_at)),
            "input_fps": _recent_rate(arrived),
            "latency": statistics.median(latencies) if latencies else None,
            "latency_p95": latencies[int(0.95 * (len(latencies) - 1))] if latencies else None,
            "last_frame_at": last_frame,
            "errors": errors,
            "tracks": self._current_json.decode() if self._current_json else None,
        }

    def report(self, force: bool = False) -> None:
        now = time.monotonic()
        if force or now - self._last_report >= self.context.status_interval:
            self._last_report = now
            self._report(self.status())


def _recent_rate(times: list[float]) -> float | None:
    """Events per second over ``times`` (``time.perf_counter()``, oldest first); None unless
    the last was within 2 s."""
    if len(times) < 2 or time.perf_counter() - times[-1] >= 2.0:
        return None
    return (len(times) - 1) / max(times[-1] - times[0], 1e-9)


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


def job_options(spec: StreamSpec, resources: PipelineResources | None = None) -> JobOptions:
    """The options of a job that tracks as the stream ``spec`` asks (its detector, its
    tracker); with ``resources``, resolved as they run (:func:`~service.pipelines.
    resolved_options`: detector 'auto' -> 'cnn' or 'default', the CNN's model named,
    tracker.pose and tracker.reid true or false with their models: recordings say what ran)."""
    options = JobOptions(detector=spec.detector, tracker=spec.tracker)
    if resources is None:
        return options
    return resolved_options(options, resources)


def stream_main(context: StreamContext, service_pid: int, stop, reports: Connection) -> None:
    """Entry point of a stream worker process; ``reports`` is the write end of the pipe its
    service reads the status from."""
    ignore_stop_signals()
    logging.basicConfig(
        level=context.log_level.upper(),
        format=f"%(asctime)s %(levelname)s stream[{context.spec.camera}] %(name)s: %(message)s",
    )

    def report(update: dict[str, Any]) -> None:
        # Waits while the pipe is full (the service reads it ten times a second, and while it
        # stops its streams); EPIPE once the service is gone, which the loop then notices.
        with contextlib.suppress(OSError):
            reports.send(update)

    worker = StreamWorker(context, report)
    try:
        worker.run(stop, service_runs=service_alive(service_pid))
    except ZenohUnavailable as error:
        report({"state": StreamState.failed.value, "error": f"Zenoh: {error}"})
        raise SystemExit(3) from None
    except Exception as error:  # the status says why the worker died, the log says where
        log.exception("camera %s: the stream worker failed", context.spec.camera)
        why = f"the worker process failed ({type(error).__name__}: {error})"
        report({"state": StreamState.failed.value, "error": why})
        raise SystemExit(1) from None
