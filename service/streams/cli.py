"""``vtrack publish`` and ``vtrack subscribe``: a camera and a consumer for the live streams."""

from __future__ import annotations

import argparse
import dataclasses
import json
import os
import re
import sys
import threading
import time
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import TYPE_CHECKING

import zenoh

from api_schemas.streams import (
    CAMERA_PATTERN,
    PREFIX_PATTERN,
    StreamTracksEnded,
    StreamTracksMessage,
)
from service.argument_types import number_type
from service.streams.keys import StreamKeys
from service.streams.session import (
    ZenohOptions,
    ZenohUnavailable,
    wait_for_neighbour,
    zenoh_endpoint,
)
from tracking.output_paths import output_file

if TYPE_CHECKING:
    import numpy as np

    from service.streams.capture_clock import Captured


def _settings(command: str):
    """The service's settings (VTRACK_*), as the tools share them; exits 2 when invalid."""
    from service.settings import InvalidSettings, load_settings

    try:
        return load_settings()
    except InvalidSettings as error:
        for problem in error.problems:
            print(f"vtrack {command}: {problem}", file=sys.stderr)
        raise SystemExit(2) from None


def _zenoh_options(args: argparse.Namespace, settings) -> ZenohOptions:
    """The service's Zenoh settings (VTRACK_ZENOH_*), with ``--connect``/``--mode`` over them."""
    options = settings.zenoh
    if args.connect:
        options = dataclasses.replace(options, listen=(), connect=tuple(args.connect))
    if args.mode:
        options = dataclasses.replace(options, mode=args.mode)
    return options


def _session(args: argparse.Namespace, command: str) -> tuple[zenoh.Session, StreamKeys] | None:
    """The command's Zenoh session and the camera's keys, or None after saying why not."""
    from service.streams.tools import member_session

    settings = _settings(command)
    keys = StreamKeys(args.prefix or settings.zenoh_prefix, args.camera)
    options = _zenoh_options(args, settings)
    try:
        session = member_session(options)
    except ZenohUnavailable as error:
        hint = ""
        if options.security.configured:  # a refused login and a wrong CA look alike from here
            hint = (
                " (with TLS or a user: check VTRACK_ZENOH_USER and VTRACK_ZENOH_PASSWORD, and "
                "that VTRACK_ZENOH_TLS_ROOT_CA signed the service's certificate)"
            )
        print(f"vtrack {command}: {error}{hint}", file=sys.stderr)
        return None
    if not wait_for_neighbour(session, REACH_SECONDS):
        endpoints = ", ".join(options.member_endpoints())
        _tell(
            command,
            (f"nothing answers at {endpoints}" if endpoints else "no Zenoh peer or router found")
            + " (is vtrack serve running there? --connect names another endpoint; "
            "VTRACK_ZENOH_LISTEN and VTRACK_ZENOH_CONNECT set the defaults); trying again in "
            "the background",
        )
    return session, keys


_STDERR = threading.Lock()

REACH_SECONDS = 1.0

DEFAULT_JPEG_QUALITY = 90
DEFAULT_CAMERA_TIMEOUT = 5.0
"""``vtrack publish``'s defaults (its flags default to None: given or not tells which
options apply to the source, so one that would do nothing is refused)."""
"""How long a tool waits for its session to reach the service before it says nothing answers
(on loopback and LANs a reachable hub answers while the session opens)."""


def _tell(command: str, news: str) -> None:
    """One whole stderr line (Zenoh's threads report too)."""
    with _STDERR:
        sys.stderr.write(f"vtrack {command}: {news}\n")
        sys.stderr.flush()


def _tracker_news(command: str, camera: str, going_on: str) -> Callable[[str, bool], None]:
    """What ``command`` says when a tracker of ``camera`` comes up or goes away: a camera or a
    consumer that goes on regardless should say why nothing comes through."""

    def changed(instance: str, alive: bool) -> None:
        if alive:
            _tell(command, f"camera {camera} is tracked by {instance}")
        else:
            _tell(
                command,
                f"the tracker of camera {camera} ({instance}) went away: the stream or the "
                f"service stopped, or the network to it is down; {going_on}",
            )

    return changed


