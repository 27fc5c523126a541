"""More sequences for the multi-person trackers (issue 76): does each keep the one annotated
person under one id, on video other than the two MOT sequences?

The MOT comparison (``benchmarks/mot.py``) has two annotated sequences, and both were used to
choose ours' parameters. OTB sequences annotate one target each; those whose target is a
standing person among others were held out for the people trackers (until two changes were chosen
on them, docs/benchmarks.md, "Held-out people"). The rule that picks them was written down before
any run: an OTB sequence whose labelled boxes are, in the median, at
least :data:`MIN_PERSON_ASPECT` times as tall as wide (a standing person; faces, heads, birds and
deer are not). In ``../shared/data/otb`` that is Basketball_first200, Couple, Crossing and
Skating1 (860 frames).

Each sequence is laid out as a MOTChallenge folder (its images linked, not copied; the target's
boxes as ``gt/gt.txt``, id 1; :data:`FRAME_RATE`, as OTB gives no rate) and
``benchmarks/mot.py`` runs every tracker on it with the same detections, those of our CNN
detector (``--detections cnn``), ours with its seeds. For the annotated person, per tracker:

- ``covered``: the share of the labelled frames where some track's box overlaps the person's
  (IoU >= 0.5, both boxes set to one aspect about their centre, height kept, so that box shape
  does not count);
- ``kept``: the share of the labelled frames covered by the one track that covers most: the
  single-target case of ID recall (IDR, Ristani et al., ECCV 2016 workshops);
- ``switches``: how often the covering track changes between consecutive covered frames.

The other people in these videos are not annotated, so false positives cannot be counted: these
figures say whether the annotated person is followed under one id, not whether a tracker invents
people (the MOT comparison counts that).

Run: ``python benchmarks/holdout_people.py --seeds 3 --json`` (about 10 minutes on 2 cores).
"""

from __future__ import annotations

import argparse
import json
import re
import shutil
import statistics
import subprocess
import sys
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from tracking.datasets.otb import OtbSequence, find_otb_sequences
from tracking.evaluation.metrics import iou
from tracking.evaluation.mot import read_mot_rows
from tracking.people.motion import PEDESTRIAN_ASPECT, with_aspect

try:  # run as a script: benchmarks/ is on sys.path
    from _paths import REPO_ROOT, SHARED_DATA
    from _report import print_json
except ImportError:  # imported as benchmarks.holdout_people (the tests)
    from benchmarks._paths import REPO_ROOT, SHARED_DATA
    from benchmarks._report import print_json

MIN_PERSON_ASPECT = 2.0
"""Least median height / width of a sequence's labelled boxes for its target to be a person."""

FRAME_RATE = 30.0
"""Frames per second given to every sequence (OTB's videos are mostly 30 fps cameras and web
videos; ours' times are in seconds, the peers count frames)."""

MATCH_IOU = 0.5
"""Least overlap of a track's box with the person's, both set to the pedestrian aspect
(:data:`~tracking.people.motion.PEDESTRIAN_ASPECT`) before they are compared."""

_SEED = re.compile(r"_seed\d+")


def labelled(sequence: OtbSequence) -> np.ndarray:
    """Whether each frame of ``sequence`` has a target box (OTB marks the others NaN or 0)."""
    boxes = sequence.ground_truth
    return np.all(np.isfinite(boxes), axis=1) & (boxes[:, 2] > 0) & (boxes[:, 3] > 0)


def person_sequences(root: Path) -> list[OtbSequence]:
    """The OTB sequences under ``root`` whose target is a standing person (the module's rule)."""
    chosen = []
    for sequence in find_otb_sequences(root):
        boxes = sequence.ground_truth[labelled(sequence)]
        if len(boxes) and np.median(boxes[:, 3] / boxes[:, 2]) >= MIN_PERSON_ASPECT:
            chosen.append(sequence)
    return chosen


