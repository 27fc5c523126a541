"""What ``vtrack publish`` costs as the gateway of a network camera, per frame and per payload.

A camera simulated on loopback (:class:`devtools.simulated_cameras.RtspCamera`) serves
the PETS09-S2L1 video as H.264 without B-frames, a key frame a second, at 480x360 and enlarged
to 1920x1080, as fast as it is read. The gateway reads it (:class:`NetworkCamera`) and
publishes every frame on Zenoh (:func:`publish_frames`) in one of four ways: forwarding the
camera's H.264 units (``--h264``), decoding and encoding again as H.264 (what ``--h264`` does
with a camera that has B-frames), decoding and sending JPEG (the default), or decoding and
sending raw pixels (``--raw``). The gateway runs in a process of its own whose CPU time is
measured from its first frame to its last (opening the camera excluded); a subscriber in this
process receives the frames, so the transport's work is counted too. The camera sends as fast
as the gateway reads, so CPU time per frame, not wall time, is the measure.

First, the wait from connecting to the first frame, with the gateway's short stream study and
with FFmpeg's own, on an RTSP camera and an MPEG-TS camera on a TCP port sending 480x360 at 10
frames per second; and how many frames came at once with the first (read during the study).
Then how long after the camera sends a frame the gateway has it, on the MPEG-TS camera read
packet by packet and with FFmpeg's parser, and on the RTSP camera (:func:`frame_delays`). Then
how far the frames' stamps are from the times the camera took them on a congested network,
stamped on arrival and with the camera's own times (:func:`capture_times`).

Usage::

    python benchmarks/gateway.py [--frames 200] [--sizes 480x360,1920x1080] [--repeats 3]
        [--delay-frames 60] [--capture-seconds 60] [--json]
"""

from __future__ import annotations

import argparse
import multiprocessing
import os
import sys
import threading
import time
from collections.abc import Callable
from itertools import islice
from pathlib import Path

import cv2
import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from devtools.simulated_cameras import (
    RtspCamera,
    TcpCamera,
    access_units,
    h264_video,
)
from devtools.testing import free_port
from service.streams.keys import StreamKeys
from service.streams.network_camera import CameraConnection, CameraSettings, NetworkCamera
from service.streams.session import ZenohOptions, open_session
from service.streams.tools import member_session, publish_frames, video_frames

try:  # run as a script: benchmarks/ is on sys.path
    from _paths import SHARED_DATA
    from _report import print_json
except ImportError:  # python -m benchmarks.<name> from the repository root
    from benchmarks._paths import SHARED_DATA
    from benchmarks._report import print_json

MODES = ("forward", "h264", "jpeg", "raw")


def camera_frames(frames: int, width: int, height: int) -> list[np.ndarray]:
    """The first ``frames`` PETS frames (RGB) at ``width`` x ``height``."""
    source, _ = video_frames(str(SHARED_DATA / "video" / "pets09_s2l1_480x360.avi"))
    return [
        cv2.resize(rgb, (width, height)) if rgb.shape[:2] != (height, width) else rgb
        for rgb in islice(source, frames)
    ]


FFMPEG_STUDY = {"analyzeduration": "0", "fpsprobesize": "-1"}
"""FFmpeg's own stream study (up to 5 s, frame rate estimated), against the gateway's
:data:`~service.streams.network_camera.INPUT_DEFAULTS`."""


def first_frame(camera_of: Callable[[], object], study: dict, repeats: int) -> dict:
    """Seconds from connecting to the first frame, and frames that came with it (within 50 ms:
    what arrived during the study), medians over ``repeats`` connections to a camera sending
    at 10 fps."""
    waits, bursts = [], []
    for _ in range(repeats):
        camera = camera_of()
        started = time.perf_counter()
        source = NetworkCamera(camera.url, CameraSettings(options=study), forward_h264=True)
        arrivals: list[float] = []
        for _ in islice(iter(source), 30):
            arrivals.append(time.perf_counter() - started)
            if arrivals[-1] - arrivals[0] >= 0.05:
                break  # the burst is over: from here the camera sends a frame each 100 ms
        camera.close()
        waits.append(arrivals[0])
        bursts.append(sum(1 for t in arrivals if t - arrivals[0] < 0.05))
    return {"seconds": float(np.median(waits)), "frames_at_once": int(np.median(bursts))}


def gateway(hub: str, url: str, mode: str, frames: int, results: multiprocessing.Queue) -> None:
    """One ``vtrack publish`` of the camera, in this process: its CPU time."""
    session = member_session(ZenohOptions(listen=(hub,)))  # connects to the hub
    keys = StreamKeys("vtrack", "gateway")
    probe = session.declare_publisher(keys.frames)
    deadline = time.monotonic() + 30
    while not probe.matching_status.matching and time.monotonic() < deadline:
        time.sleep(0.02)  # until the subscriber is known: frames sent before it are lost
    probe.undeclare()
    camera = NetworkCamera(url, CameraSettings(), forward_h264=mode == "forward")
    payload = "h264" if mode == "forward" else mode
    cpu = time.process_time()
    report = publish_frames(session, keys, iter(camera), None, payload=payload, limit=frames)
    cpu = time.process_time() - cpu
    session.close()
    results.put({"frames": report.frames, "cpu_seconds": cpu})


