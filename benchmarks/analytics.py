"""Counting people at lines and zones: the service's counts against those of the ground truth,
every tracker of the MOT benchmark counted with the same code, and what counting costs.

The lines and the zone follow one rule on every sequence, fitted to none, in normalised
coordinates: a vertical line down the middle of the frame, a horizontal line across it at 60 %
of its height (people walk on the lower part of these scenes), and the central quarter as a
zone with a 2 s dwell. Each sequence's ground-truth trajectories are counted with
:func:`tracking.evaluation.counting.count_rows` (ground point: the box's bottom centre).

* **service**: a job as users run it, the sequence's images through
  :func:`service.analysis.analyze` with the options' ``analytics`` (detector 'auto' with the
  CNN person detector, pose and re-identification networks of ``--models``), its counts from
  the job's own analytics (ankles where the pose network placed them);
* **trackers** (``--mot-results DIR``, the ``--results`` folder of ``benchmarks/mot.py``): each
  tracker's result file ``DIR/<tracker>/<sequence>.txt`` counted like the ground truth: the
  peers and ours on the same detections, with the same boxes;
* the error: the sum over both lines' two directions and the zone's entries of
  ``|count - true count|``, over the sum of the true counts;
* the cost: the counting engine's time per frame on the ground truth's people (median of
  ``--repeats``), beside the service's time per frame.

Usage::

    python benchmarks/analytics.py [--data DIR] [--models DIR] [--mot-results DIR]
        [--repeats 5] [--json]
"""

from __future__ import annotations

import argparse
import statistics
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from api_schemas.analytics import AnalyticsOptions
from api_schemas.jobs import JobOptions
from service.analysis import analyze
from service.analytics import analytics_config, engine_counts
from service.models.catalog import DEFAULT_DETECTOR, DEFAULT_POSE, DEFAULT_REID, model_path
from service.pipelines import PipelineResources
from tracking.analytics import AnalyticsConfig, AnalyticsEngine, Counts, ground_points
from tracking.datasets.mot import mot_to_image_boxes, read_mot_rows
from tracking.evaluation.counting import count_error, count_rows
from tracking.evaluation.mot import ground_truth_rows, read_sequence_info

try:  # run as a script: benchmarks/ is on sys.path
    from _paths import SHARED_DATA
    from _report import print_json
except ImportError:  # python -m benchmarks.<name> from the repository root
    from benchmarks._paths import SHARED_DATA
    from benchmarks._report import print_json

RULE = AnalyticsOptions.model_validate(
    {
        "coordinates": "normalized",
        "lines": [
            {"name": "vertical", "points": [[0.5, 0.0], [0.5, 1.0]]},
            {"name": "horizontal", "points": [[0.0, 0.6], [1.0, 0.6]]},
        ],
        "zones": [
            {
                "name": "centre",
                "polygon": [[0.25, 0.25], [0.75, 0.25], [0.75, 0.75], [0.25, 0.75]],
                "min_dwell": 2.0,
            }
        ],
    }
)
"""The lines and zone of every sequence (see the module's docstring)."""


def counts_dict(counts: Counts) -> dict[str, object]:
    return {"lines": counts.lines, "zones": counts.zones}


def error_of(counts: Counts, truth: Counts) -> dict[str, object]:
    error, total = count_error(counts, truth)
    return {"error": error, "true_total": total, "relative": error / max(total, 1)}


def service_counts(sequence: Path, models: Path) -> tuple[Counts, float, int]:
    """The counts of a job on ``sequence``'s images (its time and frames too)."""
    resources = PipelineResources(
        models_dir=models,
        cnn_model=model_path(models, DEFAULT_DETECTOR),
        pose_model=model_path(models, DEFAULT_POSE),
        reid_model=model_path(models, DEFAULT_REID),
    )
    options = JobOptions(formats=["mot"], analytics=RULE)
    with tempfile.TemporaryDirectory() as scratch:
        result = analyze(sequence / "img1", options, Path(scratch) / "run", resources=resources)
    assert result.analytics is not None
    counts = engine_counts(result.analytics)
    return counts, result.seconds, result.frames_processed


def counting_cost(rows: np.ndarray, config: AnalyticsConfig, fps: float, repeats: int) -> float:
    """Median seconds per frame of the counting engine over ``rows``' frames."""
    frames = rows[:, 0].astype(np.int64)
    blocks = [rows[frames == f] for f in np.unique(frames)]
    times = []
    for _ in range(repeats):
        engine = AnalyticsEngine(config)
        started = time.perf_counter()
        for block in blocks:
            boxes = block[:, 2:6]
            engine.update((block[0, 0] - 1) / fps, block[:, 1], ground_points(boxes), boxes)
        times.append((time.perf_counter() - started) / max(len(blocks), 1))
    return statistics.median(times)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--data", type=Path, default=SHARED_DATA / "mot")
    parser.add_argument("--models", type=Path, default=SHARED_DATA / "models")
    parser.add_argument("--mot-results", type=Path, help="benchmarks/mot.py --results folder")
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--no-service", action="store_true", help="skip the service's jobs")
    parser.add_argument("--json", action="store_true")
    args = parser.parse_args()
    report: dict[str, object] = {"rule": RULE.model_dump(mode="json"), "sequences": {}}
    for sequence in sorted(p for p in args.data.iterdir() if (p / "gt" / "gt.txt").is_file()):
        info = read_sequence_info(sequence)
        config = analytics_config(RULE, (info.width, info.height))
        truth_rows = ground_truth_rows(sequence / "gt" / "gt.txt")
        truth = count_rows(truth_rows, config, info.frame_rate)
        entry: dict[str, object] = {
            "frames": len(info),
            "fps": info.frame_rate,
            "truth": counts_dict(truth),
            "counting_seconds_per_frame": counting_cost(
                truth_rows, config, info.frame_rate, args.repeats
            ),
            "trackers": {},
        }
        if not args.no_service:
            counts, seconds, frames = service_counts(sequence, args.models)
            entry["service"] = {
                **counts_dict(counts),
                **error_of(counts, truth),
                "seconds_per_frame": seconds / max(frames, 1),
            }
        if args.mot_results is not None:
            for tracker in sorted(p for p in args.mot_results.iterdir() if p.is_dir()):
                path = tracker / f"{sequence.name}.txt"
                if not path.is_file():
                    continue
                rows = read_mot_rows(path, min_columns=6)
                rows = np.column_stack([rows[:, :2], mot_to_image_boxes(rows[:, 2:6])])
                counts = count_rows(rows, config, info.frame_rate)
                entry["trackers"][tracker.name] = {**counts_dict(counts), **error_of(counts, truth)}
        report["sequences"][sequence.name] = entry
    if args.json:
        print_json(report)
        return 0
    for name, entry in report["sequences"].items():
        print(f"{name}: {entry['frames']} frames at {entry['fps']:g} fps")
        print(f"  truth     {entry['truth']}")
        rows = ([("service", entry["service"])] if "service" in entry else []) + list(
            entry["trackers"].items()
        )
        for label, row in rows:
            print(f"  {label:<22} error {row['error']:>3} / {row['true_total']}"
                  f" ({row['relative']:.1%})")  # fmt: skip
        cost = entry["counting_seconds_per_frame"] * 1e6
        print(f"  counting: {cost:.0f} us per frame", end="")
        if "service" in entry:
            share = entry["counting_seconds_per_frame"] / entry["service"]["seconds_per_frame"]
            print(f" ({share:.2%} of the service's time per frame)")
        else:
            print()
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