def mot_folder(sequence: OtbSequence, root: Path, frame_rate: float = FRAME_RATE) -> Path:
    """``root/<name>``: ``sequence`` as a MOTChallenge sequence (``seqinfo.ini``, ``img1``
    linked to its images, the target as id 1 of ``gt/gt.txt`` in 1-based file units)."""
    import cv2

    folder = root / sequence.name
    (folder / "gt").mkdir(parents=True)
    images = sequence.frame_paths[0].parent
    (folder / "img1").symlink_to(images.resolve(), target_is_directory=True)
    first = cv2.imread(str(sequence.frame_paths[0]), cv2.IMREAD_UNCHANGED)
    if first is None:
        raise ValueError(f"cannot read {sequence.frame_paths[0]}")
    suffixes = {p.suffix.lower() for p in images.iterdir() if p.is_file()}
    if len(suffixes) != 1:  # the MOT reader lists img1/*<imExt>: the frames and nothing else
        raise ValueError(f"{images} holds files other than its frames ({sorted(suffixes)})")
    (folder / "seqinfo.ini").write_text(
        "[Sequence]\n"
        f"name={sequence.name}\nimDir=img1\nframeRate={frame_rate:g}\n"
        f"seqLength={len(sequence)}\nimWidth={first.shape[1]}\nimHeight={first.shape[0]}\n"
        f"imExt={sequence.frame_paths[0].suffix}\n"
    )
    frames = np.flatnonzero(labelled(sequence))
    boxes = sequence.ground_truth[frames]
    rows = [
        f"{f + 1},1,{x + 1:.2f},{y + 1:.2f},{w:.2f},{h:.2f},1,1,1"
        for f, (x, y, w, h) in zip(frames, boxes, strict=True)
    ]
    (folder / "gt" / "gt.txt").write_text("\n".join(rows) + "\n")
    return folder


def target_identity(truth: np.ndarray, rows: np.ndarray) -> dict[str, float]:
    """How one annotated person is followed: ``truth`` its rows (``frame, id, x, y, w, h``),
    ``rows`` a tracker's (the same units); see the module's docstring for the figures."""
    truth, rows = np.asarray(truth, dtype=float), np.asarray(rows, dtype=float)
    frames = truth[:, 0].astype(np.int64)
    if len(rows) == 0 or len(frames) == 0:
        return {"covered": 0.0, "kept": 0.0, "switches": 0.0, "frames": float(len(frames))}
    index = np.full(max(frames.max(), int(rows[:, 0].max())) + 1, -1)
    index[frames] = np.arange(len(frames))
    rows = rows[index[rows[:, 0].astype(np.int64)] >= 0]
    person = with_aspect(truth[index[rows[:, 0].astype(np.int64)], 2:6], PEDESTRIAN_ASPECT)
    tracked = with_aspect(rows[:, 2:6], PEDESTRIAN_ASPECT)
    overlap = iou(tracked, person)  # per row, the tracking metrics' own overlap
    good = rows[overlap >= MATCH_IOU]
    overlap = overlap[overlap >= MATCH_IOU]
    # per frame, the track that overlaps most
    order = np.lexsort((-overlap, good[:, 0]))
    _, first = np.unique(good[order, 0], return_index=True)
    ids = good[order[first], 1].astype(np.int64)
    kept = np.unique(ids, return_counts=True)[1].max() if len(ids) else 0
    return {
        "covered": len(ids) / len(frames),
        "kept": float(kept) / len(frames),
        "switches": float(np.count_nonzero(ids[1:] != ids[:-1])),
        "frames": float(len(frames)),
    }


def run_mot(
    folders: Sequence[Path], results: Path, seeds: int, frames: int | None, extra: Sequence[str]
) -> dict:
    """``benchmarks/mot.py`` on ``folders`` with the CNN's detections; its JSON report."""
    command = [
        sys.executable,
        str(REPO_ROOT / "benchmarks" / "mot.py"),
        "--sequences",
        *map(str, folders),
        "--detections",
        "cnn",
        "--no-end-to-end",
        "--repeats",
        "1",
        "--seeds",
        str(seeds),
        *(["--frames", str(frames)] if frames else []),
        "--results",
        str(results),
        "--json",
        "--no-score",  # TrackEval would count every other person as a false positive
        *extra,
    ]
    done = subprocess.run(command, stdout=subprocess.PIPE, text=True, check=False)
    if done.returncode != 0:
        raise SystemExit(f"benchmarks/mot.py failed (exit {done.returncode})")
    return json.loads(done.stdout[done.stdout.index("{") :])


