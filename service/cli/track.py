"""``vtrack track``: one target followed through a video or image folder from its first box.

The frames are read as a job's are (:meth:`~service.frames.FrameSource.timed`) and tracked by
the same :class:`~tracking.pipeline.SingleTargetPipeline`; the boxes go out as CSV rows or JSON
lines (:class:`~service.outputs.box_rows.BoxRowWriter`).
"""

from __future__ import annotations

import argparse
import os
import sys
from pathlib import Path
from typing import Literal

from api_schemas.common import FirstBox
from api_schemas.jobs import JobOptions
from service.cli.common import (
    QUIET_HELP,
    W2C_HELP,
    add_fps_argument,
    add_range_arguments,
    color_names_file,
    open_source,
    parse_box,
    progress_bar,
    stopped,
    warn_unknown_variables,
    warn_unused_table,
)
from service.frames import FrameSource, ReadProgress, frame_size_problem, is_greyscale
from service.outputs.box_rows import BoxRowWriter
from service.pipelines import PipelineResources, build_pipeline, check_options
from tracking.correlation import DEFAULT_PRESET, PRESETS
from tracking.output_paths import output_file, staged_output
from tracking.pipeline import SingleTargetPipeline
from tracking.types import Box, box_problem


def add_command(commands: argparse._SubParsersAction) -> None:
    """The ``track`` command and its arguments."""
    track = commands.add_parser(
        "track",
        help="follow one target through a video or image folder from its first box",
        description=f"Follow one target with a correlation-filter tracker (preset {DEFAULT_PRESET} "
        "by default: STRCF on grey, HOG and Color Names, with scale adaptation; it reports "
        "the frames where the target looks hidden or lost).",
    )
    track.add_argument("source", help="video file, image folder, or OTB sequence folder")
    track.add_argument(
        "--box",
        type=parse_box,
        metavar="X,Y,W,H",
        help="first-frame box x,y,w,h in pixels, 0-based (default: an OTB folder's ground truth)",
    )
    track.add_argument(
        "--preset",
        default=DEFAULT_PRESET,
        choices=sorted(PRESETS),
        help=f"tracker variant (default {DEFAULT_PRESET})",
    )
    track.add_argument("--w2c", type=Path, metavar="FILE", help=W2C_HELP)
    track.add_argument(
        "-o", "--out", type=Path, metavar="FILE", help="write the boxes here instead of stdout"
    )
    track.add_argument(
        "--format",
        choices=("csv", "json"),
        help="csv rows or JSON lines (default: json for a --out FILE ending .json or .jsonl, "
        "csv otherwise)",
    )
    add_range_arguments(track, "the first box is drawn on the first frame at or after it")
    add_fps_argument(track)
    track.add_argument("-q", "--quiet", action="store_true", help=QUIET_HELP)
    track.set_defaults(handler=_track)