def _publish(args: argparse.Namespace) -> int:
    from service.streams.network_camera import (
        CameraSettings,
        NetworkCamera,
        is_stream_url,
        redacted,
    )
    from service.streams.tools import publish_frames, video_frames, watch_trackers
    from tracking.detection import MotDetections

    camera = is_stream_url(args.source)
    # an option that would do nothing here is refused, not ignored
    problem = None
    if camera and (args.fps or args.loop):
        problem = (
            "--fps and --loop are for files: a network camera sends at its own rate (the "
            "tracker skips what it cannot follow) and is connected to again when it drops"
        )
    elif not camera and (args.timeout is not None or args.input_option):
        problem = "--timeout and --input-option are for network cameras (rtsp://...)"
    elif args.quality is not None and (args.raw or args.h264):
        problem = "--quality is the JPEG quality: not with --raw or --h264"
    elif args.detections_scale is not None and args.detections is None:
        problem = "--detections-scale scales the boxes of --detections, which is not given"
    if problem:
        print(f"vtrack publish: {problem}", file=sys.stderr)
        return 2
    frames: Iterator[np.ndarray | bytes | Captured]
    try:
        if camera:
            timeout = DEFAULT_CAMERA_TIMEOUT if args.timeout is None else args.timeout
            settings = CameraSettings(read_timeout=timeout, options=dict(args.input_option))
            source = NetworkCamera(
                args.source,
                settings,
                forward_h264=args.h264,
                tell=lambda news: _tell("publish", news),
            )
            frames, rate = iter(source), None
            pace = f"{source.connection.description}, as it arrives"
        else:
            frames, fps = video_frames(args.source)
            rate = args.fps or fps or 25.0
            pace = f"at {rate:g} fps"
        detections = None
        if args.detections is not None:
            table = MotDetections.from_file(args.detections)
            detections = table.for_frame
    except (ValueError, OSError) as error:
        print(f"vtrack publish: {error}", file=sys.stderr)
        return 2
    opened = _session(args, "publish")
    if opened is None:
        return 1
    session, keys = opened
    _tell("publish", f"{redacted(args.source)} on {keys.frames}: {pace} (Ctrl-C stops)")
    watcher = watch_trackers(
        session, keys, _tracker_news("publish", args.camera, "still sending its frames")
    )
    sent = 0

    def count(sequence: int, stamp: float) -> None:
        # Counted as each frame goes out: Ctrl-C interrupts publish_frames before it returns
        # its report, and the total must still be true.
        nonlocal sent
        sent += 1

    try:
        while True:
            first = sent
            report = publish_frames(
                session,
                keys,
                frames,
                rate,
                payload="raw" if args.raw else "h264" if args.h264 else "jpeg",
                quality=DEFAULT_JPEG_QUALITY if args.quality is None else args.quality,
                detections=detections,
                detections_scale=args.detections_scale or 1.0,
                first_sequence=first,
                wait_for_subscriber=args.wait if first == 0 else 0.0,
                limit=None if args.limit is None else args.limit - first,
                on_sent=count,
            )
            if report.subscribed is False:
                _tell(
                    "publish",
                    f"nobody subscribed to {keys.frames} within {args.wait:g} s (is a stream "
                    "started for this camera? POST /v1/streams); frames were sent anyway",
                )
            if not args.loop or (args.limit is not None and sent >= args.limit):
                break
            frames, _ = video_frames(args.source)
    except KeyboardInterrupt:
        pass
    finally:
        watcher.undeclare()
        session.close()
    _tell("publish", f"{sent} frames sent")
    return 0