def score(
    report: dict, folders: Sequence[Path], frames: int | None = None
) -> dict[str, dict[str, dict[str, float]]]:
    """``{tracker: {sequence: figures}}`` from the result files of ``report`` (every row that
    ran, scored by TrackEval or not), seeds averaged (a row's name without ``_seed<k>`` and
    ``@cnn``); ``frames``: only the first so many frames ran."""
    results = Path(report["results_dir"])
    runs: dict[str, dict[str, list[dict[str, float]]]] = {}
    for row in sorted(p.name for p in results.iterdir() if p.is_dir()):
        base = _SEED.sub("", row.split("@")[0])
        if base.endswith("+aspect"):  # the peer's own boxes at another width: the same figures
            continue
        for folder in folders:
            path = results / row / f"{folder.name}.txt"
            if not path.is_file():
                continue
            truth = read_mot_rows(folder / "gt" / "gt.txt", min_columns=6)
            truth = truth[truth[:, 0] <= (frames or np.inf)]
            figures = target_identity(truth, read_mot_rows(path, min_columns=6))
            runs.setdefault(base, {}).setdefault(folder.name, []).append(figures)
    return {
        tracker: {
            name: {k: statistics.fmean(f[k] for f in seeds) for k in seeds[0]}
            for name, seeds in sequences.items()
        }
        for tracker, sequences in runs.items()
    }


def summary(scores: dict[str, dict[str, dict[str, float]]]) -> dict[str, dict[str, float]]:
    """Each tracker's figures averaged over the sequences (each sequence counts once)."""
    return {
        tracker: {
            k: statistics.fmean(f[k] for f in sequences.values())
            for k in ("covered", "kept", "switches")
        }
        for tracker, sequences in scores.items()
    }


def format_table(scores: dict[str, dict[str, dict[str, float]]]) -> str:
    """Kept / covered (percent) and switches per sequence and over all, best kept first."""
    overall = summary(scores)
    names = sorted(next(iter(scores.values())))
    header = f"{'tracker':22s}" + "".join(f"{n[:18]:>20s}" for n in [*names, "mean"])
    lines = [header, f"{'':22s}" + f"{'kept/covered sw':>20s}" * (len(names) + 1)]
    for tracker in sorted(overall, key=lambda t: -overall[t]["kept"]):
        cells = [scores[tracker].get(n) for n in names] + [overall[tracker]]
        lines.append(
            f"{tracker:22s}"
            + "".join(
                f"{100 * f['kept']:>10.1f}/{100 * f['covered']:4.1f} {f['switches']:4.1f}"
                if f
                else f"{'-':>20s}"
                for f in cells
            )
        )
    return "\n".join(lines)


def parse_args(argv: Sequence[str] | None) -> argparse.Namespace:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--otb", type=Path, default=SHARED_DATA / "otb", help="OTB folder")
    parser.add_argument("--seeds", type=int, default=3, help="seeds of each of ours (default 3)")
    parser.add_argument(
        "--results",
        type=Path,
        default=REPO_ROOT / "benchmarks" / "results" / "holdout_people",
        help="where the sequences are laid out and mot.py writes (emptied first)",
    )
    parser.add_argument("--frames", type=int, help="only the first N frames of each sequence")
    parser.add_argument("--json", action="store_true", help="print one JSON object to stdout")
    parser.add_argument(
        "mot_args", nargs=argparse.REMAINDER, help="after --: more options for benchmarks/mot.py"
    )
    return parser.parse_args(argv)


def main(argv: Sequence[str] | None = None) -> int:
    args = parse_args(argv)
    sequences = person_sequences(args.otb)
    if not sequences:
        raise SystemExit(f"no OTB sequence under {args.otb} has a standing person as its target")
    shutil.rmtree(args.results, ignore_errors=True)
    folders = [mot_folder(s, args.results / "sequences") for s in sequences]
    extra = [a for a in args.mot_args if a != "--"]
    report = run_mot(folders, args.results / "mot", args.seeds, args.frames, extra)
    scores = score(report, folders, args.frames)
    if args.json:
        print_json(
            {
                "sequences": [f.name for f in folders],
                "frame_rate": FRAME_RATE,
                "scores": scores,
                "summary": summary(scores),
            }
        )
    else:
        print(format_table(scores))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
