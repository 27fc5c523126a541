"""Run an OpenCV tracker (KCF, CSRT or MIL) over OTB sequences and print the results as JSON.

A standalone script for the peer environment (``opencv-contrib-python-headless``, see
``benchmarks/_peer_env.py``): it imports nothing from the project. ``benchmarks/otb.py`` runs it
in a subprocess:

    .venv-peers/bin/python benchmarks/peers/opencv_trackers.py KIND SEQUENCE_DIR [...]

Per sequence it reads the frames itself (``cv2.imread``, BGR as OpenCV's trackers expect),
initialises on the first ground-truth box converted to 0-based integer pixels (OpenCV takes an
integer ``Rect``), calls ``update`` on every later frame and times only the ``init`` and
``update`` calls with ``time.perf_counter``. A failed update (``ok`` False: KCF's peak fell below
``detect_thresh``, CSRT's PSR below ``psr_threshold``) keeps the previous box, as a tracker's
user would; those frames are listed in ``failed_frames``. KCF keeps searching around its last
position on the next frame.

Tracker kinds. ``desc_npca`` and ``desc_pca`` are bitmasks of ``TrackerKCF_GRAY`` (1) and
``TrackerKCF_CN`` (2): the descriptors used as they are, and those compressed by KCF's adaptive
PCA to ``compressed_size`` dimensions (Danelljan et al., CVPR 2014; thesis ch. 4). Two OpenCV
bugs constrain the choice (checked on 4.14.0):

- if either set is empty, the second successful ``update`` raises "Matrix operand is an empty
  matrix" (it blends the empty model of that set; opencv/opencv#22203), so grey alone or CN alone
  cannot be configured directly;
- grey in the compressed set needs ``compressed_size = 1`` (OpenCV asserts
  ``compressed_size <= channels``).

So grey-only KCF puts grey in both sets with ``compressed_size = 1``: the compressed copy is the
grey patch times +-1 (a 1x1 projection), and the Gaussian kernel of KCF, which averages the
squared distance over all channels, is then exactly that of grey alone (at twice the cost).

- ``kcf_gray``: KCF on grey pixels: ``desc_npca = GRAY``, ``desc_pca = GRAY``,
  ``compressed_size = 1``.
- ``kcf_cn``: OpenCV's default KCF: grey as it is plus Color Names compressed to 2 dimensions
  (``desc_npca = GRAY``, ``desc_pca = CN``, ``compressed_size = 2``), the "CN2" tracker of
  Danelljan et al. CVPR 2014. CN without grey cannot be configured (first bug).
- ``kcf_cn_full``: grey plus all 10 of OpenCV's Color Names channels, none compressed
  (``desc_npca = CN``, ``desc_pca = GRAY``, ``compressed_size = 1``).
- ``csrt``: CSRT (Lukezic et al., CVPR 2017).
- ``<kind>_nothresh``: the same with the failure threshold at -inf (KCF's ``detect_thresh``,
  CSRT's ``psr_threshold``), so ``update`` never reports a failure. After a failed update
  neither tracker moves nor trains its model, and with the default KCF threshold (0.5) the
  response peak of OpenCV's KCF soon stays below it on OTB sequences: KCF then freezes for the
  rest of the sequence. These kinds show what the filters themselves do.
- ``mil``: MIL, online multiple-instance boosting (Babenko et al., CVPR 2009), with OpenCV's
  default ``TrackerMIL_Params``. It has no failure threshold, hence no ``_nothresh`` twin.

Every parameter not named here keeps OpenCV's default.

Output (stdout): one JSON object ``{"kind", "opencv", "threads", "params", "sequences": [...]}``;
each sequence is ``{"name", "boxes": [[x, y, w, h], ...], "seconds": [...], "failed_frames"}``
with 0-based boxes, or ``{"name", "error"}`` if the tracker could not run on it.
"""

from __future__ import annotations

import argparse
import json
import math
import re
import sys
import time
from pathlib import Path

import cv2

IMAGE_SUFFIXES = {".jpg", ".jpeg", ".png", ".bmp"}
KCF_DESCRIPTORS = {
    # kind: (desc_npca, desc_pca, compressed_size)
    "kcf_gray": (cv2.TrackerKCF_GRAY, cv2.TrackerKCF_GRAY, 1),
    "kcf_cn": (cv2.TrackerKCF_GRAY, cv2.TrackerKCF_CN, 2),
    "kcf_cn_full": (cv2.TrackerKCF_CN, cv2.TrackerKCF_GRAY, 1),
}
NO_THRESHOLD = "_nothresh"
KINDS = (
    *KCF_DESCRIPTORS,
    "csrt",
    *(k + NO_THRESHOLD for k in (*KCF_DESCRIPTORS, "csrt")),
    "mil",
)