def _subscribe(args: argparse.Namespace) -> int:
    from service.streams.tools import (
        TrackerReplyError,
        current_tracks,
        follow_tracks,
        reach_tracker,
        watch_trackers,
    )

    if args.output:
        try:
            output_file(args.output)
        except OSError as error:
            print(f"vtrack subscribe: {error}", file=sys.stderr)
            return 2
    opened = _session(args, "subscribe")
    if opened is None:
        return 1
    session, keys = opened
    record = args.output.open("a") if args.output else None
    # --output records JSON lines in the file instead of printing; --json prints them as well.
    printing = not args.output or args.json
    done = threading.Event()
    received = 0
    lock = threading.Lock()

    def show(message: StreamTracksMessage | StreamTracksEnded, arrived: float) -> None:
        nonlocal printing, received
        with lock:
            if done.is_set():
                return
            document = json.dumps(message.model_dump(mode="json"), separators=(",", ":"))
            if record is not None:
                record.write(document + "\n")
                record.flush()
            if printing:
                try:
                    sys.stdout.write((document if args.json else _summary(message)) + "\n")
                    sys.stdout.flush()
                except BrokenPipeError:
                    # The reader went away (| head): stop quietly, as cat does. Python's own
                    # flush at exit would fail again and say so: stdout goes to /dev/null.
                    os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
                    printing = False
                    if record is None:
                        done.set()
                        return
            received += isinstance(message, StreamTracksMessage)
            if args.count is not None and received >= args.count:
                done.set()

    try:
        if args.current:
            try:
                message = current_tracks(session, keys)
            except TrackerReplyError as error:
                print(f"vtrack subscribe: {error}", file=sys.stderr)
                return 1
            if message is None:
                print(f"vtrack subscribe: no tracker answered on {keys.current}", file=sys.stderr)
                return 1
            show(message, time.time())
            return 0
        subscriber = follow_tracks(session, keys, show, on_ended=show)
        watcher = watch_trackers(
            session, keys, _tracker_news("subscribe", args.camera, "still waiting for its tracks")
        )
        if not reach_tracker(session, keys, timeout=5.0):
            _tell(
                "subscribe",
                f"no tracker of camera {args.camera} answers yet (is the stream started?); "
                "listening anyway",
            )
        _tell("subscribe", f"following {keys.tracks} (Ctrl-C stops)")
        done.wait(args.duration)
        watcher.undeclare()
        subscriber.undeclare()
    except KeyboardInterrupt:
        pass
    finally:
        with lock:  # a message still arriving must not write to the closed file
            done.set()
        session.close()
        if record is not None:
            record.close()
    return 0


def _summary(message: StreamTracksMessage | StreamTracksEnded) -> str:
    """One human line for a tracks message (frame, time, latency, and who is where), or for
    the end of the tracks (why, and which ids will not come again)."""
    if isinstance(message, StreamTracksEnded):
        ids = ", ".join(f"#{i}" for i in message.track_ids)
        return (
            f"tracks ended after seq {message.sequence} t={message.timestamp:.3f}: "
            f"{message.reason}" + (f"; {ids} will not come again" if ids else "")
        )
    people = ", ".join(
        f"#{t.track_id} ({t.box.x:.0f},{t.box.y:.0f} {t.box.w:.0f}x{t.box.h:.0f})"
        for t in message.tracks
    )
    return (
        f"seq {message.sequence} t={message.timestamp:.3f} "
        f"latency {1000 * message.latency:.0f} ms skipped {message.frames_skipped}: "
        f"{people or 'nobody'}"
    )


def _matching(pattern: str, what: str) -> Callable[[str], str]:
    """An argparse type: ``text`` if it matches ``pattern`` (the API's own rule for ``what``)."""

    def parse(text: str) -> str:
        if not re.match(pattern, text):
            raise argparse.ArgumentTypeError(f"{text!r} is not a valid {what} ({pattern})")
        return text

    return parse


def _ffmpeg_option(text: str) -> tuple[str, str]:
    key, separator, value = text.partition("=")
    if not (separator and key):
        raise argparse.ArgumentTypeError(f"expected KEY=VALUE, got {text!r}")
    return key, value


def _endpoint(text: str) -> str:
    try:
        return zenoh_endpoint(text)
    except ValueError as error:
        raise argparse.ArgumentTypeError(str(error)) from None


