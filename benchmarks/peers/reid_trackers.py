"""Run a BoxMOT tracker with a learned appearance model over MOTChallenge sequences; print JSON.

A standalone script for the re-id peer environment (``boxmot``, PyTorch, OpenCV 4; see
``benchmarks/_reid_env.py``): it imports nothing from the project but its sibling
``_sequences.py``. ``benchmarks/mot.py`` runs it
in a subprocess:

    .venv-reid/bin/python benchmarks/peers/reid_trackers.py KIND SEQUENCE_DIR [...]
        --det FILE [...] --embeddings NPY [...] [--frames N] [--repeats R]
        [--frame-rate sequence|library]

Kinds: ``deepocsort`` (BoxMOT's DeepOcSort, Maggiolino et al. 2023), ``strongsort``
(StrongSort, Du et al. 2023) and ``botsort_reid`` (BoxMOT's BotSort, Aharon et al. 2022, with
its re-identification on). Each is made by BoxMOT's own factory, ``create_tracker(TrackerSpec(
name))``, so every parameter is BoxMOT's default (its ``configs/trackers/<name>.yaml``), except
BoT-SORT's ``frame_rate``, which by default (``--frame-rate sequence``) is the sequence's
``frameRate`` from ``seqinfo.ini`` (as for the other peers; it scales BoT-SORT's
``track_buffer``, given in frames at 30 fps). Deep OC-SORT and StrongSORT have no frame-rate
parameter: their ``max_age`` stays 30 frames whatever the video's rate. Updates run in BoxMOT's
fixed-step mode (no timestamps).

Input, per frame and sequence (the i-th ``--det`` and ``--embeddings`` belong to the i-th
sequence):

- the detections of ``--det``, a MOTChallenge detection file (rows ``frame, id, x, y, w, h,
  conf, ...``, 1-based), rows without width or height left out (as the project's
  ``MotDetections`` does), as ``boxmot.structures.Detections`` with corners ``x1, y1, x2, y2``
  in the file's coordinates and the confidence column clipped to ``[0, 1]`` (BoxMOT refuses
  others; the files here are within it);
- ``embeddings=``: the rows of ``--embeddings`` (``.npy``, ``(rows of the file, D)`` float32,
  aligned with the file's rows), the project's re-identification network's L2-normalised
  vectors. A row of NaN (a box the network could not embed: too small, outside the frame) is
  replaced by the unit vector ``1 / sqrt(D)`` in every component, an appearance equally
  (un)like every other; the count is reported as ``"unembedded"``. With embeddings given,
  BoxMOT never builds its ReID backend, so no weights are loaded or downloaded (the script
  checks that none was built);
- the frame (BGR), which all three read for their camera-motion compensation.

Output: the tracks BoxMOT returns (its confirmed tracks; their box is the tracker's estimate as
BoxMOT reports it), ids as given. Only ``update`` is timed (``time.perf_counter``); reading
images and building the ``Detections`` are not, and neither is the re-identification network,
which ran beforehand in the benchmark's process. With ``--repeats R`` the sequence is tracked R
times by fresh trackers; the rows are those of the first run, ``"deterministic"`` says whether
every run gave the same rows.

Output (stdout): one JSON object ``{"kind", "class", "versions", "params", "sequences": [...]}``;
each sequence is ``{"name", "frames", "frame_rate", "rows": [[frame, id, x, y, w, h, conf],
...], "seconds": [per run], "deterministic", "fed_digest", "unembedded"}`` or ``{"name",
"error"}``. ``fed_digest`` is a digest of the boxes the tracker was given (frame, x, y, w, h,
rounded to 1e-4 px), the same function as ``benchmarks/mot.py``'s ``fed_digest``.
"""

from __future__ import annotations

import argparse
import configparser
import contextlib
import functools
import importlib.metadata
import json
import logging
import os
import sys
import time
import warnings
from pathlib import Path