def measure(units: list[bytes], mode: str) -> dict:
    hub = f"tcp/127.0.0.1:{free_port()}"
    session = open_session(ZenohOptions(listen=(hub,)).hub_config())  # as the service's
    received = []
    lock = threading.Lock()

    def count(sample) -> None:
        with lock:
            received.append(len(sample.payload.to_bytes()))

    subscriber = session.declare_subscriber(StreamKeys("vtrack", "gateway").frames, count)
    camera = RtspCamera(units, fps=1000.0)  # as fast as the gateway reads
    results: multiprocessing.Queue = multiprocessing.get_context("spawn").Queue()
    process = multiprocessing.get_context("spawn").Process(
        target=gateway, args=(hub, camera.url, mode, len(units), results)
    )
    process.start()
    measured = results.get(timeout=600)
    process.join(60)
    deadline = time.monotonic() + 10
    while len(received) < measured["frames"] and time.monotonic() < deadline:
        time.sleep(0.05)
    subscriber.undeclare()
    session.close()
    camera.close()
    frames = measured["frames"]
    return {
        "mode": mode,
        "frames_sent": frames,
        "frames_received": len(received),
        "cpu_ms_per_frame": 1000 * measured["cpu_seconds"] / frames,
        "kb_per_frame": sum(received) / max(len(received), 1) / 1000,
    }


def first_frames(repeats: int) -> dict:
    """The wait for the first frame with the gateway's study and FFmpeg's, on an RTSP camera
    and an MPEG-TS camera on a TCP port (480x360, 10 fps)."""
    images = camera_frames(60, 480, 360)
    units, transport_stream = access_units(images), h264_video(images, "mpegts")
    cameras = {
        "rtsp": lambda: RtspCamera(units, fps=10),
        "mpegts-tcp": lambda: TcpCamera(transport_stream, fps=10),
    }
    return {
        name: {
            "gateway": first_frame(camera_of, {}, repeats),
            "ffmpeg_defaults": first_frame(camera_of, FFMPEG_STUDY, repeats),
        }
        for name, camera_of in cameras.items()
    }


def frame_delays(frames: int) -> dict:
    """How long after the camera sends a frame the gateway has it, decoded and forwarded: the
    MPEG-TS camera on a TCP port read packet by packet (the gateway,
    :attr:`CameraConnection.whole_frames`) and with FFmpeg's parser, which holds a frame until
    the next one starts, and the RTSP camera (read with the parser), both at 10 fps.
    Milliseconds, median and maximum over the frames after the first 10 (the stream study's)
    and before the last 3 (the stream's end flushes them)."""
    images = camera_frames(frames, 480, 360)
    units, transport_stream = access_units(images), h264_video(images, "mpegts")
    readings = {
        "mpegts-tcp, packet by packet": (lambda: TcpCamera(transport_stream, fps=10), False),
        "mpegts-tcp, parser": (lambda: TcpCamera(transport_stream, fps=10), True),
        "rtsp": (lambda: RtspCamera(units, fps=10), False),
    }
    out = {}
    for name, (camera_of, parse) in readings.items():
        for forward in (False, True):
            camera = camera_of()
            connection = CameraConnection(camera.url, CameraSettings(), forward, parse)
            arrivals = [time.time() for _ in connection.items()]
            camera.close()
            sent = camera.taken if isinstance(camera, TcpCamera) else camera.sent
            delays = 1000 * (np.array(arrivals) - sent[: len(arrivals)])[10:-3]
            out[f"{name}, {'forwarded' if forward else 'decoded'}"] = {
                "median": float(np.median(delays)),
                "max": float(delays.max()),
            }
    return out