def add_commands(commands: argparse._SubParsersAction) -> None:
    """The ``publish`` and ``subscribe`` subcommands of ``vtrack``."""
    positive = number_type(float, 0, above=True)

    def zenoh_arguments(parser: argparse.ArgumentParser) -> None:
        parser.add_argument(
            "--camera",
            required=True,
            type=_matching(CAMERA_PATTERN, "camera name"),
            help="camera name (the key's chunk)",
        )
        parser.add_argument(
            "--prefix",
            type=_matching(PREFIX_PATTERN, "key prefix"),
            help="key prefix (VTRACK_ZENOH_PREFIX, default vtrack)",
        )
        parser.add_argument(
            "--connect",
            action="append",
            type=_endpoint,
            metavar="ENDPOINT",
            help="Zenoh endpoint to connect to, e.g. tcp/127.0.0.1:7447 (repeatable; default: "
            "the service's VTRACK_ZENOH_LISTEN and VTRACK_ZENOH_CONNECT)",
        )
        parser.add_argument("--mode", choices=("peer", "client"), help="Zenoh mode")

    publish = commands.add_parser(
        "publish",
        help="publish a video file, a webcam or a network camera to Zenoh as a camera",
        description="Publish frames as a camera does: JPEG (or raw rgb8, or H.264) on "
        "<prefix>/cameras/<camera>/frames with sequence number and capture time attached.",
    )
    publish.add_argument(
        "source",
        help="video file, image folder, webcam:N, or a network camera's URL (rtsp://, "
        "http(s)://, rtmp(s)://, tcp://, udp://)",
    )
    zenoh_arguments(publish)
    publish.add_argument("--fps", type=positive, help="frames per second (default: the video's)")
    publish.add_argument("--loop", action="store_true", help="start over at the end")
    publish.add_argument("--limit", type=number_type(int, 1), help="stop after this many frames")
    publish.add_argument(
        "--wait",
        type=number_type(float, 0),
        default=5.0,
        help="seconds to wait for a tracker to subscribe before the first frame (default 5)",
    )
    encoding = publish.add_mutually_exclusive_group()
    encoding.add_argument("--raw", action="store_true", help="raw rgb8 pixels instead of JPEG")
    encoding.add_argument(
        "--h264",
        action="store_true",
        help="H.264 instead of JPEG: one access unit per frame, a key frame every second; a "
        "network camera's own H.264 is forwarded as it is when it has no B-frames",
    )
    publish.add_argument(
        "--timeout",
        type=positive,
        help="network camera: seconds without data before it counts as lost and is connected "
        f"to again (default {DEFAULT_CAMERA_TIMEOUT:g})",
    )
    publish.add_argument(
        "--input-option",
        type=_ffmpeg_option,
        action="append",
        default=[],
        metavar="KEY=VALUE",
        help="network camera: an FFmpeg input option, e.g. rtsp_transport=udp (repeatable; "
        "RTSP uses TCP by default)",
    )
    publish.add_argument(
        "--quality",
        type=number_type(int, 1, 100),
        help=f"JPEG quality (default {DEFAULT_JPEG_QUALITY})",
    )
    publish.add_argument(
        "--detections",
        type=Path,
        help="MOTChallenge det.txt to publish as an upstream detector, frame by frame",
    )
    publish.add_argument(
        "--detections-scale",
        type=positive,
        help="multiply the detections' boxes by this (default 1; e.g. 0.625: PETS 768x576 "
        "boxes on the 480x360 video)",
    )
    publish.set_defaults(handler=_publish)

    subscribe = commands.add_parser(
        "subscribe",
        help="print or record a camera's tracks from Zenoh",
        description="Follow <prefix>/cameras/<camera>/tracks: one line per frame on stdout, or "
        "JSON lines with --json; a line (a StreamTracksEnded object with --json) when the tracks "
        "end. --output records JSON lines in a file instead of printing (with --json, it prints "
        "them too). A closed stdout (| head) ends it quietly.",
    )
    zenoh_arguments(subscribe)
    subscribe.add_argument(
        "-o",
        "--output",
        type=Path,
        metavar="FILE",
        help="append JSON lines to this file instead of printing (add --json to print too)",
    )
    subscribe.add_argument("--json", action="store_true", help="print JSON lines")
    subscribe.add_argument(
        "--count", type=number_type(int, 1), help="stop after this many tracks messages"
    )
    subscribe.add_argument("--duration", type=positive, help="stop after this many seconds")
    subscribe.add_argument(
        "--current", action="store_true", help="ask for the current tracks once and exit"
    )
    subscribe.set_defaults(handler=_subscribe)