def _track(args: argparse.Namespace) -> int:
    warn_unknown_variables()
    start = args.start or 0.0
    if args.end is not None and args.end <= start:
        print(
            f"vtrack: --end ({args.end:g} s) must come after --start ({start:g} s)", file=sys.stderr
        )
        return 2
    try:
        source = open_source(args)
        if problem := frame_size_problem(source.width, source.height):
            raise ValueError(problem)  # as uploads and streams are refused
        if source.path.is_dir() and source.fps is None and (start > 0 or args.end is not None):
            print(
                "vtrack: warning: the image folder states no frame rate (no seqinfo.ini "
                f"frameRate): --start and --end count {source.timing_fps:g} frames per second; "
                "give its rate with --fps",
                file=sys.stderr,
            )
        if problem := source.start_problem(start, "--start"):
            raise ValueError(problem)
        box = args.box or _truth_box(source, start)
    except ValueError as error:  # FrameSourceError and SequenceError are ValueErrors
        print(f"vtrack: {error}", file=sys.stderr)
        return 2
    # before any output: a bad box is a usage error, not a run that stops at its first frame
    if problem := box_problem(box, (source.height, source.width)):
        first = source.image_range(start).start + 1
        where = "--box" if args.box else f"the ground truth's box of frame {first}"
        print(f"vtrack: {where} {problem}", file=sys.stderr)
        return 2
    warn_unused_table(args.w2c, args.preset)
    # a file named .json gets JSON lines unless --format says otherwise
    json_name = args.out is not None and args.out.suffix.lower() in (".json", ".jsonl")
    fmt: Literal["csv", "json"] = args.format or ("json" if json_name else "csv")
    try:
        # the preset and the Color Names table as a job's options are planned
        first_box = FirstBox(x=box.x, y=box.y, w=box.w, h=box.h)
        options = JobOptions(mode="single_target", preset=args.preset, first_box=first_box)
        plan = check_options(options, PipelineResources(color_names=color_names_file(args.w2c)))
        pipeline = build_pipeline(plan)
        assert isinstance(pipeline, SingleTargetPipeline)  # a single target's plan
        target, partial = staged_output(output_file(args.out)) if args.out else (None, None)
        out_file = open(partial or target, "w") if target else sys.stdout  # noqa: SIM115
    except (ValueError, OSError) as error:
        print(f"vtrack: {error}", file=sys.stderr)
        return 2
    read, writer, greyscale = ReadProgress(), BoxRowWriter(out_file, fmt), False
    bar = progress_bar(source.frames_until(args.end), args.quiet)

    def advance() -> None:
        bar.update(read.frames - bar.n)

    read.on_read = advance
    try:
        for frame in source.timed(1, read, start, args.end):
            if writer.rows == 0:
                greyscale = is_greyscale(frame.image)
            tracks = pipeline.process(frame.image, frame.timestamp)
            # the video's own frame number: damaged frames leave their gap
            writer.write(frame.index + 1, tracks, pipeline.last_output)
        if writer.rows == 0:
            raise ValueError(
                f"no frame lies between --start {start:g} s and --end {args.end:g} s"
                if read.reached_end
                else f"no frame is at or after --start {start:g} s: the last is at "
                f"{read.end_time:.2f} s"
            )
        bar.close()
        if partial and target:
            out_file.close()
            os.replace(partial, target)
    except ValueError as error:
        bar.close()
        print(f"vtrack: {error}", file=sys.stderr)
        return 2
    except KeyboardInterrupt as error:
        bar.close()
        verb = "printed" if target is None else "written"
        kept = "nothing written" if partial else f"the {writer.rows} rows {verb} are complete"
        what, status = stopped(error)
        print(f"vtrack: {what} after {writer.rows} frames; {kept}", file=sys.stderr)
        return status
    finally:
        if target:
            out_file.close()
        if partial:
            partial.unlink(missing_ok=True)  # gone already when the run completed
    # as `vtrack analyze` judges them
    from service.analysis import damage_warnings, greyscale_warning

    warnings = [*source.notes, *damage_warnings(source, read)]
    if greyscale and (lost := greyscale_warning("single_target", args.preset)):
        warnings.append(lost)
    for warning in warnings:
        print(f"vtrack: warning: {warning}", file=sys.stderr)
    if args.out and not args.quiet:
        print(f"vtrack: wrote {writer.rows} boxes to {args.out}", file=sys.stderr)
    return 0


def _truth_box(source: FrameSource, start: float) -> Box:
    """The box of an OTB folder's ground truth on the first frame at ``start`` seconds.

    Raises
    ------
    ValueError
        The folder has no ground truth, or none for that frame, or it is not OTB's.
    """
    from tracking.datasets.otb import parse_ground_truth

    path = source.path / "groundtruth_rect.txt"
    if not source.path.is_dir() or not path.is_file():
        raise ValueError("give the first box with --box x,y,w,h")
    truth = parse_ground_truth(path.read_text(), str(path))
    index = source.image_range(start).start
    if index >= len(truth):
        raise ValueError(f"{path} has no box for frame {index + 1}: give the first box with --box")
    return Box(*(float(v) for v in truth[index]))
