"""End-to-end service benchmark: upload-to-result time for a video, as a ratio to its duration.

    python benchmarks/service.py [--video PATH] [--options JSON] [--workers N]
                                 [--dpm-model MODEL.mat] [--models-dir DIR]
                                 [--inference-threads N] [--jobs N] [--json]

Starts ``vtrack serve`` (default settings; a temporary data folder) on a loopback port, uploads
the video (default: the PETS09-S2L1 video of the shared data, 795 frames at 10 fps = 79.5 s)
with the given job options (default: none, i.e. the service defaults: detector 'auto', every
frame, all four outputs), follows the job to its end, downloads every result, and reports:

* ``upload_to_result_s``: from the first byte of the upload to the last byte of the last result;
* ``ratio_to_real_time``: that divided by the video's duration (below 1: faster than real time);
* the parts: upload, waiting in the queue, tracking, downloads; frames per second of tracking.

With ``--jobs N`` the video is uploaded N times at once (jobs side by side, one per worker
process): the time runs to the last result of the last job, tracking is the slowest job's, and
``job_tracking_s`` lists each job's.

With ground truth (by default, for the default video: PETS09-S2L1's annotations scaled by 0.625
from 768x576 to the video's 480x360; ``--ground-truth`` and ``--gt-scale`` for another video),
the tracks of the ``mot`` result are scored (``hota``, ``det_a``, ``ass_a``, percent;
``tracking.evaluation.hota``): what the user downloads, frames the job skipped counting as
frames where nobody was found. With ``--jobs N``, the first job's.

One job uses one worker process; ``--workers`` only sets how many the server starts.
``--dpm-model`` configures the server with a voc-release5 model (``VTRACK_DPM_MODEL``), for jobs
with ``{"detector": {"name": "dpm"}}``; ``--models-dir`` with a folder of CNN models
(``VTRACK_MODELS_DIR``; the shared data's ``models`` folder is laid out as ``vtrack models
fetch`` lays one out), with which detector 'auto' runs the CNN and the tracker the pose and
re-identification networks found there. ``detector`` and ``networks`` in the report are the
detector and the networks that ran, as the JSON result names them.
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
import time
from datetime import datetime
from pathlib import Path

import cv2
import httpx

# Run as a script, benchmarks/ comes first on sys.path and this file would shadow the service
# package.
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from devtools.testing import Server, wait_for
from tracking.datasets.mot import parse_mot_rows
from tracking.evaluation.hota import hota
from tracking.evaluation.mot import ground_truth_rows, mot_to_image_boxes

try:  # run as a script: benchmarks/ is on sys.path
    from _paths import SHARED_DATA
    from _report import machine, print_json
except ImportError:  # python -m benchmarks.<name> from the repository root
    from benchmarks._paths import SHARED_DATA
    from benchmarks._report import machine, print_json

DEFAULT_VIDEO = SHARED_DATA / "video" / "pets09_s2l1_480x360.avi"
DEFAULT_GROUND_TRUTH = SHARED_DATA / "mot" / "PETS09-S2L1" / "gt" / "gt.txt"
DEFAULT_GT_SCALE = 0.625
"""PETS09-S2L1's annotations are in 768x576 pixels; the video is 480x360."""


def _video_seconds(path: Path) -> tuple[int, float, float]:
    capture = cv2.VideoCapture(str(path))
    frames = int(capture.get(cv2.CAP_PROP_FRAME_COUNT))
    fps = capture.get(cv2.CAP_PROP_FPS)
    capture.release()
    return frames, fps, frames / fps


def score(mot_text: str, ground_truth: Path, scale: float, frames: int) -> dict:
    """HOTA (percent) of a ``mot`` result against MOTChallenge ground truth scaled by ``scale``,
    over the video's first ``frames`` frames."""
    ours = parse_mot_rows(mot_text, min_columns=6, source="the mot result")[:, :6]
    ours[:, 2:6] = mot_to_image_boxes(ours[:, 2:6])
    return hota(ground_truth_rows(ground_truth, scale, frames), ours).percent()