def capture_times(seconds: float, seed: int = 0) -> dict:
    """How far the gateway's frame stamps are from the times the frames were taken, for a camera
    at 10 fps (MPEG-TS over TCP, decoded as the default JPEG gateway does) on a congested
    network: 30% of frames held back 0-300 ms, those behind them waiting in order. Two ways to
    stamp the same frames: on arrival (the gateway before the capture clock) and with the
    camera's presentation times (:class:`~service.streams.capture_clock.CaptureClock`, what
    :class:`NetworkCamera` gives). Errors in milliseconds: of the spacing of consecutive
    frames (what the tracker's motion model reads), and of the time itself minus the least
    delay, after the first 15 s (what consumers read)."""
    frames = round(seconds * 10)
    sent = frames + 10  # the last frames of a stream come out early (the decoder is flushed)
    rng = np.random.default_rng(seed)
    delays = rng.uniform(0.0, 0.3, sent) * (rng.random(sent) < 0.3)
    images = camera_frames(sent, 480, 360)
    camera = TcpCamera(h264_video(images, "mpegts"), fps=10, delays=delays)
    try:
        source = NetworkCamera(camera.url)
        received = np.array([(item.time, time.time()) for item in islice(source, frames)])
    finally:
        camera.close()
    taken = np.array(camera.taken[:frames])
    out = {"frames": frames}
    for name, stamps in (("arrival", received[:, 1]), ("capture_clock", received[:, 0])):
        spacing = np.abs(np.diff(stamps) - np.diff(taken)) * 1000
        late = (stamps - taken) * 1000
        settled = late[min(150, frames // 2) :] - late.min()  # 15 s, or half a short run
        out[name] = {
            "spacing_error_ms": {
                "median": float(np.median(spacing)),
                "p95": float(np.percentile(spacing, 95)),
                "max": float(spacing.max()),
            },
            "frames_within_10ms_of_the_previous": int((np.diff(stamps) < 0.01).sum()),
            "time_error_after_15s_ms": {
                "median": float(np.median(settled)),
                "max": float(settled.max()),
            },
        }
    return out


def _at_least(minimum: float, kind: type = int) -> Callable[[str], float]:
    """An argparse type: a number of ``kind`` no smaller than ``minimum``."""

    def parse(text: str) -> float:
        try:
            value = kind(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"not a number: {text!r}") from None
        if not value >= minimum:
            raise argparse.ArgumentTypeError(f"must be at least {minimum}, got {text}")
        return value

    return parse


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--frames", type=_at_least(1), default=200)
    parser.add_argument("--sizes", default="480x360,1920x1080")
    parser.add_argument("--modes", default=",".join(MODES))
    parser.add_argument(
        "--repeats", type=_at_least(1), default=3, help="connections per first-frame row"
    )
    parser.add_argument(
        "--capture-seconds",
        type=_at_least(1.0, float),
        default=60.0,
        help="stream length for the stamps' row",
    )
    # the delay rows leave out the first 10 frames (connecting) and the last 3 (closing)
    parser.add_argument(
        "--delay-frames",
        type=_at_least(20),
        default=60,
        help="stream length for the frame-delay rows (at least 20)",
    )
    parser.add_argument("--json", action="store_true")
    args = parser.parse_args()
    try:
        sizes = {
            size: tuple(int(side) for side in size.split("x")) for size in args.sizes.split(",")
        }
    except ValueError:
        parser.error(f"--sizes: WIDTHxHEIGHT,... expected, got {args.sizes!r}")
    if any(len(sides) != 2 or min(sides) < 16 for sides in sizes.values()):
        parser.error(f"--sizes: WIDTHxHEIGHT,... of at least 16x16 expected, got {args.sizes!r}")
    modes = args.modes.split(",")
    if unknown := set(modes) - set(MODES):
        parser.error(f"--modes: unknown {', '.join(sorted(unknown))}; known: {', '.join(MODES)}")
    report = {"frames": args.frames, "cpu_count": os.cpu_count(), "sizes": {}}
    report["first_frame"] = first_frames(args.repeats)
    if not args.json:
        for name, rows in report["first_frame"].items():
            for study, row in rows.items():
                print(
                    f"{name} first frame, {study} study: {row['seconds']:.2f} s, "
                    f"{row['frames_at_once']} frames at once"
                )
    report["frame_delay_ms"] = frame_delays(args.delay_frames)
    if not args.json:
        for name, row in report["frame_delay_ms"].items():
            print(f"frame delay, {name}: {row['median']:.0f} ms, max {row['max']:.0f}")
    report["capture_times"] = capture_times(args.capture_seconds)
    if not args.json:
        for name in ("arrival", "capture_clock"):
            row = report["capture_times"][name]
            spacing, settled = row["spacing_error_ms"], row["time_error_after_15s_ms"]
            print(
                f"stamps {name:13s}: spacing error median {spacing['median']:.1f} ms, p95 "
                f"{spacing['p95']:.1f}, max {spacing['max']:.1f}; "
                f"{row['frames_within_10ms_of_the_previous']} frames within 10 ms of the "
                f"previous; time error after 15 s median {settled['median']:.1f} ms, max "
                f"{settled['max']:.1f}"
            )
    for size, (width, height) in sizes.items():
        units = access_units(camera_frames(args.frames, width, height))
        rows = [measure(units, mode) for mode in modes]
        report["sizes"][size] = rows
        if not args.json:
            print(f"{size}: camera sends {sum(map(len, units)) / len(units) / 1000:.1f} KB/frame")
            for row in rows:
                print(
                    f"  {row['mode']:8s} {row['cpu_ms_per_frame']:7.2f} ms CPU/frame "
                    f"{row['kb_per_frame']:8.1f} "
                    f"KB/frame sent, {row['frames_received']}/{row['frames_sent']} received"
                )
    if args.json:
        print_json(report, indent=2)
    return 0


if __name__ == "__main__":
    sys.exit(main())