os.environ.setdefault("HF_HUB_OFFLINE", "1")  # nothing is to be fetched; fail rather than try

import cv2
import numpy as np
import torch
from _sequences import add_run_arguments, check_run_arguments, fed_digest, run_sequences
from boxmot import create_tracker
from boxmot.structures import Boxes, Detections
from boxmot.trackers.config import load_tracker_config
from boxmot.trackers.specs import TrackerSpec

KINDS = {"deepocsort": "deepocsort", "strongsort": "strongsort", "botsort_reid": "botsort"}
FRAME_RATE_PARAM = {"botsort_reid": "frame_rate"}  # the others have none


def read_sequence(folder: Path, det_file: Path, embeddings_file: Path) -> dict[str, object]:
    """Name, frame rate, frame paths, detection rows and their embeddings."""
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
    rows = np.loadtxt(det_file, delimiter=",", ndmin=2)
    if rows.size == 0:
        rows = np.zeros((0, 7))
    embeddings = np.load(embeddings_file)
    if embeddings.ndim != 2 or len(embeddings) != len(rows):
        raise ValueError(
            f"{embeddings_file}: {embeddings.shape} embeddings for {len(rows)} rows of {det_file}"
        )
    sized = (rows[:, 4] > 0) & (rows[:, 5] > 0)
    return {
        "name": info.get("name", folder.name),
        "frame_rate": float(info["frameRate"]),
        "frames": frames[:length],
        "detections": rows[sized],
        "embeddings": embeddings[sized].astype(np.float32),
    }


def to_detections(rows: np.ndarray, embeddings: np.ndarray, index: int) -> Detections:
    """File rows ``frame, id, x, y, w, h, conf, ...`` of one frame and their embeddings."""
    xywh = rows[:, 2:6]
    xyxy = np.concatenate([xywh[:, :2], xywh[:, :2] + xywh[:, 2:4]], axis=1)
    return Detections(
        geometry=Boxes(torch.from_numpy(np.ascontiguousarray(xyxy, dtype=np.float32))),
        scores=torch.from_numpy(np.clip(rows[:, 6], 0.0, 1.0).astype(np.float32)),
        class_ids=torch.zeros(len(rows), dtype=torch.int64),
        sample_id=f"frame{index + 1}",
        embeddings=torch.from_numpy(np.ascontiguousarray(embeddings, dtype=np.float32)),
    )


def make_tracker(kind: str, frame_rate: float | None) -> object:
    options = {} if frame_rate is None or kind not in FRAME_RATE_PARAM else {
        FRAME_RATE_PARAM[kind]: frame_rate
    }  # fmt: skip
    return create_tracker(TrackerSpec(name=KINDS[kind], options=tuple(options.items())))


def track_once(
    kind: str, sequence: dict[str, object], frames: int, frame_rate: float | None
) -> tuple[list[list[float]], float, str]:
    """One run of a fresh tracker: result rows (file units), seconds in update, fed digest."""
    tracker = make_tracker(kind, frame_rate)
    detections: np.ndarray = sequence["detections"]
    embeddings: np.ndarray = sequence["embeddings"]
    numbers = detections[:, 0].astype(np.int64)
    rows: list[list[float]] = []
    fed: list[np.ndarray] = []
    seconds = 0.0
    for index in range(frames):
        frame_number = index + 1
        picked = np.flatnonzero(numbers == frame_number)
        current = to_detections(detections[picked], embeddings[picked], index)
        fed.append(np.column_stack([detections[picked, 0], detections[picked, 2:6]]))
        image = cv2.imread(str(sequence["frames"][index]), cv2.IMREAD_COLOR)
        if image is None:
            raise ValueError(f"cannot read image {sequence['frames'][index]}")
        start = time.perf_counter()
        tracked = tracker.update(current, image)
        seconds += time.perf_counter() - start
        boxes = tracked.geometry.values.detach().numpy().astype(np.float64)
        ids = tracked.track_ids.detach().numpy()
        scores = tracked.scores.detach().numpy().astype(np.float64)
        for (x1, y1, x2, y2), track_id, score in zip(boxes, ids, scores, strict=True):
            rows.append(
                [frame_number, int(track_id), float(x1), float(y1), float(x2 - x1),
                 float(y2 - y1), float(score)]
            )  # fmt: skip
    if (
        getattr(tracker, "_reid_model", None) is not None
        or getattr(tracker, "_reid_encoder", None) is not None
    ):
        raise RuntimeError(f"{kind} built a ReID backend although it was given the embeddings")
    return rows, seconds, fed_digest(np.concatenate(fed) if fed else np.zeros((0, 5)))


