"""Tools for users of the streams: publish a video (or a webcam) as a camera, follow tracks.

``vtrack publish`` and ``vtrack subscribe`` (see :mod:`service.cli`) are thin wrappers around
:func:`publish_frames` and :func:`follow_tracks`; tests and ``benchmarks/stream.py`` call these
directly.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Literal

import cv2
import numpy as np
import zenoh

from api_schemas.streams import (
    StreamTracksEnded,
    StreamTracksMessage,
    UpstreamDetection,
    UpstreamDetections,
)
from service.frames import capture_frames, open_frames
from service.outputs.h264 import AccessUnitEncoder
from service.streams.capture_clock import Captured
from service.streams.keys import StreamKeys
from service.streams.payloads import encode_jpeg, frame_attachment
from service.streams.session import ZenohOptions, open_session
from tracking.detection.base import Detections


@dataclass(slots=True)
class PublishReport:
    """What :func:`publish_frames` sent."""

    frames: int
    seconds: float
    late: int
    """Frames sent more than one frame period after their schedule (the source was slow)."""
    subscribed: bool | None = None
    """Whether a subscriber was known before the first frame (None: not waited for)."""


def video_frames(source: str) -> tuple[Iterator[np.ndarray], float | None]:
    """RGB frames of a video file, an image folder, or a webcam (``webcam:0`` or ``0``)."""
    device = source.removeprefix("webcam:")
    if device.isdigit():
        capture = cv2.VideoCapture(int(device))
        if not capture.isOpened():
            raise ValueError(f"cannot open webcam {device}")
        return capture_frames(capture), capture.get(cv2.CAP_PROP_FPS) or None
    frames = open_frames(Path(source))
    return iter(frames), frames.fps


def publish_frames(
    session: zenoh.Session,
    keys: StreamKeys,
    frames: Iterator[np.ndarray | bytes | Captured],
    fps: float | None,
    *,
    payload: Literal["jpeg", "raw", "h264"] = "jpeg",
    quality: int = 90,
    detections: Callable[[int], Detections | None] | None = None,
    detections_scale: float = 1.0,
    first_sequence: int = 0,
    limit: int | None = None,
    on_sent: Callable[[int, float], None] | None = None,
    stop: threading.Event | None = None,
    wait_for_subscriber: float = 0.0,
    block: bool = False,
) -> PublishReport:
    """Publish ``frames`` on ``keys.frames`` at ``fps`` frames per second (as fast as possible
    when ``None``), as a camera does: ``payload`` JPEG, raw ``rgb8`` pixels, or H.264 (one
    Annex B access unit per frame, a key frame every second: what a camera's encoder sends),
    with sequence number and capture time (Unix time) in the attachment: the time it is sent,
    or for a :class:`.Captured` item the time it carries (a network camera's frame,
    :class:`~service.streams.network_camera.NetworkCamera`). An item (or a ``Captured`` item's
    data) that is ``bytes`` is an H.264 access unit a camera encoded itself, published as it
    is.

    ``detections(i)``, when given, supplies the detections of the ``i``-th frame, published on
    ``keys.detections`` right after the frame (an upstream detector), its boxes multiplied by
    ``detections_scale`` (detections made on larger frames). ``on_sent(sequence, t)``
    is called with each frame's publication time (``time.time()``). With
    ``wait_for_subscriber``, the first frame waits up to that many seconds for a subscriber
    (a tracker) to be known: a session that has just opened reaches the others a moment later.
    Frames that the network cannot take at once are dropped, as Zenoh does by default for live
    data; with ``block`` the publisher waits instead (every frame reaches the tracker, which
    then skips what it cannot follow). H.264 is always sent so: the units that follow a lost
    one do not decode until the next key frame.
    """
    block = block or payload == "h264"
    congestion = zenoh.CongestionControl.BLOCK if block else zenoh.CongestionControl.DROP
    frame_publisher = session.declare_publisher(keys.frames, congestion_control=congestion)
    detection_publisher = session.declare_publisher(
        keys.detections, encoding=zenoh.Encoding.APPLICATION_JSON
    )
    subscribed = None
    if wait_for_subscriber > 0:
        waiting = [frame_publisher] + ([detection_publisher] if detections else [])
        subscribed = _wait_for_subscribers(session, keys, waiting, wait_for_subscriber)
    period = 1.0 / fps if fps else 0.0
    encoder: AccessUnitEncoder | None = None
    encoded_shape: tuple[int, ...] = ()
    started = time.perf_counter()
    sent = late = 0
    try:
        for index, frame in enumerate(frames):
            if (limit is not None and sent >= limit) or (stop is not None and stop.is_set()):
                break
            due = started + index * period
            wait = due - time.perf_counter()
            if wait > 0:
                time.sleep(wait)
            elif period and -wait > period:
                late += 1
            sequence = first_sequence + index
            stamp = time.time()
            if isinstance(frame, Captured):
                stamp, frame = frame.time, frame.data
            extra = {}
            if isinstance(frame, bytes):
                data, encoding = frame, zenoh.Encoding.VIDEO_H264
            elif payload == "raw":
                height, width = frame.shape[:2]
                data = np.ascontiguousarray(frame, dtype=np.uint8).tobytes()
                extra = {"width": width, "height": height, "format": "rgb8"}
                encoding = zenoh.Encoding.APPLICATION_OCTET_STREAM
            elif payload == "h264":
                if encoder is None or encoded_shape != frame.shape:  # a camera may change size
                    encoder = AccessUnitEncoder(frame.shape[1], frame.shape[0], "rgb24")
                    encoded_shape = frame.shape
                units = encoder.encode(frame, round(stamp * 1e9))
                data, encoding = b"".join(unit for _, unit in units), zenoh.Encoding.VIDEO_H264
            else:
                data, encoding = encode_jpeg(frame, quality), zenoh.Encoding.IMAGE_JPEG
            frame_publisher.put(
                data, encoding=encoding, attachment=frame_attachment(sequence, stamp, **extra)
            )
            if on_sent is not None:
                on_sent(sequence, stamp)
            found = detections(index) if detections is not None else None
            if found is not None:
                message = detections_message(sequence, found, detections_scale)
                detection_publisher.put(message.model_dump_json())
            sent += 1
    finally:
        frame_publisher.undeclare()
        detection_publisher.undeclare()
    return PublishReport(sent, time.perf_counter() - started, late, subscribed)


def _wait_for_subscribers(
    session: zenoh.Session, keys: StreamKeys, publishers: list[zenoh.Publisher], timeout: float
) -> bool:
    """Wait until every publisher has a subscriber, then until the tracker answers a query.

    In peer mode a subscription is announced through the hub before gossip has connected the
    two sessions directly, and what is published in between is lost; an answer from the
    tracker's queryable proves the direct connection.
    """
    deadline = time.monotonic() + timeout
    # zenoh's stubs type matching_status as a bool; it is a MatchingStatus
    while not all(p.matching_status.matching for p in publishers):  # type: ignore[attr-defined]
        if time.monotonic() >= deadline:
            return False
        time.sleep(0.02)
    reach_tracker(session, keys, timeout=max(deadline - time.monotonic(), 0.5))
    return True


def detections_message(
    sequence: int, detections: Detections, scale: float = 1.0
) -> UpstreamDetections:
    """Detections as an upstream detector publishes them, boxes multiplied by ``scale``."""
    boxes = (detections.boxes * scale).tolist()
    items = [
        UpstreamDetection(x=b[0], y=b[1], w=b[2], h=b[3], score=float(s))
        for b, s in zip(boxes, detections.probabilities, strict=True)
    ]
    return UpstreamDetections(sequence=sequence, detections=items)


def follow_tracks(
    session: zenoh.Session,
    keys: StreamKeys,
    on_message: Callable[[StreamTracksMessage, float], None],
    on_ended: Callable[[StreamTracksEnded, float], None] | None = None,
) -> zenoh.Subscriber:
    """Subscribe to a camera's tracks: ``on_message(message, received)`` for each, with its
    arrival time (``time.time()``), and ``on_ended(message, received)`` when the tracks end
    (the ``tracks/ended`` key). Undeclare the returned subscriber to stop."""

    def received(sample: zenoh.Sample) -> None:
        now = time.time()
        payload = sample.payload.to_bytes()
        if str(sample.key_expr) == keys.ended:
            if on_ended is not None:
                on_ended(StreamTracksEnded.model_validate_json(payload), now)
        else:
            on_message(StreamTracksMessage.model_validate_json(payload), now)

    # "tracks/**" is "tracks" and every key below it: one subscriber for both messages
    return session.declare_subscriber(
        keys.tracks if on_ended is None else f"{keys.tracks}/**", received
    )


class TrackerReplyError(Exception):
    """The camera's tracker answered, with an error instead of tracks (the message says why,
    e.g. ``camera gate has no tracks yet``)."""


def current_tracks(
    session: zenoh.Session, keys: StreamKeys, timeout: float = 2.0
) -> StreamTracksMessage | None:
    """Ask the camera's tracker for its latest tracks (its queryable); None without answer.

    A session that has just opened knows the tracker only once gossip has connected them (a
    fraction of a second), so the question is repeated until ``timeout``.

    Raises
    ------
    TrackerReplyError
        The tracker answered with an error (and no tracker with tracks): it is there, but has
        nothing to say yet.
    """
    deadline = time.monotonic() + timeout
    while True:
        refusals = []
        for reply in session.get(keys.current, timeout=max(deadline - time.monotonic(), 0.1)):
            if reply.ok is not None:
                return StreamTracksMessage.model_validate_json(reply.ok.payload.to_bytes())
            if reply.err is not None:
                refusals.append(reply.err.payload.to_bytes().decode(errors="replace"))
        if refusals:
            raise TrackerReplyError(refusals[0])
        if time.monotonic() >= deadline:
            return None
        time.sleep(0.1)


def reach_tracker(session: zenoh.Session, keys: StreamKeys, timeout: float = 5.0) -> bool:
    """Wait until the camera's tracker answers a query (with tracks or without): then this
    session is connected to it, and its tracks messages reach this session's subscribers."""
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if any(True for _ in session.get(keys.current, timeout=0.5)):
            return True
        time.sleep(0.05)
    return False


