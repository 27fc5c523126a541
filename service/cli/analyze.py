"""``vtrack analyze``: the service's pipeline on one video or image folder, without a server."""

from __future__ import annotations

import argparse
import copy
import fcntl
import json
import math
import os
import shutil
import sys
from pathlib import Path
from typing import TYPE_CHECKING

from service.argument_types import number_type
from service.cli.common import (
    QUIET_HELP,
    W2C_HELP,
    NetworkFiles,
    add_fps_argument,
    add_range_arguments,
    color_names_file,
    dpm_model_file,
    network_files,
    open_source,
    parse_box,
    progress_bar,
    stopped,
    warn_unknown_variables,
    warn_unused_table,
)
from service.frames import FrameSource
from tracking.correlation import DEFAULT_PRESET, PRESETS
from tracking.output_paths import output_folder
from tracking.types import Box, box_problem

if TYPE_CHECKING:
    from api_schemas.jobs import JobOptions
    from tracking.detection.base import Detections
    from tracking.detection.external import MotDetections


def add_command(commands: argparse._SubParsersAction) -> None:
    """The ``analyze`` command and its arguments."""
    analyze = commands.add_parser(
        "analyze",
        help="track every person in a video and write the results (no server)",
        description="The service's pipeline on one video file or image folder, with a "
        "progress bar: every person in view (or, with --box, one object), written as JSON, "
        "MCAP, MOT text and an annotated MP4.",
    )
    analyze.add_argument("source", help="video file or image folder (MOTChallenge img1/ too)")
    analyze.add_argument(
        "-o", "--out-dir", type=Path, required=True, metavar="DIR", help="folder for the results"
    )
    analyze.add_argument(
        "--format",
        type=_formats,
        help="comma-separated results to write: json,mcap,mot,mp4 (default: all)",
    )
    analyze.add_argument(
        "--mcap-images",
        choices=("h264", "jpeg"),
        help="frames in the MCAP as H.264 video (default) or JPEG images (for tools that read "
        "foxglove.CompressedImage only)",
    )
    analyze.add_argument(
        "--dpm-model",
        type=Path,
        help="detect with this voc-release5 model (.mat) instead (VTRACK_DPM_MODEL gives the "
        "model for a detector 'dpm' of --options)",
    )
    analyze.add_argument(
        "--cnn-model",
        type=Path,
        help="detect with this CNN network (an OpenVINO .xml or an .onnx file); by default the "
        "CNN of VTRACK_CNN_MODEL or VTRACK_MODELS_DIR runs when there is one (`vtrack models "
        "fetch`), else the embedded detector",
    )
    analyze.add_argument(
        "--pose-model",
        type=Path,
        metavar="PATH",
        help="measure every person's 18 body keypoints with this pose network (an OpenVINO "
        ".xml or an .onnx file; the parts are then the keypoints); by default the network of "
        "VTRACK_POSE_MODEL or VTRACK_MODELS_DIR (human-pose-estimation-0001) runs when there "
        "is one, else none (about 40 ms per 768x576 frame on 2 cores; --options "
        '\'{"tracker": {"pose": false}}\' turns it off)',
    )
    analyze.add_argument(
        "--reid-model",
        type=Path,
        metavar="PATH",
        help="tell people apart and recognise those who come back by appearance embeddings "
        "of this re-identification network (an OpenVINO .xml or an .onnx file); by default "
        "the network of VTRACK_REID_MODEL or VTRACK_MODELS_DIR "
        "(person-reidentification-retail-0287) runs when there is one, else none (about 2 ms "
        'per person on 2 cores; --options \'{"tracker": {"reid": false}}\' turns it '
        "off)",
    )
    analyze.add_argument(
        "--upscale",
        type=number_type(float, -math.inf),  # the job options' bounds: their message
        help="enlarge frames before detecting; default by the frame height (a portrait "
        "frame's width): embedded detector 2.0 at 360 px (finds people 40-55 px tall), 1.5 "
        "at 480-720, 1.0 at 1080, 0.5 at 2160; DPM 1.0 up to 1080 px, 0.5 at 2160",
    )
    analyze.add_argument(
        "--detection-interval",
        type=float,
        help="seconds between full-frame detections, regions around the tracks in between "
        "(default 0: every frame in full; 0.2 tracked 25 fps video 1.3-2.6x as fast in our "
        "benchmarks)",
    )
    analyze.add_argument(
        "--detections",
        type=Path,
        metavar="FILE",
        help="track the people of this MOTChallenge det.txt (public detections; rows by the "
        "video's frame numbers, from 1) instead of detecting them",
    )
    analyze.add_argument(
        "--detections-scale",
        type=number_type(float, 0, above=True),
        metavar="S",
        help="multiply the boxes of --detections by this (default 1; e.g. 0.625: PETS 768x576 "
        "boxes on the 480x360 video)",
    )
    analyze.add_argument("--frame-step", type=int, help="track every N-th frame (default 1)")
    add_range_arguments(
        analyze, "results keep the video's times and frame numbers, the MP4 starts at 0"
    )
    add_fps_argument(analyze)
    analyze.add_argument(
        "--fill-gaps",
        type=float,
        metavar="SECONDS",
        help="fill a person's frames in the json and mot results when the tracker loses them "
        "for at most this long and finds them again (linear in time, marked interpolated; "
        "default 0: off)",
    )
    analyze.add_argument(
        "--box",
        type=parse_box,
        metavar="X,Y,W,H",
        help="follow one object from this first box instead",
    )
    analyze.add_argument(
        "--preset", choices=sorted(PRESETS), help=f"tracker for --box (default {DEFAULT_PRESET})"
    )
    analyze.add_argument(
        "--options",
        type=_job_options,
        help="job options as JSON, the service's `options` part (for example "
        '\'{"tracker": {"report_missing": 0.15}}\'); the flags above win over it',
    )
    analyze.add_argument("--w2c", type=Path, metavar="FILE", help=W2C_HELP)
    analyze.add_argument("-q", "--quiet", action="store_true", help=QUIET_HELP)
    analyze.set_defaults(handler=_analyze)


