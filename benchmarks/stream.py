"""Live stream benchmark: a video published on Zenoh as a camera, tracked live by the service.

    python benchmarks/stream.py [--fps 10] [--frames N] [--configs a,b] [--data DIR]
                                [--payload jpeg|h264|raw] [--server-log FILE] [--json]

Starts ``vtrack serve`` (one job worker, a temporary data folder, Zenoh on a free loopback
port), then for each configuration starts a stream (``POST /v1/streams``, a camera of its own),
waits until its worker has subscribed, and publishes the PETS09-S2L1 video (480x360, 795 frames)
on the camera's frames key at ``--fps`` with :func:`service.streams.tools.publish_frames`, as a
camera does (JPEG, or ``--payload`` H.264 or raw pixels; sequence number and capture time
attached), while following the camera's
tracks with :func:`service.streams.tools.follow_tracks` in this process. Configurations:

* ``service_cnn``: default stream options, detector 'auto', which runs the CNN person detector
  (the server is given the shared data's ``models`` folder as ``VTRACK_MODELS_DIR``: Open Model
  Zoo's person-detection-0202, at 576 px for these 360 px frames), and the tracker the pose
  (human-pose-estimation-0001, also at 576 px) and re-identification (0287) networks found there.
* ``service_cnn_only`` (only when asked for): the same without the pose and re-identification
  networks (``tracker.pose`` and ``tracker.reid`` false).
* ``service_detector``: the service's embedded HOG detector (``"default"``, at the factor it
  picks for 360 px frames, 2.0).
* ``upstream_detections``: the publisher also publishes the public ``det/det.txt`` detections
  (scaled by 0.625 from 768x576) on the detections key, as an upstream detector would.
* ``service_detector_1_5x`` (only when asked for): the embedded detector with ``upscale`` 1.5,
  cheaper, but it misses most people of this video (40-60 px tall).
* ``service_detector_regions`` (only when asked for): the embedded detector on the full frame
  every 0.2 s and on regions around the tracks in between (``full_detection_interval``).

Figures per configuration: frames published, tracks messages received, the stream's counters
(REST, at the end), the share of frames skipped (``frames_skipped / frames_in``, goal: under
5%), the end-to-end latency from a frame's publication to the arrival of its tracks message
(both ``time.time()`` on this machine; median goal: under 150 ms), the worker's own processing
latency, frames tracked per second, the worker's resident memory (VmRSS) at the start and the
end of publishing, and HOTA of the streamed tracks against the ground truth scaled to the video
(frames without a tracks message count as frames where nobody was found).

With ``--json``, stdout is exactly one JSON object; progress goes to stderr.
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import sys
import tempfile
import threading
import time
from dataclasses import dataclass, field
from pathlib import Path

import httpx
import numpy as np

# Run as a script, benchmarks/ comes first on sys.path and benchmarks/service.py would shadow
# the service package.
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from api_schemas.streams import StreamTracksMessage
from devtools.testing import Server, wait_for
from service.streams.keys import StreamKeys
from service.streams.session import ZenohOptions
from service.streams.tools import (
    follow_tracks,
    member_session,
    publish_frames,
    trackers_of,
    video_frames,
)
from tracking.detection import MotDetections
from tracking.evaluation.hota import hota
from tracking.evaluation.mot import ground_truth_rows

try:  # run as a script: benchmarks/ is on sys.path
    from _paths import SHARED_DATA
    from _report import machine, print_json
except ImportError:  # python -m benchmarks.<name> from the repository root
    from benchmarks._paths import SHARED_DATA
    from benchmarks._report import machine, print_json

VIDEO = Path("video") / "pets09_s2l1_480x360.avi"
SEQUENCE = Path("mot") / "PETS09-S2L1"
SCALE = 0.625
"""PETS09-S2L1 annotations are in 768x576 pixels; the video is 480x360."""
PREFIX = "vtrack"

CONFIGS = {
    "service_cnn": {},
    "service_cnn_only": {"tracker": {"pose": False, "reid": False}},
    "service_detector": {"detector": {"name": "default"}},
    "upstream_detections": {},
    "service_detector_1_5x": {"detector": {"name": "default", "upscale": 1.5}},
    "service_detector_regions": {
        "detector": {"name": "default"},
        "tracker": {"full_detection_interval": 0.2},
    },
}
"""Stream options (the body of ``POST /v1/streams`` besides the camera) per configuration."""
DEFAULT_CONFIGS = ("service_cnn", "service_detector", "upstream_detections")
UPSTREAM = "upstream_detections"
SKIP_GOAL = 0.05
LATENCY_GOAL = 0.150


def _log(*parts: object) -> None:
    print(*parts, file=sys.stderr, flush=True)


def _percentile(values: list[float], q: float) -> float | None:
    return float(np.percentile(values, q)) if values else None


def _cpu_seconds(pid: int | None) -> float | None:
    """User + system CPU time of process ``pid`` so far (None when it cannot be read)."""
    try:
        fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
        return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")
    except (OSError, ValueError, IndexError):
        return None


def _rss_kib(pid: int | None) -> int | None:
    """VmRSS of process ``pid`` in KiB (None when it cannot be read)."""
    try:
        for line in Path(f"/proc/{pid}/status").read_text().splitlines():
            if line.startswith("VmRSS:"):
                return int(line.split()[1])
    except (OSError, ValueError):
        pass
    return None


@dataclass
class Received:
    """What this process saw of one stream: publication and arrival times, the messages."""

    sent: dict[int, float] = field(default_factory=dict)
    messages: list[tuple[StreamTracksMessage, float]] = field(default_factory=list)
    lock: threading.Lock = field(default_factory=threading.Lock)

    def on_sent(self, sequence: int, stamp: float) -> None:
        with self.lock:
            self.sent[sequence] = stamp

    def on_message(self, message: StreamTracksMessage, arrived: float) -> None:
        with self.lock:
            self.messages.append((message, arrived))


class MemorySampler(threading.Thread):
    """VmRSS of a process every ``interval`` seconds until stopped."""

    def __init__(self, pid: int | None, interval: float = 0.5) -> None:
        super().__init__(daemon=True)
        self.pid, self.interval = pid, interval
        self.samples: list[tuple[float, int]] = []  # (seconds since start, KiB)
        self.halt = threading.Event()

    def run(self) -> None:
        started = time.monotonic()
        while not self.halt.wait(self.interval):
            value = _rss_kib(self.pid)
            if value is not None:
                self.samples.append((time.monotonic() - started, value))

    def at(self, seconds: float) -> int | None:
        """The first sample taken ``seconds`` or more after the start."""
        return next((kib for t, kib in self.samples if t >= seconds), None)


def stream_hota(messages: list[StreamTracksMessage], gt_path: Path, frames: int) -> dict:
    """HOTA of the streamed tracks against the ground truth of the published frames."""
    rows = [
        (m.sequence + 1, t.track_id, t.box.x, t.box.y, t.box.w, t.box.h)
        for m in messages
        for t in m.tracks
    ]
    tracks = np.array(rows, dtype=np.float64).reshape(-1, 6)
    return hota(ground_truth_rows(gt_path, SCALE, frames), tracks).percent()


def run_config(
    name: str,
    server: Server,
    client: httpx.Client,
    data: Path,
    fps: float,
    frames: int | None,
    payload: str = "jpeg",
) -> dict:
    camera = f"bench_{name}"
    keys = StreamKeys(PREFIX, camera)
    response = client.post("/v1/streams", json={"camera": camera, **CONFIGS[name]})
    if response.status_code != 201:
        raise RuntimeError(f"POST /v1/streams: {response.status_code} {response.text}")

    def subscribed():
        status = client.get(f"/v1/streams/{camera}").json()
        if status["state"] == "failed":
            raise RuntimeError(f"stream {camera} failed: {status['error']}")
        return status if status["state"] == "waiting" else None

    status = wait_for(subscribed, 120, f"stream {camera} to subscribe", interval=0.2)
    pid = status["worker_pid"]
    detections = None
    if name == UPSTREAM:
        table = MotDetections.from_file(data / SEQUENCE / "det" / "det.txt")
        detections = table.for_frame
    received = Received()
    session = member_session(ZenohOptions(listen=(server.zenoh_listen[0],)))
    sampler = MemorySampler(pid)
    try:
        subscriber = follow_tracks(session, keys, received.on_message)
        wait_for(lambda: trackers_of(session, keys), 20, f"the tracker of {camera} on Zenoh")
        time.sleep(1.0)  # gossip: let this session and the worker connect directly
        source, _ = video_frames(str(data / VIDEO))
        load_before = os.getloadavg()[0]
        rss_start, cpu_start = _rss_kib(pid), _cpu_seconds(pid)
        sampler.start()
        _log(f"{name}: publishing at {fps:g} fps on {keys.frames}")
        report = publish_frames(
            session,
            keys,
            source,
            fps,
            payload=payload,
            detections=detections,
            detections_scale=SCALE,
            limit=frames,
            on_sent=received.on_sent,
        )
        rss_end, cpu_end = _rss_kib(pid), _cpu_seconds(pid)
        sampler.halt.set()
        load_after = os.getloadavg()[0]

        def drained():
            counters = client.get(f"/v1/streams/{camera}").json()["counters"]
            handled = sum(counters[k] for k in ("frames_processed", "frames_skipped", "malformed"))
            return counters["frames_in"] >= report.frames and handled >= counters["frames_in"]

        try:
            wait_for(drained, 30, f"stream {camera} to handle every frame", interval=0.2)
        except TimeoutError as error:
            _log(f"{name}: {error}")
        time.sleep(1.0)  # the last tracks message on its way
        status = client.get(f"/v1/streams/{camera}").json()
        subscriber.undeclare()
    finally:
        sampler.halt.set()
        session.close()
        final = client.delete(f"/v1/streams/{camera}")
    if final.status_code == 200:
        status["counters"] = final.json()["counters"]

    with received.lock:
        messages = list(received.messages)
        sent = dict(received.sent)
    counters = status["counters"]
    published = report.frames
    timed = [
        (arrived - sent[m.sequence], m.sequence) for m, arrived in messages if m.sequence in sent
    ]
    end_to_end = [latency for latency, _ in timed]
    worker = [m.latency for m, _ in messages]
    sources = [m.detections for m, _ in messages]
    first_sent = min(sent.values()) if sent else 0.0
    last_arrival = max((a for _, a in messages), default=first_sent)
    skipped_share = (
        counters["frames_skipped"] / counters["frames_in"] if counters["frames_in"] else None
    )
    median = _percentile(end_to_end, 50)
    cpu = cpu_end - cpu_start if cpu_start is not None and cpu_end is not None else None
    samples = sampler.samples
    detector = status.get("detector")
    figures = {
        "detector": None
        if detector is None
        else " ".join(filter(None, (detector["name"], detector["model"]))),
        "frames_published": published,
        "publish_seconds": round(report.seconds, 2),
        "publish_fps": round(published / report.seconds, 2) if report.seconds else None,
        "publish_late": report.late,
        "messages": len(messages),
        "frames_in": counters["frames_in"],
        "frames_processed": counters["frames_processed"],
        "frames_skipped": counters["frames_skipped"],
        "malformed": counters["malformed"],
        "detections_in": counters["detections_in"],
        "detections_used": counters["detections_used"],
        "restarts": counters["restarts"],
        "messages_upstream": sources.count("upstream"),
        "messages_service": sources.count("service"),
        "skipped_share": round(skipped_share, 4) if skipped_share is not None else None,
        "missing_share": round(1 - len(messages) / published, 4) if published else None,
        "tracked_fps": round(len(messages) / (last_arrival - first_sent), 2)
        if messages and last_arrival > first_sent
        else None,
        "latency_median_ms": _ms(median),
        "latency_p95_ms": _ms(_percentile(end_to_end, 95)),
        "latency_max_ms": _ms(max(end_to_end, default=None)),
        "latency_max_sequence": max(timed)[1] if timed else None,
        "worker_latency_median_ms": _ms(_percentile(worker, 50)),
        "worker_latency_p95_ms": _ms(_percentile(worker, 95)),
        "rest_latency_ms": _ms(status.get("latency")),
        "rest_latency_p95_ms": _ms(status.get("latency_p95")),
        "worker_cpu_seconds": round(cpu, 2) if cpu is not None else None,
        "worker_cpu_ms_per_frame": round(1000 * cpu / len(messages), 1)
        if cpu is not None and messages
        else None,
        "worker_cpu_share": round(cpu / report.seconds, 2) if cpu is not None else None,
        "rss_start_mib": _mib(rss_start),
        "rss_10s_mib": _mib(sampler.at(10.0)),
        "rss_end_mib": _mib(rss_end),
        "rss_max_mib": _mib(max((kib for _, kib in samples), default=None)),
        "load_average": [round(load_before, 2), round(load_after, 2)],
        "skip_goal_met": skipped_share is not None and skipped_share < SKIP_GOAL,
        "skip_ratio_to_goal": round(skipped_share / SKIP_GOAL, 2)
        if skipped_share is not None
        else None,
        "latency_goal_met": median is not None and median < LATENCY_GOAL,
        "latency_ratio_to_goal": round(median / LATENCY_GOAL, 2) if median is not None else None,
    }
    if detections is not None:  # frames tracked with the service's detector all the same
        figures["fallback_sequences"] = [
            m.sequence for m, _ in messages if m.detections != "upstream"
        ]
    gt_path = data / SEQUENCE / "gt" / "gt.txt"
    if gt_path.is_file():
        figures.update(stream_hota([m for m, _ in messages], gt_path, published))
    return figures


def _ms(seconds: float | None) -> float | None:
    return round(1000 * seconds, 1) if seconds is not None else None


def _mib(kib: int | None) -> float | None:
    return round(kib / 1024, 1) if kib is not None else None


ROWS = (
    ("frames published", "frames_published", "{}"),
    ("publisher fps (late frames)", None, None),
    ("tracks messages received", "messages", "{}"),
    ("frames in / processed / skipped / malformed", None, None),
    ("frames skipped (goal < 5%)", "skipped_share", "{:.1%}"),
    ("  ratio to goal", "skip_ratio_to_goal", "{:.2f}"),
    ("frames without tracks message", "missing_share", "{:.1%}"),
    ("frames tracked per second", "tracked_fps", "{:.2f}"),
    ("latency median, ms (goal < 150)", "latency_median_ms", "{:.0f}"),
    ("  ratio to goal", "latency_ratio_to_goal", "{:.2f}"),
    ("latency p95 / max, ms", None, None),
    ("worker latency median / p95, ms", None, None),
    ("detections upstream / service", None, None),
    ("worker CPU ms per tracked frame (cores)", None, None),
    ("worker RSS start / 10 s / end / max, MiB", None, None),
    ("HOTA (DetA, AssA)", None, None),
    ("goals met (skip, latency)", None, None),
)


def _cell(figures: dict, label: str, key: str | None, fmt: str | None) -> str:
    f = figures
    if key is not None:
        return "-" if f.get(key) is None else fmt.format(f[key])
    if label.startswith("publisher"):
        return f"{f['publish_fps']:.2f} ({f['publish_late']})"
    if label.startswith("frames in"):
        return (
            f"{f['frames_in']} / {f['frames_processed']} / {f['frames_skipped']} / {f['malformed']}"
        )
    if label.startswith("latency p95"):
        return f"{f['latency_p95_ms']:.0f} / {f['latency_max_ms']:.0f}"
    if label.startswith("worker latency"):
        return f"{f['worker_latency_median_ms']:.0f} / {f['worker_latency_p95_ms']:.0f}"
    if label.startswith("detections"):
        return f"{f['messages_upstream']} / {f['messages_service']}"
    if label.startswith("worker CPU"):
        if f.get("worker_cpu_ms_per_frame") is None:
            return "-"
        return f"{f['worker_cpu_ms_per_frame']:.0f} ({f['worker_cpu_share']:.2f})"
    if label.startswith("worker RSS"):
        values = (f[f"rss_{k}_mib"] for k in ("start", "10s", "end", "max"))
        return " / ".join("-" if v is None else f"{v:.0f}" for v in values)
    if label.startswith("HOTA"):
        return f"{f['hota']} ({f['det_a']}, {f['ass_a']})" if "hota" in f else "-"
    if label.startswith("goals"):
        return " ".join("yes" if f[k] else "no" for k in ("skip_goal_met", "latency_goal_met"))
    return "?"


def print_table(result: dict) -> None:
    print(
        f"{result['video']}: {result['frames']} frames published at {result['fps']:g} fps, "
        f"{result['machine']['cpu_count']} CPUs ({result['machine']['cpu']})"
    )
    names = list(result["configs"])
    cells = {
        name: [
            _cell(result["configs"][name], *row) if "error" not in result["configs"][name] else "-"
            for row in ROWS
        ]
        for name in names
    }
    width = max(len(label) for label, _, _ in ROWS) + 2
    widths = [max(len(n), *(len(c) for c in cells[n])) + 2 for n in names]
    print(" " * width + "".join(n.rjust(w) for n, w in zip(names, widths, strict=True)))
    for i, (label, _, _) in enumerate(ROWS):
        row = "".join(cells[n][i].rjust(w) for n, w in zip(names, widths, strict=True))
        print(f"{label:<{width}}{row}")
    for name in names:
        if "error" in result["configs"][name]:
            print(f"{name}: {result['configs'][name]['error']}")


def run(
    data: Path,
    fps: float,
    frames: int | None,
    configs: list[str],
    server_log: Path | None = None,
    payload: str = "jpeg",
) -> dict:
    video = data / VIDEO
    if not video.is_file():
        raise FileNotFoundError(f"{video} not found (--data or VTRACK_SHARED_DATA)")
    result: dict = {
        "video": video.name,
        "fps": fps,
        "frames": frames,
        "payload": payload,
        "machine": machine(),
        "configs": {},
    }
    with tempfile.TemporaryDirectory(prefix="vtrack-stream-bench-") as scratch:
        models = data / "models"
        server = Server(
            Path(scratch) / "data", workers=1, zenoh_prefix=PREFIX, models_dir=models.resolve()
        )
        try:
            _log(f"starting the server (HTTP {server.url}, Zenoh {server.zenoh_listen[0]})")
            server.start()
            with httpx.Client(base_url=server.url, timeout=60) as client:
                for name in configs:
                    try:
                        figures = run_config(name, server, client, data, fps, frames, payload)
                    except Exception as error:  # one broken configuration must not stop the rest
                        _log(f"{name}: {type(error).__name__}: {error}\n{server.log_tail()}")
                        figures = {"error": f"{type(error).__name__}: {error}"}
                    result["configs"][name] = figures
                    _log(f"{name}: {json.dumps(figures)}")
        finally:
            server.stop()
            if server_log is not None and server.log_path.is_file():
                shutil.copyfile(server.log_path, server_log)
    if frames is None:
        published = [c.get("frames_published") for c in result["configs"].values()]
        result["frames"] = max((p for p in published if p is not None), default=None)
    return result


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--data", type=Path, default=SHARED_DATA, help="the shared data folder")
    parser.add_argument("--fps", type=float, default=10.0, help="publication rate (default 10)")
    parser.add_argument("--frames", type=int, help="frames to publish (default: all 795)")
    parser.add_argument(
        "--configs",
        default=",".join(DEFAULT_CONFIGS),
        help=f"comma-separated configurations among {', '.join(CONFIGS)} "
        f"(default: {','.join(DEFAULT_CONFIGS)})",
    )
    parser.add_argument(
        "--payload",
        choices=("jpeg", "h264", "raw"),
        default="jpeg",
        help="how the camera sends its frames (default jpeg)",
    )
    parser.add_argument("--server-log", type=Path, help="keep the service's log in this file")
    parser.add_argument("--json", action="store_true", help="print one JSON object")
    args = parser.parse_args(argv)
    configs = [c.strip() for c in args.configs.split(",") if c.strip()]
    unknown = sorted(set(configs) - set(CONFIGS))
    if unknown:
        parser.error(f"unknown configurations {unknown}; choose from {list(CONFIGS)}")
    result = run(args.data, args.fps, args.frames, configs, args.server_log, args.payload)
    if args.json:
        print_json(result, indent=None)
    else:
        print_table(result)
    return 1 if any("error" in c for c in result["configs"].values()) else 0


if __name__ == "__main__":
    sys.exit(main())
