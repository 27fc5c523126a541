"""Run a multi-object tracker of Roboflow's ``trackers`` over MOTChallenge sequences; print JSON.

A standalone script for the MOT peer environment (``trackers``, ``supervision``, OpenCV 5; see
``benchmarks/_mot_env.py``): it imports nothing from the project but its sibling
``_sequences.py``. ``benchmarks/mot.py`` runs it
in a subprocess:

    .venv-mot/bin/python benchmarks/peers/mot_trackers.py KIND SEQUENCE_DIR [...]
        [--det FILE [...]] [--frames N] [--repeats R] [--frame-rate sequence|library]

Kinds: ``sort`` (SORTTracker), ``bytetrack`` (ByteTrackTracker), ``ocsort`` (OCSORTTracker),
``botsort`` (BoTSORTTracker). Every parameter keeps the library's default except
``frame_rate``, which by default (``--frame-rate sequence``) is the sequence's ``frameRate``
from ``seqinfo.ini``: it describes the input, not the tracker, and the library uses it only to
scale ``lost_track_buffer`` (given in frames at 30 fps) to the video's rate. ``--frame-rate
library`` keeps the library's 30 fps. Updates run in the library's fixed-rate mode (no
timestamps): every frame is one step.

Input, per frame, the detections of a MOTChallenge detection file as ``supervision.Detections``
with ``xyxy`` and ``confidence`` (the file's column 7, as it is), in the file's coordinates
(1-based; these trackers never look at pixels, so their output stays in the same convention).
The file is the sequence's public detections ``det/det.txt``, or the i-th ``--det FILE`` for
the i-th sequence (``benchmarks/mot.py`` passes its CNN detections so). Rows without width or
height are left out, as the project's ``MotDetections`` leaves them out for ours. BoT-SORT also
gets the frame (BGR, as it expects) for its camera-motion compensation (on by default,
sparse optical flow at half resolution); the others get no frame (they would only warn).

Output: the detections the tracker returns with a ``tracker_id`` of 0 or more (confirmed
tracks; -1 marks unmatched or not yet confirmed boxes, which are left out), their box being the
matched detection's box, as the library reports it.

Only ``update`` is timed (``time.perf_counter``); reading images and building the
``Detections`` are not. With ``--repeats R`` the sequence is tracked R times by fresh trackers
and every run's time is reported; the rows are those of the first run, and ``"deterministic"``
says whether every run gave the same rows.

Output (stdout): one JSON object ``{"kind", "class", "versions", "params", "sequences": [...]}``;
each sequence is ``{"name", "frames", "frame_rate", "rows": [[frame, id, x, y, w, h, conf],
...], "seconds": [per run], "deterministic", "fed_digest"}`` or ``{"name", "error"}``.
``fed_digest`` is a digest of the boxes the tracker was given (frame, x, y, w, h, rounded to
1e-4 px), the same function as ``benchmarks/mot.py``'s ``fed_digest``.
"""

from __future__ import annotations

import argparse
import configparser
import functools
import importlib.metadata
import inspect
import json
import sys
import time
import warnings
from pathlib import Path

import cv2
import numpy as np
import supervision as sv
import trackers
from _sequences import add_run_arguments, check_run_arguments, fed_digest, run_sequences

KINDS = {
    "sort": trackers.SORTTracker,
    "bytetrack": trackers.ByteTrackTracker,
    "ocsort": trackers.OCSORTTracker,
    "botsort": trackers.BoTSORTTracker,
}
NEEDS_FRAMES = frozenset({"botsort"})  # camera-motion compensation reads the image


def default_params(kind: str) -> dict[str, object]:
    """The constructor defaults of ``kind``'s class (for the record), as JSON-ready values."""
    signature = inspect.signature(KINDS[kind].__init__)
    params = {}
    for name, parameter in signature.parameters.items():
        if name == "self" or parameter.default is inspect.Parameter.empty:
            continue
        value = parameter.default
        if isinstance(value, type):
            value = value.__name__
        elif not isinstance(value, str | int | float | bool | type(None)):
            value = repr(value)
        params[name] = value
    return params


def read_sequence(folder: Path, det_file: Path | None = None) -> dict[str, object]:
    """Name, frame rate and frame paths from ``seqinfo.ini``; detections (``det_file``, by
    default ``det/det.txt``), rows with a width and a height."""
    parser = configparser.ConfigParser()
    if not parser.read(folder / "seqinfo.ini", encoding="utf-8"):
        raise ValueError(f"{folder}: no seqinfo.ini")
    info = parser["Sequence"]
    suffix = info.get("imExt", ".jpg").lower()
    frames = sorted(
        p for p in (folder / info.get("imDir", "img1")).glob("*") if p.suffix.lower() == suffix
    )
    length = int(info.get("seqLength", len(frames)))
    if len(frames) < length:
        raise ValueError(f"{folder}: seqLength {length} but {len(frames)} images")
    rows = np.loadtxt(det_file or folder / "det" / "det.txt", delimiter=",", ndmin=2)
    if rows.size == 0:
        rows = np.zeros((0, 7))
    rows = rows[(rows[:, 4] > 0) & (rows[:, 5] > 0)]
    return {
        "name": info.get("name", folder.name),
        "frame_rate": float(info["frameRate"]),
        "frames": frames[:length],
        "detections": rows,
    }