def _formats(text: str) -> list[str]:
    from api_schemas.jobs import OutputFormat

    names = [name.strip() for name in text.split(",") if name.strip()]
    known = [f.value for f in OutputFormat]
    unknown = [name for name in names if name not in known]
    if unknown or not names:
        raise argparse.ArgumentTypeError(
            f"formats are a comma-separated list of {','.join(known)}, got {text!r}"
        )
    return list(dict.fromkeys(names))


def _job_options(text: str) -> dict:
    """``--options``: a JSON object of job options, as the service's ``options`` part."""
    try:
        value = json.loads(text)
    except json.JSONDecodeError as error:
        raise argparse.ArgumentTypeError(f"not JSON: {error}") from None
    if not isinstance(value, dict):
        raise argparse.ArgumentTypeError(f"a JSON object of job options, got {text!r}")
    return value


def _analyze_options(args: argparse.Namespace) -> tuple[dict, dict[tuple[str, ...], str]]:
    """The job options of ``args``: ``--options`` with the other flags given over it, and the
    flag behind each field those flags set (to name it in errors)."""
    box = args.box
    flags = {
        ("formats",): ("--format", args.format),
        ("mcap_images",): ("--mcap-images", args.mcap_images),
        ("frame_step",): ("--frame-step", args.frame_step),
        ("fill_gaps",): ("--fill-gaps", args.fill_gaps),
        ("start",): ("--start", args.start),
        ("end",): ("--end", args.end),
        ("mode",): ("--box", None if box is None else "single_target"),
        ("first_box",): (
            "--box",
            None if box is None else {"x": box.x, "y": box.y, "w": box.w, "h": box.h},
        ),
        ("preset",): ("--preset", args.preset),
        ("detector", "name"): ("--dpm-model", "dpm" if args.dpm_model else None)
        if args.cnn_model is None
        else ("--cnn-model", "cnn"),
        ("detector", "upscale"): ("--upscale", args.upscale),
        ("tracker", "pose"): ("--pose-model", True if args.pose_model is not None else None),
        ("tracker", "reid"): ("--reid-model", True if args.reid_model is not None else None),
        ("tracker", "full_detection_interval"): ("--detection-interval", args.detection_interval),
    }
    raw = copy.deepcopy(args.options or {})
    given = {}
    for key, (flag, value) in flags.items():
        if value is None:
            continue
        given[key] = flag
        *parents, name = key
        section = raw
        for parent in parents:
            if not isinstance(section.get(parent), dict):
                section[parent] = {}
            section = section[parent]
        section[name] = value
    return raw, given