def run(
    video: Path,
    options: dict | None,
    workers: int | None,
    dpm_model: Path | None = None,
    jobs: int = 1,
    ground_truth: tuple[Path, float] | None = None,
    models_dir: Path | None = None,
    inference_threads: int | None = None,
) -> dict:
    frames, fps, duration = _video_seconds(video)
    settings = {"dpm_model": str(dpm_model.resolve())} if dpm_model else {}
    if models_dir is not None:
        settings["models_dir"] = str(models_dir.resolve())
    if inference_threads is not None:
        settings["inference_threads"] = inference_threads
    with tempfile.TemporaryDirectory(prefix="vtrack-bench-") as scratch:
        server = Server(
            Path(scratch) / "data", workers=workers, log_level="warning", **settings
        ).start()
        try:
            with httpx.Client(base_url=server.url, timeout=600) as client:
                start = time.perf_counter()
                job_ids = []
                for _ in range(jobs):
                    with video.open("rb") as handle:
                        files = {"video": (video.name, handle, "video/x-msvideo")}
                        data = {"options": json.dumps(options)} if options else None
                        response = client.post("/v1/jobs", files=files, data=data)
                    if response.status_code != 202:
                        raise RuntimeError(f"the upload was refused: {response.text}")
                    job_ids.append(response.json()["id"])
                uploaded = time.perf_counter()

                def finished(job_id: str) -> dict | None:
                    status = client.get(f"/v1/jobs/{job_id}").json()
                    return status if status["state"] not in ("queued", "running") else None

                statuses = [
                    wait_for(lambda j=job_id: finished(j), 3 * 3600, "the job", interval=0.2)
                    for job_id in job_ids
                ]
                done = time.perf_counter()
                results = []
                for status in statuses:
                    if status["state"] != "succeeded":
                        raise RuntimeError(f"a job {status['state']}: {status['error']}")
                    contents = {
                        fmt: client.get(link).content
                        for fmt, link in status["links"]["results"].items()
                    }
                    results.append(contents)
                detector, networks = None, None
                if "json" in results[0]:
                    ran = json.loads(results[0]["json"])["options"]
                    detector, tracker = ran.get("detector"), ran.get("tracker") or {}
                    networks = {
                        name: tracker.get(f"{name}_model") if tracker.get(name) else None
                        for name in ("pose", "reid")
                    }
                end = time.perf_counter()
        finally:
            server.stop()

    def seconds(status: dict, since: str, until: str) -> float:
        return (
            datetime.fromisoformat(status[until]) - datetime.fromisoformat(status[since])
        ).total_seconds()

    queued_s = max(seconds(s, "created_at", "started_at") for s in statuses)
    job_tracking_s = [round(seconds(s, "started_at", "finished_at"), 2) for s in statuses]
    tracking_s = max(job_tracking_s)
    total = end - start
    accuracy = {}
    if ground_truth is not None and "mot" in results[0]:
        accuracy = score(results[0]["mot"].decode(), *ground_truth, frames)
    return {
        "video": video.name,
        "frames": frames,
        "video_fps": fps,
        "video_seconds": round(duration, 3),
        "options": options or {},
        "settings": settings,
        "detector": detector,
        "networks": networks,
        "jobs": jobs,
        "upload_to_result_s": round(total, 2),
        "ratio_to_real_time": round(total / duration, 3),
        "upload_s": round(uploaded - start, 2),
        "queued_s": round(queued_s, 2),
        "tracking_s": tracking_s,
        "job_tracking_s": job_tracking_s,
        "tracking_fps": round(frames / tracking_s, 2),
        "poll_to_download_s": round(end - done, 2),
        # the first job's results, the ones scored (every job tracks the same video alike)
        "result_bytes": {fmt: len(content) for fmt, content in results[0].items()},
        **accuracy,
        "machine": machine(),
    }


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--video", type=Path, default=DEFAULT_VIDEO, help="video to upload")
    parser.add_argument("--options", type=json.loads, help="job options (JSON)")
    parser.add_argument("--workers", type=int, help="worker processes of the server")
    parser.add_argument(
        "--dpm-model", type=Path, help="voc-release5 model for jobs with detector 'dpm'"
    )
    parser.add_argument(
        "--models-dir",
        type=Path,
        help="folder of CNN models (VTRACK_MODELS_DIR), e.g. the shared data's models folder",
    )
    parser.add_argument(
        "--inference-threads",
        type=int,
        help="threads of each CNN inference (VTRACK_INFERENCE_THREADS; default: the service's)",
    )
    parser.add_argument(
        "--jobs", type=int, default=1, help="upload the video this many times at once"
    )
    parser.add_argument(
        "--ground-truth",
        type=Path,
        help="MOTChallenge gt.txt of the video's frames, to score the tracks (default: "
        "PETS09-S2L1's for the default video)",
    )
    parser.add_argument(
        "--gt-scale",
        type=float,
        help="factor from the ground truth's pixels to the video's (default 0.625 for the "
        "default video, else 1)",
    )
    parser.add_argument("--json", action="store_true", help="print one JSON object")
    args = parser.parse_args(argv)
    if args.jobs < 1:
        parser.error(f"--jobs must be at least 1, got {args.jobs}")
    if args.gt_scale is not None and not args.gt_scale > 0:
        parser.error(f"--gt-scale must be positive, got {args.gt_scale}")
    default_video = args.video == DEFAULT_VIDEO
    gt = args.ground_truth or (DEFAULT_GROUND_TRUTH if default_video else None)
    if gt is not None and not gt.is_file():
        parser.error(f"--ground-truth: no file {gt}")
    scale = args.gt_scale or (DEFAULT_GT_SCALE if default_video and not args.ground_truth else 1.0)
    figures = run(
        args.video,
        args.options,
        args.workers,
        args.dpm_model,
        args.jobs,
        None if gt is None else (gt, scale),
        args.models_dir,
        args.inference_threads,
    )
    if args.json:
        print_json(figures, indent=None)
        return 0
    print(f"{figures['video']}: {figures['frames']} frames, {figures['video_seconds']} s of video")
    print(f"options: {json.dumps(figures['options'])}, {figures['jobs']} job(s) at once")
    if figures["detector"] is not None:
        print(f"detector that ran: {json.dumps(figures['detector'])}")
    if figures["networks"] is not None:
        print(f"pose and re-identification that ran: {json.dumps(figures['networks'])}")
    rows = [
        ("upload to result", f"{figures['upload_to_result_s']:.1f} s"),
        ("ratio to real time", f"{figures['ratio_to_real_time']:.2f}"),
        ("  upload", f"{figures['upload_s']:.1f} s"),
        ("  queued", f"{figures['queued_s']:.1f} s"),
        ("  tracking", f"{figures['tracking_s']:.1f} s ({figures['tracking_fps']:.1f} frames/s)"),
        ("  downloads", f"{figures['poll_to_download_s']:.1f} s"),
    ]
    if "hota" in figures:
        accuracy = f"{figures['hota']} (DetA {figures['det_a']}, AssA {figures['ass_a']})"
        rows.append(("HOTA", accuracy))
    for name, value in rows:
        print(f"{name:<22}{value}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