def create_tracker(kind: str) -> tuple[cv2.Tracker, dict[str, object]]:
    """A fresh tracker of ``kind`` and the parameters it was given (for the record)."""
    base = kind.removesuffix(NO_THRESHOLD)
    if base == "csrt":
        params = cv2.TrackerCSRT_Params()
        if kind.endswith(NO_THRESHOLD):
            params.psr_threshold = float("-inf")
        tracker = cv2.TrackerCSRT.create(params)
    elif base in KCF_DESCRIPTORS:
        params = cv2.TrackerKCF_Params()
        params.desc_npca, params.desc_pca, params.compressed_size = KCF_DESCRIPTORS[base]
        if kind.endswith(NO_THRESHOLD):
            params.detect_thresh = float("-inf")
        tracker = cv2.TrackerKCF.create(params)
    elif kind == "mil":
        params = cv2.TrackerMIL_Params()
        tracker = cv2.TrackerMIL.create(params)
    else:
        raise ValueError(f"unknown tracker kind {kind!r}; expected one of {', '.join(KINDS)}")
    record = {name: getattr(params, name) for name in dir(params) if not name.startswith("_")}
    # strict JSON has no infinity: write non-finite numbers as strings
    record = {
        k: str(v) if isinstance(v, float) and not math.isfinite(v) else v for k, v in record.items()
    }
    return tracker, record


def read_sequence(folder: Path, start_fraction: float = 0.0) -> tuple[str, list[Path], list[float]]:
    """The segment from frame ``int(start_fraction * N)`` on: its name (``Name@frame`` when it
    does not start at frame 1), its frame paths and its first box, 1-based."""
    lines = (folder / "groundtruth_rect.txt").read_text().rstrip().splitlines()
    start = int(start_fraction * len(lines))
    first = [float(v) for v in re.split(r"[,\s]+", lines[start].strip()) if v]
    if len(first) != 4:
        raise ValueError(f"{folder}/groundtruth_rect.txt, line {start + 1}: expected x,y,w,h")
    frames = sorted(p for p in (folder / "img").iterdir() if p.suffix.lower() in IMAGE_SUFFIXES)
    if len(frames) < len(lines):
        raise ValueError(f"{folder}: {len(lines)} ground-truth rows but {len(frames)} images")
    name = folder.name if start == 0 else f"{folder.name}@{start + 1}"
    return name, frames[start : len(lines)], first


def read_bgr(path: Path, scale: float = 1.0) -> cv2.typing.MatLike:
    """A frame, resized by ``scale`` as the benchmark's ``--scale`` resizes it for our trackers."""
    image = cv2.imread(str(path), cv2.IMREAD_COLOR)
    if image is None:
        raise ValueError(f"cannot read image {path}")
    if scale != 1.0:
        image = cv2.resize(image, None, fx=scale, fy=scale, interpolation=cv2.INTER_AREA)
    return image


def run_sequence(
    kind: str, folder: Path, start_fraction: float = 0.0, scale: float = 1.0
) -> dict[str, object]:
    name, frames, (x1, y1, w, h) = read_sequence(folder, start_fraction)
    # 1-based (x, y) -> 0-based, scaled; OpenCV wants integers
    x, y, w, h = ((x1 - 1.0) * scale, (y1 - 1.0) * scale, w * scale, h * scale)
    box = (round(x), round(y), max(1, round(w)), max(1, round(h)))
    tracker, _ = create_tracker(kind)
    boxes = [list(box)]
    image = read_bgr(frames[0], scale)
    start = time.perf_counter()
    tracker.init(image, box)
    seconds = [time.perf_counter() - start]
    failed = []
    for index, path in enumerate(frames[1:], start=1):
        image = read_bgr(path, scale)
        start = time.perf_counter()
        ok, found = tracker.update(image)
        seconds.append(time.perf_counter() - start)
        if ok:
            box = tuple(int(v) for v in found)
        else:
            failed.append(index)  # keep the previous box
        boxes.append(list(box))
    return {"name": name, "boxes": boxes, "seconds": seconds, "failed_frames": failed}


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("kind", choices=KINDS)
    parser.add_argument("sequences", nargs="+", type=Path, help="OTB sequence folders")
    parser.add_argument(
        "--threads", type=int, default=None, help="cv2.setNumThreads (default: OpenCV's own)"
    )
    parser.add_argument(
        "--start-fraction",
        type=float,
        default=0.0,
        help="start each sequence at frame int(F * N) with that frame's box (default 0)",
    )
    parser.add_argument(
        "--scale", type=float, default=1.0, help="resize frames and boxes by this (default 1)"
    )
    args = parser.parse_args(argv)
    if args.threads is not None:
        cv2.setNumThreads(args.threads)
    _, params = create_tracker(args.kind)
    results = []
    for folder in args.sequences:
        try:
            result = run_sequence(args.kind, folder, args.start_fraction, args.scale)
        except (OSError, ValueError, cv2.error) as exc:
            result = {"name": folder.name, "error": f"{type(exc).__name__}: {exc}"}
            print(f"{args.kind} {folder.name}: {result['error']}", file=sys.stderr)
        else:
            fps = len(result["seconds"]) / max(sum(result["seconds"]), 1e-12)
            print(
                f"{args.kind} {result['name']}: {len(result['boxes'])} frames, {fps:.0f} fps, "
                f"{len(result['failed_frames'])} failed updates",
                file=sys.stderr,
            )
        results.append(result)
    json.dump(
        {
            "kind": args.kind,
            "opencv": cv2.__version__,
            "threads": cv2.getNumThreads(),
            "params": params,
            "sequences": results,
        },
        sys.stdout,
    )
    sys.stdout.write("\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