def _detections_conflict(args: argparse.Namespace, options: JobOptions) -> str | None:
    """Why ``--detections`` or ``--detections-scale`` cannot go with the other arguments (an
    option that would do nothing is refused, not ignored); ``None`` when they can."""
    from api_schemas.jobs import DetectorOptions

    if args.detections is None:
        if args.detections_scale is not None:
            return "--detections-scale scales the boxes of --detections, which is not given"
        return None
    if options.mode == "single_target":
        return "--detections gives people to track, not with --box"
    flags = {
        "--dpm-model": args.dpm_model,
        "--cnn-model": args.cnn_model,
        "--upscale": args.upscale,
    }
    idle = [flag for flag, value in flags.items() if value is not None]
    if args.detection_interval is not None:
        idle.append("--detection-interval")
    elif options.tracker.full_detection_interval:
        idle.append("--options: tracker.full_detection_interval")
    explicit = (args.dpm_model, args.cnn_model, args.upscale)
    if all(v is None for v in explicit) and options.detector != DetectorOptions():
        idle.append("--options: detector")
    if idle:
        return f"--detections replaces the detector: {', '.join(idle)} would do nothing beside it"
    return None


class _PublicDetections:
    """The detections of ``--detections`` by frame index, scaled by ``--detections-scale``;
    counts the frames asked for that had rows, so a file for another video is noticed."""

    def __init__(self, table: MotDetections, scale: float) -> None:
        self.table, self.scale = table, scale
        self.frames_with_rows = 0

    def __call__(self, index: int) -> Detections:
        found = self.table.for_frame(index)
        self.frames_with_rows += bool(len(found))
        return found if self.scale == 1.0 else found.scaled(self.scale)

    def warnings(self, path: Path, frames: int) -> list[str]:
        """Sentences on what the file could not give as it stands: rows without a size,
        confidences that are not probabilities, no row for any of the ``frames`` tracked."""
        rows, said = self.table.rows, []
        if self.table.dropped:
            said.append(
                f"--detections: {path} has rows without a width or height "
                f"({self.table.dropped}); they were left out"
            )
        low, high = (rows[:, 6].min(), rows[:, 6].max()) if len(rows) else (0.0, 1.0)
        if low < 0 or high > 1:
            said.append(
                f"--detections: the confidences of {path} run from {low:g} to {high:g}; taken "
                "as probabilities they are clipped to 0-1 (every one below 0 counts as "
                "impossible, every one above 1 as certain): rescale them to 0-1 to keep their "
                "order"
            )
        if self.frames_with_rows or not frames:
            return said
        if not len(rows):
            return [*said, f"--detections: {path} has no rows: nobody was tracked"]
        first, last = rows[:, 0].min(), rows[:, 0].max()
        return [
            *said,
            f"--detections: no row of {path} is for the {frames} frames tracked (its rows are "
            f"for frames {first:.0f}-{last:.0f}, counted from 1): nobody was tracked; are they "
            "another video's detections?",
        ]


