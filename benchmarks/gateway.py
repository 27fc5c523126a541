"""What ``vtrack publish`` costs as the gateway of a network camera, per frame and per payload.

A camera simulated on loopback (:class:`service.streams.simulated_cameras.RtspCamera`) serves
the PETS09-S2L1 video as H.264 without B-frames, a key frame a second, at 480x360 and enlarged
to 1920x1080, as fast as it is read. The gateway reads it (:class:`NetworkCamera`) and
publishes every frame on Zenoh (:func:`publish_frames`) in one of four ways: forwarding the
camera's H.264 units (``--h264``), decoding and encoding again as H.264 (what ``--h264`` does
with a camera that has B-frames), decoding and sending JPEG (the default), or decoding and
sending raw pixels (``--raw``). The gateway runs in a process of its own whose CPU time is
measured from its first frame to its last (opening the camera excluded); a subscriber in this
process receives the frames, so the transport's work is counted too. The camera sends as fast
as the gateway reads, so CPU time per frame, not wall time, is the measure.

Usage::

    python benchmarks/gateway.py [--frames 200] [--sizes 480x360,1920x1080] [--json]
"""

from __future__ import annotations

import argparse
import json
import multiprocessing
import os
import sys
import threading
import time
from itertools import islice
from pathlib import Path

import cv2

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from service.outputs.h264 import AccessUnitEncoder  # noqa: E402
from service.streams.keys import StreamKeys  # noqa: E402
from service.streams.network_camera import CameraSettings, NetworkCamera  # noqa: E402
from service.streams.session import ZenohOptions, open_session  # noqa: E402
from service.streams.simulated_cameras import RtspCamera  # noqa: E402
from service.streams.tools import member_session, publish_frames, video_frames  # noqa: E402
from service.testing import free_port  # noqa: E402

MODES = ("forward", "h264", "jpeg", "raw")


def shared_data() -> Path:
    return Path(os.environ.get("VTRACK_SHARED_DATA", REPO.parent / "shared" / "data"))


def camera_units(frames: int, width: int, height: int) -> list[bytes]:
    """The camera's H.264 access units: PETS frames at ``width`` x ``height``, 10 fps."""
    source, _ = video_frames(str(shared_data() / "video" / "pets09_s2l1_480x360.avi"))
    encoder = AccessUnitEncoder(width, height, "rgb24")
    units = []
    for index, rgb in enumerate(islice(source, frames)):
        image = cv2.resize(rgb, (width, height)) if rgb.shape[:2] != (height, width) else rgb
        units += [unit for _, unit in encoder.encode(image, index * 10**8)]
    return units


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


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--frames", type=int, default=200)
    parser.add_argument("--sizes", default="480x360,1920x1080")
    parser.add_argument("--modes", default=",".join(MODES))
    parser.add_argument("--json", action="store_true")
    args = parser.parse_args()
    report = {"frames": args.frames, "cpu_count": os.cpu_count(), "sizes": {}}
    for size in args.sizes.split(","):
        width, height = (int(side) for side in size.split("x"))
        units = camera_units(args.frames, width, height)
        rows = [measure(units, mode) for mode in args.modes.split(",")]
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
        print(json.dumps(report, indent=2))
    return 0


if __name__ == "__main__":
    sys.exit(main())