def to_detections(rows: np.ndarray) -> sv.Detections:
    """File rows ``frame, id, x, y, w, h, conf, ...`` of one frame -> ``sv.Detections``."""
    if len(rows) == 0:
        return sv.Detections.empty()
    xywh = rows[:, 2:6]
    xyxy = np.concatenate([xywh[:, :2], xywh[:, :2] + xywh[:, 2:4]], axis=1)
    return sv.Detections(xyxy=xyxy, confidence=rows[:, 6].copy())


def track_once(
    kind: str, sequence: dict[str, object], frames: int, frame_rate: float | None
) -> tuple[list[list[float]], float, str]:
    """One run of a fresh tracker: result rows (file units), the seconds spent in update and
    the digest of the detections it was given."""
    tracker = KINDS[kind](**({} if frame_rate is None else {"frame_rate": frame_rate}))
    detections: np.ndarray = sequence["detections"]
    by_frame = {int(f): detections[detections[:, 0] == f] for f in np.unique(detections[:, 0])}
    empty = np.zeros((0, detections.shape[1]))
    rows: list[list[float]] = []
    fed: list[np.ndarray] = []
    seconds = 0.0
    for index in range(frames):
        frame_number = index + 1
        given = by_frame.get(frame_number, empty)
        fed.append(np.column_stack([given[:, 0], given[:, 2:6]]))
        current = to_detections(given)
        image = None
        if kind in NEEDS_FRAMES:
            image = cv2.imread(str(sequence["frames"][index]), cv2.IMREAD_COLOR)
            if image is None:
                raise ValueError(f"cannot read image {sequence['frames'][index]}")
        start = time.perf_counter()
        tracked = tracker.update(current) if image is None else tracker.update(current, image)
        seconds += time.perf_counter() - start
        if len(tracked) == 0 or tracked.tracker_id is None:
            continue
        confidence = tracked.confidence
        if confidence is None:
            confidence = np.ones(len(tracked))
        for (x1, y1, x2, y2), track_id, score in zip(
            tracked.xyxy, tracked.tracker_id, confidence, strict=True
        ):
            if track_id >= 0:
                rows.append(
                    [frame_number, int(track_id), float(x1), float(y1), float(x2 - x1),
                     float(y2 - y1), float(score)]
                )  # fmt: skip
    return rows, seconds, fed_digest(np.concatenate(fed) if fed else np.zeros((0, 5)))


def run_sequence(
    kind: str,
    folder: Path,
    max_frames: int | None,
    repeats: int,
    use_sequence_rate: bool,
    det_file: Path | None = None,
) -> dict[str, object]:
    sequence = read_sequence(folder, det_file)
    frames = len(sequence["frames"])
    if max_frames is not None:
        frames = min(frames, max_frames)
    frame_rate = sequence["frame_rate"] if use_sequence_rate else None
    runs = [track_once(kind, sequence, frames, frame_rate) for _ in range(repeats)]
    rows = runs[0][0]
    return {
        "name": sequence["name"],
        "frames": frames,
        "frame_rate": sequence["frame_rate"],
        "rows": rows,
        "seconds": [seconds for _, seconds, _ in runs],
        "deterministic": all(r == rows for r, _, _ in runs[1:]),
        "fed_digest": runs[0][2],
    }


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("kind", choices=sorted(KINDS))
    parser.add_argument("sequences", nargs="+", type=Path, help="MOTChallenge sequence folders")
    parser.add_argument(
        "--det",
        type=Path,
        action="append",
        help="detection file of each sequence, in order (default: each one's det/det.txt)",
    )
    add_run_arguments(
        parser, "frame_rate passed to the tracker: seqinfo.ini's (default) or the library's 30"
    )
    args = parser.parse_args(argv)
    check_run_arguments(parser, args)
    if args.det is not None and len(args.det) != len(args.sequences):
        parser.error("give one --det per sequence, or none")
    det_files = args.det or [None] * len(args.sequences)
    warnings.simplefilter("ignore", FutureWarning)  # pyDeprecate notices of the library
    runs = [
        (
            folder.name,
            functools.partial(
                run_sequence,
                args.kind,
                folder,
                args.frames,
                args.repeats,
                args.frame_rate == "sequence",
                det_file,
            ),
        )
        for folder, det_file in zip(args.sequences, det_files, strict=True)
    ]
    # the library logs through `logging` and may print: run_sequences keeps stdout for the JSON
    results = run_sequences(
        args.kind, runs, (OSError, ValueError, KeyError, cv2.error), args.repeats
    )
    params = default_params(args.kind)
    params["frame_rate"] = "seqinfo.ini frameRate" if args.frame_rate == "sequence" else 30.0
    versions = {
        name: importlib.metadata.version(name)
        for name in ("trackers", "supervision", "opencv-python", "numpy", "scipy")
    }
    json.dump(
        {
            "kind": args.kind,
            "class": KINDS[args.kind].__name__,
            "versions": versions,
            "params": params,
            "sequences": results,
        },
        sys.stdout,
    )
    sys.stdout.write("\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
