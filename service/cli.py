"""The ``vtrack`` command line."""

from __future__ import annotations

import argparse
import dataclasses
import json
import sys
from pathlib import Path

from tqdm import tqdm

from service.frames import FrameSourceError, open_frames
from tracking.correlation import PRESETS, CorrelationTracker
from tracking.types import Box, TrackerOutput


def _parse_box(text: str) -> Box:
    try:
        x, y, w, h = (float(v) for v in text.replace(" ", "").split(","))
    except ValueError:
        raise argparse.ArgumentTypeError(f"a box is x,y,w,h (four numbers), got {text!r}") from None
    return Box(x, y, w, h)


def _first_box_from_groundtruth(folder: Path) -> Box | None:
    """The first line of an OTB ``groundtruth_rect.txt`` (1-based pixels), if there is one."""
    path = folder / "groundtruth_rect.txt"
    if not path.is_file():
        return None
    first = path.read_text().splitlines()[0].replace("\t", ",").replace(" ", ",")
    x, y, w, h = (float(v) for v in first.split(",") if v)
    return Box(x - 1, y - 1, w, h)


def _format_row(index: int, box: Box, out: TrackerOutput | None, fmt: str) -> str:
    """One output row; the first frame (the given box) has no peak or PSR."""
    peak, psr = (out.peak, out.psr) if out is not None else (None, None)
    if fmt == "json":
        record = {"frame": index, "box": [box.x, box.y, box.w, box.h], "peak": peak, "psr": psr}
        return json.dumps(record)
    scores = f"{peak:.4f},{psr:.2f}" if out is not None else ","
    return f"{index},{box.x:.2f},{box.y:.2f},{box.w:.2f},{box.h:.2f},{scores}"


def _track(args: argparse.Namespace) -> int:
    try:
        source = open_frames(args.source)
    except FrameSourceError as error:
        print(f"vtrack: {error}", file=sys.stderr)
        return 2
    box = args.box or (_first_box_from_groundtruth(source.path) if source.path.is_dir() else None)
    if box is None:
        print("vtrack: give the first box with --box x,y,w,h", file=sys.stderr)
        return 2
    config = PRESETS[args.preset]
    if args.w2c:
        config = dataclasses.replace(config, color_names_path=str(args.w2c))
    tracker = CorrelationTracker(config)
    out_file = open(args.out, "w") if args.out else sys.stdout  # noqa: SIM115
    try:
        if args.format == "csv":
            print("frame,x,y,w,h,peak,psr", file=out_file)
        frames = tqdm(source, total=source.frame_count, unit="frame", disable=args.quiet)
        for index, frame in enumerate(frames, start=1):
            if index == 1:
                tracker.initialize(frame, box)
                print(_format_row(index, box, None, args.format), file=out_file)
            else:
                output = tracker.update(frame)
                print(_format_row(index, output.box, output, args.format), file=out_file)
    except ValueError as error:
        print(f"vtrack: {error}", file=sys.stderr)
        return 2
    finally:
        if args.out:
            out_file.close()
    if args.out:
        print(f"vtrack: wrote {index} boxes to {args.out}", file=sys.stderr)
    return 0


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="vtrack", description=__doc__)
    commands = parser.add_subparsers(dest="command", required=True)
    track = commands.add_parser(
        "track",
        help="follow one target through a video or image folder from its first box",
        description="Follow one target with a circulant-structure tracker (RCSK by default).",
    )
    track.add_argument("source", help="video file, image folder, or OTB sequence folder")
    track.add_argument(
        "--box",
        type=_parse_box,
        help="first-frame box x,y,w,h in pixels, 0-based (default: an OTB folder's ground truth)",
    )
    track.add_argument(
        "--preset", default="hog_cn_scale", choices=sorted(PRESETS), help="tracker variant"
    )
    track.add_argument("--w2c", type=Path, help="van de Weijer w2c.mat Color Names table")
    track.add_argument("--out", type=Path, help="write the boxes here instead of stdout")
    track.add_argument("--format", choices=("csv", "json"), default="csv", help="output format")
    track.add_argument("--quiet", action="store_true", help="no progress bar")
    track.set_defaults(handler=_track)
    return parser


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    return args.handler(args)


if __name__ == "__main__":
    sys.exit(main())
