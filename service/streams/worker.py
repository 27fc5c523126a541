"""Inside a stream worker process: frames from Zenoh in, tracks to Zenoh out, live.

One process per stream, forked from the service's fork server
(:func:`service.worker_processes.worker_context`); it opens its own Zenoh session. Zenoh
delivers samples on its own threads; the subscriber callbacks only check the attachment and drop
the sample into a one-frame slot (:class:`~service.streams.inbox.LatestFrame`), so the frame the
tracker takes next is always the newest and a slow tracker skips frames instead of queueing
them. The main thread runs the frame loop here: it tracks, publishes, and reports its status to
the service process over a pipe a few times per second. What it publishes is built by
:mod:`service.streams.payloads`, with the ids of :mod:`service.streams.track_ids`; what it
records is written by :mod:`service.streams.recording`.
"""

from __future__ import annotations

import collections
import contextlib
import ctypes
import logging
import statistics
import threading
import time
from dataclasses import dataclass, field
from multiprocessing.connection import Connection
from pathlib import Path
from typing import Any

import zenoh

from api_schemas.jobs import JobOptions, OutputFormat
from api_schemas.streams import (
    FrameAttachment,
    StreamCounters,
    StreamSpec,
    StreamState,
    StreamTracksMessage,
)
from service.pipelines import (
    PipelineResources,
    build_pipeline,
    check_options,
    enlargement_problem,
)
from service.streams.inbox import Incoming, LatestFrame, UpstreamBuffer
from service.streams.keys import StreamKeys
from service.streams.payloads import (
    H264Frames,
    PayloadError,
    check_frame_size,
    decode_frame,
    ended_message,
    frame_attachment,
    is_h264,
    parse_attachment,
    parse_detections,
    to_detections,
    tracks_message,
)
from service.streams.recording import Recording
from service.streams.session import ZenohOptions, ZenohUnavailable, open_session
from service.streams.track_ids import TrackIds
from service.streams.zone_events import ZoneEvents
from service.worker_processes import ignore_stop_signals, service_alive
from tracking.detection.base import Detections
from tracking.pipeline import FramePipeline

log = logging.getLogger(__name__)

RECENT = 100
"""Frames over which latency percentiles and the frame rate are computed."""

STAMP_GAP = 5.0
"""Seconds between the stamps of consecutive tracked frames from which, if the frames arrived
at least 20 times closer together, the stream warns that the timestamps are not in seconds
(milliseconds make every frame a gap that ends the tracks, and nobody is ever tracked)."""


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
    sinks: tuple[str, ...] = ()
    """The sinks (webhooks, the MQTT broker) that get the events of the zones and lines,
    through the outbox in ``database``."""


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
        self._ids: TrackIds | None = None  # opened by run
        self._current: StreamTracksMessage | None = None  # the latest tracks message
        self._current_json: bytes | None = None  # the same as published
        self._ended: zenoh.Publisher | None = None  # says when the tracks end
        self._no_tracks = "has no tracks yet"  # the query's answer without one
        self._state = StreamState.waiting
        self._pipeline: FramePipeline | None = None
        self._recording = Recording(context.spec, context.recordings_dir, self._note_error)
        self._zones = ZoneEvents(context, self._note_error)
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
        self._recording.salvage()
        self._ids = TrackIds(self.spec.camera, self.context.database, self._note_error)
        try:
            self._pipeline = self._new_pipeline()
            session = open_session(self.context.zenoh.member_config())
        except BaseException:
            self._ids.close()
            raise
        self._zones.open(session)
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
            self._recording.close()
            self._zones.close()
            session.close()
            self._ids.close()
        self.report(force=True)

    def _new_pipeline(self) -> FramePipeline:
        # planned again at each start: the service's models may have changed since the last
        plan = check_options(job_options(self.spec), self.context.resources)
        pipeline = build_pipeline(plan)
        # the networks compiled for every batch of people now, not on the frames where a new
        # number of people first shows (each compile would drop the frames behind it)
        pipeline.prepare()
        # a recording holds one run of tracks, and says what ran
        self._recording.new_run(pipeline.part_names, pipeline.skeleton, plan.options)
        self._zones.new_run()  # the zones are placed on the new run's first frame
        return pipeline

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
        self._pipeline = self._new_pipeline()
        assert self._ids is not None
        self._ids.start_over()
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
        if self._current is not None:
            self._no_tracks = f"has no tracks: they ended ({why})"
        self._announce_end(why)
        self._restarts += 1

    def _announce_end(self, why: str) -> None:
        """Tell the ``tracks/ended`` key that this run's tracks ended, if it published any."""
        current, self._current, self._current_json = self._current, None, None
        if current is None or self._ended is None:
            return
        try:
            self._ended.put(ended_message(current, why).model_dump_json().encode())
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
        assert self._ids is not None
        # the frames between the previous message's and this one (skipped while this one was
        # tracked, later frames replaced each other: they count in the next message)
        skipped = self._latest.skipped_before_taken
        published = self._ids.published(tracked)
        message = tracks_message(
            published,
            frame_index=self._processed,
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
        events = self._zones.update(published, self._processed - 1, size)
        self._recording.write(image, message, events, self._zones.config)

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
            "analytics": self._zones.counts(),
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


def job_options(spec: StreamSpec) -> JobOptions:
    """The options of a job that tracks as the stream ``spec`` asks (its detector, its
    tracker) and writes what it records (an MCAP with its images)."""
    return JobOptions(
        detector=spec.detector,
        tracker=spec.tracker,
        formats=[OutputFormat.mcap],
        mcap_images=spec.record_images,
    )


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