def run_sequence(
    kind: str,
    folder: Path,
    det_file: Path,
    embeddings_file: Path,
    max_frames: int | None,
    repeats: int,
    use_sequence_rate: bool,
) -> dict[str, object]:
    sequence = read_sequence(folder, det_file, embeddings_file)
    frames = len(sequence["frames"])
    if max_frames is not None:
        frames = min(frames, max_frames)
    in_frames = sequence["detections"][:, 0] <= frames
    missing = ~np.isfinite(sequence["embeddings"]).all(axis=1)
    unembedded = int(np.count_nonzero(missing & in_frames))
    dimension = sequence["embeddings"].shape[1]
    sequence["embeddings"][missing] = 1.0 / np.sqrt(dimension)
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
        "unembedded": unembedded,
    }


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("kind", choices=sorted(KINDS))
    parser.add_argument("sequences", nargs="+", type=Path, help="MOTChallenge sequence folders")
    parser.add_argument(
        "--det", type=Path, action="append", required=True, help="detection file, per sequence"
    )
    parser.add_argument(
        "--embeddings",
        type=Path,
        action="append",
        required=True,
        help=".npy embeddings aligned with the detection file's rows, per sequence",
    )
    add_run_arguments(parser, "BoT-SORT's frame_rate: seqinfo.ini's (default) or the library's 30")
    args = parser.parse_args(argv)
    check_run_arguments(parser, args)
    if not len(args.det) == len(args.embeddings) == len(args.sequences):
        parser.error("give one --det and one --embeddings per sequence")
    warnings.simplefilter("ignore", FutureWarning)
    logging.disable(logging.WARNING)  # BoxMOT's per-tracker INFO lines and ECC warnings
    runs = [
        (
            folder.name,
            functools.partial(
                run_sequence,
                args.kind,
                folder,
                det_file,
                embeddings_file,
                args.frames,
                args.repeats,
                args.frame_rate == "sequence",
            ),
        )
        for folder, det_file, embeddings_file in zip(
            args.sequences, args.det, args.embeddings, strict=True
        )
    ]
    errors = (OSError, ValueError, KeyError, RuntimeError, cv2.error)
    results = run_sequences(args.kind, runs, errors, args.repeats)
    with contextlib.redirect_stdout(sys.stderr):
        params = load_tracker_config(KINDS[args.kind], None, None)
    params = {k: v if isinstance(v, str | int | float | bool | type(None)) else repr(v)
              for k, v in params.items()}  # fmt: skip
    if args.kind in FRAME_RATE_PARAM:
        rate = (
            "seqinfo.ini frameRate" if args.frame_rate == "sequence" else params.get("frame_rate")
        )
        params[FRAME_RATE_PARAM[args.kind]] = rate
    versions = {
        name: importlib.metadata.version(name)
        for name in ("boxmot", "torch", "numpy", "scipy", "opencv-python", "lapx")
    }
    tracker_class = type(make_tracker(args.kind, None)).__name__
    json.dump(
        {
            "kind": args.kind,
            "class": tracker_class,
            "versions": versions,
            "params": params,
            "embeddings": "given (the benchmark's re-identification network); NaN rows -> "
            "1/sqrt(D)",
            "sequences": results,
        },
        sys.stdout,
    )
    sys.stdout.write("\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