def _public_detections(args: argparse.Namespace, source: FrameSource) -> _PublicDetections | None:
    """The detections of ``--detections`` (``None`` without it).

    Raises
    ------
    ValueError
        The file is not a MOTChallenge ``det.txt`` (the line), or its boxes reach far beyond
        the frames (made on larger ones: ``--detections-scale`` is missing).
    """
    from tracking.detection.external import MotDetections

    if args.detections is None:
        return None
    try:
        table = MotDetections.from_file(args.detections)
    except (OSError, ValueError) as error:  # MotFormatError names the line
        raise ValueError(f"--detections: {error}") from None
    scale = args.detections_scale or 1.0
    if len(table.rows):
        right, bottom = (table.rows[:, 2:4] + table.rows[:, 4:6]).max(axis=0) * scale
        if right > 1.25 * source.width or bottom > 1.25 * source.height:
            raise ValueError(
                f"--detections: boxes reach x={right:.0f}, y={bottom:.0f}, far beyond the "
                f"{source.width}x{source.height} frames: made on larger frames? give "
                "--detections-scale, the frames' width over that of the frames they were made on"
            )
    return _PublicDetections(table, scale)


def _tracked_with(options: JobOptions, dpm_model: Path | None, detections: Path | None) -> str:
    """What found and followed the tracks, for the closing line: the detector in particular,
    since a DPM set in VTRACK_DPM_MODEL is used only when the options ask for it, and the pose
    and re-identification networks that ran (the models folder's run unless told not to)."""
    if options.mode == "single_target":
        return f"the {options.preset} tracker"
    if detections is not None:
        found = f"the detections of {detections}"
    elif options.detector.name == "dpm" and dpm_model is not None:
        found = f"the DPM {dpm_model.name}"
    elif options.detector.name == "cnn":
        found = f"the CNN detector {options.detector.model}"
    else:
        found = "the embedded detector (OpenCV's HOG people detector)"
    tracker = options.tracker
    networks = [
        f"the pose network {tracker.pose_model}" if tracker.pose else "",
        f"the re-identification network {tracker.reid_model}" if tracker.reid else "",
    ]
    named = [found, *filter(None, networks)]
    return named[0] if len(named) == 1 else f"{', '.join(named[:-1])} and {named[-1]}"


