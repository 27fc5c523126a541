"""A MOTChallenge sequence at another frame height: the same scene as a camera of that
resolution shows it (frames, ground truth and public detections resized together).

    python benchmarks/resize_sequence.py SOURCE DESTINATION --height H

Writes ``DESTINATION`` (which must not exist) in the MOTChallenge layout that
``benchmarks/mot.py --sequences`` reads: ``img1/`` (JPEG quality 95, bilinear resizing),
``gt/gt.txt`` and ``det/det.txt`` with their boxes scaled, ``seqinfo.ini`` with the new size.
Boxes scale about the image's top-left corner: a 1-based MOTChallenge ``x`` is the 0-based
left edge plus 1, so ``x' = (x - 1) * s + 1``; widths and heights scale by ``s``. The copy is
derived from third-party data: write it outside the project's tree (e.g. under ``/tmp``).
"""

from __future__ import annotations

import argparse
import configparser
import sys
from pathlib import Path

import cv2
import numpy as np


def resize_rows(path: Path, scale: float) -> str:
    """The rows of a MOTChallenge text file with their boxes (columns 3-6) scaled."""
    lines = []
    for row in np.loadtxt(path, delimiter=",", ndmin=2):
        x, y, w, h = (row[2] - 1) * scale + 1, (row[3] - 1) * scale + 1, *(row[4:6] * scale)
        rest = ",".join(f"{v:g}" for v in row[6:])
        lines.append(f"{int(row[0])},{int(row[1])},{x:.3f},{y:.3f},{w:.3f},{h:.3f},{rest}\n")
    return "".join(lines)


def resize_sequence(source: Path, destination: Path, height: int) -> float:
    """Write the resized copy of ``source``; returns the scale factor."""
    ini = configparser.ConfigParser()
    ini.optionxform = str  # keep MOTChallenge's camelCase keys
    ini.read(source / "seqinfo.ini", encoding="utf-8")  # a missing file reads as empty
    if not ini.has_section("Sequence"):
        ini.add_section("Sequence")
    info = ini["Sequence"]
    frames = sorted((source / info.get("imDir", "img1")).glob(f"*{info.get('imExt', '.jpg')}"))
    if not frames:
        raise SystemExit(f"{source}: no frames")
    first = cv2.imread(str(frames[0]))
    scale = height / first.shape[0]
    width = round(first.shape[1] * scale)
    images = destination / "img1"
    images.mkdir(parents=True)
    for frame in frames:
        image = cv2.imread(str(frame))
        resized = cv2.resize(image, (width, height), interpolation=cv2.INTER_LINEAR)
        cv2.imwrite(str(images / frame.name), resized, [cv2.IMWRITE_JPEG_QUALITY, 95])
    for name in ("gt/gt.txt", "det/det.txt"):
        if (source / name).is_file():
            (destination / name).parent.mkdir()
            (destination / name).write_text(resize_rows(source / name, scale))
    info["imDir"], info["imWidth"], info["imHeight"] = "img1", str(width), str(height)
    with open(destination / "seqinfo.ini", "w", encoding="utf-8") as file:
        ini.write(file)
    return scale


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("source", type=Path, help="a MOTChallenge sequence folder")
    parser.add_argument("destination", type=Path, help="the new folder (must not exist)")
    parser.add_argument("--height", type=int, required=True, help="frame height in pixels")
    args = parser.parse_args(argv)
    if args.height < 16:
        parser.error("--height must be at least 16 pixels")
    if args.destination.exists():
        parser.error(f"{args.destination} exists")
    scale = resize_sequence(args.source, args.destination, args.height)
    print(f"{args.destination}: {args.source.name} resized by {scale:.4g}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