def watch_trackers(
    session: zenoh.Session, keys: StreamKeys, changed: Callable[[str, bool], None]
) -> zenoh.Subscriber:
    """Call ``changed(instance, alive)`` when a service instance starts or stops tracking the
    camera, first for those tracking it now. Its liveliness token goes when the stream is
    stopped, the service stops or dies, or the network to it fails. Undeclare the returned
    subscriber to stop."""

    def on_sample(sample: zenoh.Sample) -> None:
        if (instance := tracker_instance(keys, sample.key_expr)) is not None:
            changed(instance, sample.kind == zenoh.SampleKind.PUT)

    return session.liveliness().declare_subscriber(keys.trackers, on_sample, history=True)


def trackers_of(session: zenoh.Session, keys: StreamKeys, timeout: float = 1.0) -> list[str]:
    """Instances whose liveliness token says they track this camera (as this session knows)."""
    found = []
    for reply in session.liveliness().get(keys.trackers, timeout=timeout):
        if reply.ok is not None and (instance := tracker_instance(keys, reply.ok.key_expr)):
            found.append(instance)
    return sorted(found)


def tracker_instance(keys: StreamKeys, key_expr: zenoh.KeyExpr) -> str | None:
    """The instance a tracker's liveliness token names, ``None`` for a token that names no
    single camera and instance: one declared on ``vtrack/trackers/*/x`` matches every camera's
    query, and would put every stream of every service on standby."""
    instance = str(key_expr).removeprefix(keys.trackers[:-1])
    if instance == str(key_expr) or not instance or any(c in instance for c in "*$/"):
        return None
    return instance


def member_session(options: ZenohOptions) -> zenoh.Session:
    """A session that joins the service's Zenoh network as a camera or consumer does."""
    return open_session(options.member_config())