def _lock_out_dir(folder: Path) -> None:
    """Hold an exclusive lock on ``folder`` until the process ends: two runs into one folder
    would move each other's files away and both fail, leaving a mix of their results.

    Raises
    ------
    OSError
        Another process holds the lock.
    """
    descriptor = os.open(folder, os.O_RDONLY)  # kept open: the lock lasts as long as it
    try:
        fcntl.flock(descriptor, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except BlockingIOError:
        os.close(descriptor)
        raise BlockingIOError(
            f"another vtrack analyze is writing into {folder}: wait for it to end or give "
            "another --out-dir"
        ) from None


def _analyze(args: argparse.Namespace) -> int:
    from pydantic import ValidationError

    from api_schemas.common import error_message
    from api_schemas.jobs import JobOptions

    warn_unknown_variables()
    raw, given = _analyze_options(args)
    try:
        options = JobOptions.model_validate(raw)
    except ValidationError as error:
        first = error.errors()[0]
        loc = tuple(str(part) for part in first["loc"])
        # the flag that set the refused field, or set a field inside it (--upscale: detector)
        where = [
            flag
            for key, flag in given.items()
            if loc and (key[: len(loc)] == loc or loc[: len(key)] == key)
        ][:1]
        message = error_message(first)
        if where:  # the options' modes, as this command's flags choose them
            message = (
                message.replace("mode 'single_target'", "--box")
                .replace("mode 'people'", "tracking people (without --box)")
                .replace("which formats leaves out", "which --format leaves out")
            )
        elif loc:
            where = [f"--options: {'.'.join(loc)}"]
        print(f"vtrack: {': '.join([*where, message])}", file=sys.stderr)
        return 2
    if problem := _detections_conflict(args, options):
        print(f"vtrack: {problem}", file=sys.stderr)
        return 2
    # the trackers and detectors (most of the command's imports) once the options are good
    from service.analysis import analyze, publish
    from service.outputs.base import ANALYTICS_FILE
    from service.pipelines import PipelineResources, check_options

    try:
        # VTRACK_DPM_MODEL is read only for a run that detects with it; --dpm-model always
        needs_dpm = options.mode == "people" and options.detector.name == "dpm"
        dpm_model = dpm_model_file(args.dpm_model) if needs_dpm or args.dpm_model else None
        if needs_dpm and dpm_model is None:
            raise ValueError(
                "detector 'dpm' needs a voc-release5 model: give --dpm-model MODEL.mat or set "
                "VTRACK_DPM_MODEL"
            )
        networks = NetworkFiles(None, None, None, None)  # a single target runs none
        if options.mode == "people":
            networks = network_files(args.cnn_model, args.pose_model, args.reid_model)
        resources = PipelineResources(
            dpm_model=dpm_model,
            color_names=color_names_file(args.w2c),
            models_dir=networks.models_dir,
            cnn_model=networks.cnn,
            pose_model=networks.pose,
            reid_model=networks.reid,
        )
        if options.mode == "single_target" and options.preset is not None:  # always set then
            warn_unused_table(args.w2c, options.preset)
        source = open_source(args)
        detections = _public_detections(args, source)
        if options.mode == "single_target" and options.first_box is not None:
            b = options.first_box
            if problem := box_problem(Box(b.x, b.y, b.w, b.h), (source.height, source.width)):
                raise ValueError(f"{given.get(('first_box',), '--options: first_box')} {problem}")
        # before the bar
        plan = check_options(options, resources, source, detect=detections is None)
        created = not args.out_dir.exists()
        output_folder(args.out_dir)  # before the work, not after it
        _lock_out_dir(args.out_dir)
    except (OSError, ValueError) as error:  # FrameSourceError is a ValueError
        print(f"vtrack: {error}", file=sys.stderr)
        return 2
    bar = progress_bar(source.frames_until(options.end), args.quiet)
    frames_read = 0

    def progress(read: int, frames_processed: int, fps: float | None) -> bool:
        nonlocal frames_read
        frames_read = read
        bar.update(read - bar.n)
        return True

    scratch = args.out_dir / ".vtrack-partial"
    try:
        result = analyze(
            source,
            plan,
            scratch,
            filename=Path(args.source).name,
            progress=progress,
            progress_interval=0.2,
            detections=detections,
        )
        files = publish(result, args.out_dir)
        scratch.rmdir()
    except (ValueError, OSError, KeyboardInterrupt) as error:  # OSError: disk full
        bar.close()
        # the files of an unfinished run are no result: none is left behind
        shutil.rmtree(scratch, ignore_errors=True)
        if created and args.out_dir.is_dir() and not any(args.out_dir.iterdir()):
            args.out_dir.rmdir()
        if isinstance(error, KeyboardInterrupt):
            what, status = stopped(error)
            print(f"vtrack: {what} after {frames_read} frames; nothing written", file=sys.stderr)
            return status
        message = str(error)
        if isinstance(error, OSError) and error.filename is None and error.strerror:
            message = f"cannot write the results into {args.out_dir}: {error.strerror}"  # disk full
        print(f"vtrack: {message}", file=sys.stderr)  # OptionsError is a ValueError
        return 2
    bar.update(result.video.frames_read - bar.n)
    bar.close()
    warnings = list(result.warnings)
    if detections is not None:
        warnings += detections.warnings(args.detections, result.frames_processed)
    for warning in warnings:
        print(f"vtrack: warning: {warning}", file=sys.stderr)
    if not args.quiet:
        rate = result.frames_processed / max(result.seconds, 1e-9)
        tracked_with = _tracked_with(result.options, dpm_model, args.detections)
        print(
            f"vtrack: tracked {result.frames_processed} frames in {result.seconds:.1f} s "
            f"({rate:.1f} frames/s) with {tracked_with}",
            file=sys.stderr,
        )
    for fmt, path in files.items():
        print(f"{fmt.value}\t{path}")
    if result.analytics_file is not None:  # the events and counts of the zones and lines
        print(f"analytics\t{args.out_dir / ANALYTICS_FILE}")
    return 0
