"""Body parts measured by the pose network: how often each part of a tracked person is placed by
a keypoint of the frame, rather than predicted by the body model.

    python benchmarks/parts.py [--data DIR] [--sequence NAME] [--frames N] [--models DIR] [--json]

The people tracker runs end to end on a MOTChallenge sequence (default PETS09-S2L1 of the shared
data) with the CNN person detector (person-detection-0202), the pose network
(human-pose-estimation-0001) and the re-identification network (0287), all from ``--models``
(default: the shared data's ``models`` folder), as a service job with the three installed runs.
Over every reported person that is confirmed and not occluded in a frame, it counts the frames
in which each part group was measured: ``any`` when at least one keypoint of the group was (head:
nose, eyes or ears; shoulders, hips, ankles: left or right), ``all`` when every one was. The time
is the tracker's ``update`` calls, detector and networks included.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

try:  # run as a script: benchmarks/ is on sys.path
    from _paths import SHARED_DATA
    from _report import machine, print_json
except ImportError:  # python -m benchmarks.parts from the repository root
    from benchmarks._paths import SHARED_DATA
    from benchmarks._report import machine, print_json

GROUPS = {
    "head": ("nose", "right_eye", "left_eye", "right_ear", "left_ear"),
    "shoulders": ("left_shoulder", "right_shoulder"),
    "hips": ("left_hip", "right_hip"),
    "ankles": ("left_ankle", "right_ankle"),
}
MODELS = {
    "detector": "person-detection-0202/FP16/person-detection-0202.xml",
    "pose": "human-pose-estimation-0001/FP16-INT8/human-pose-estimation-0001.xml",
    "reid": "person-reidentification-retail-0287/FP16/person-reidentification-retail-0287.xml",
}


def measure(sequence: Path, models: Path, frames: int | None) -> dict[str, object]:
    """Shares of unoccluded person-frames whose part groups were measured, and the time."""
    from tracking.datasets.mot import MotSequence
    from tracking.detection import make_detector
    from tracking.detection.pose import PoseEstimator
    from tracking.detection.reid import ReidEmbedder
    from tracking.evaluation.mot import read_sequence_info
    from tracking.people import MultiPersonTracker

    mot = MotSequence.open(sequence)
    info = read_sequence_info(sequence)
    tracker = MultiPersonTracker(
        detector=make_detector(models / MODELS["detector"]),
        pose=PoseEstimator.from_file(models / MODELS["pose"]),
        reid=ReidEmbedder.from_file(models / MODELS["reid"]),
    )
    count = len(mot) if frames is None else min(frames, len(mot))
    anything = dict.fromkeys(GROUPS, 0)
    every = dict.fromkeys(GROUPS, 0)
    people = 0
    seconds = 0.0
    for index in range(count):
        frame = mot.read_frame(index)
        start = time.perf_counter()
        tracks = tracker.update(frame, info.timestamp(index))
        seconds += time.perf_counter() - start
        for track in tracks:
            if track.occluded:
                continue
            people += 1
            measured = {part.name: part.measured for part in track.parts}
            for group, names in GROUPS.items():
                anything[group] += any(measured[n] for n in names)
                every[group] += all(measured[n] for n in names)
    share = max(people, 1)
    return {
        "sequence": mot.path.name,
        "frames": count,
        "person_frames": people,
        "measured_any": {g: round(v / share, 3) for g, v in anything.items()},
        "measured_all": {g: round(v / share, 3) for g, v in every.items()},
        "seconds": round(seconds, 2),
        "ms_per_frame": round(1000 * seconds / max(count, 1), 1),
        "ratio_to_real_time": round(seconds / (count / info.frame_rate), 3),
        "machine": machine(),
    }


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--data", type=Path, default=SHARED_DATA / "mot", help="MOT sequences")
    parser.add_argument("--sequence", default="PETS09-S2L1", help="a sequence under --data")
    parser.add_argument("--frames", type=int, help="only the first N frames")
    parser.add_argument("--models", type=Path, default=SHARED_DATA / "models")
    parser.add_argument("--json", action="store_true", help="one JSON object on stdout")
    args = parser.parse_args(argv)
    missing = [str(args.models / m) for m in MODELS.values() if not (args.models / m).is_file()]
    if missing:
        parser.error(f"models not found: {', '.join(missing)}")
    if args.frames is not None and args.frames < 1:
        parser.error("--frames must be positive")
    figures = measure(args.data / args.sequence, args.models, args.frames)
    if args.json:
        print_json(figures)
        return 0
    print(f"{figures['sequence']}: {figures['frames']} frames, {figures['person_frames']} "
          "unoccluded person-frames")  # fmt: skip
    for group in GROUPS:
        any_share, all_share = figures["measured_any"][group], figures["measured_all"][group]
        print(f"  {group:<10} measured {any_share:.3f} (every keypoint: {all_share:.3f})")
    print(f"  {figures['ms_per_frame']} ms per frame, {figures['ratio_to_real_time']} of real time")
    return 0


if __name__ == "__main__":
    sys.exit(main())
