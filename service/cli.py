"""The ``vtrack`` command line: ``track`` one target, ``analyze`` a video, ``serve`` the API,
``publish`` a video as a Zenoh camera and ``subscribe`` to its tracks."""

from __future__ import annotations

import argparse
import codecs
import contextlib
import copy
import dataclasses
import errno
import fcntl
import io
import json
import math
import os
import re
import shutil
import signal
import socket
import sys
from pathlib import Path
from typing import TYPE_CHECKING

from tqdm import tqdm

from service import __version__
from service.argument_types import number_type, time_type
from service.frames import (
    FrameSource,
    ReadProgress,
    frame_size_problem,
    is_greyscale,
    open_frames,
)
from service.logs import quiet_ffmpeg
from service.streams.cli import add_commands as add_stream_commands
from tracking.correlation import PRESETS
from tracking.output_paths import output_file, output_folder, staged_output
from tracking.types import Box, TrackerOutput, box_problem

if TYPE_CHECKING:
    from api_schemas.jobs import JobOptions
    from service.settings import Settings
    from tracking.detection.base import Detections
    from tracking.detection.external import MotDetections

INTERRUPTED = 130
"""Exit status after Ctrl-C (128 + SIGINT), as a shell reports a program the signal ended."""


CLOSED_OUTPUT = 141
"""Exit status when the reader of our standard output went away (``vtrack track ... | head``):
128 + SIGPIPE, what the shell reports for ``yes | head``."""


class Terminated(KeyboardInterrupt):
    """SIGTERM (``kill``, ``timeout``, systemd, ``docker stop``), raised where the program is,
    as Ctrl-C raises KeyboardInterrupt: a run stops the same way and cleans up after itself."""


def _terminate(signum: int, frame: object) -> None:
    raise Terminated


def _stopped(error: KeyboardInterrupt) -> tuple[str, int]:
    """How to say what stopped a run, and its exit status (128 + the signal)."""
    if isinstance(error, Terminated):
        return "stopped by SIGTERM", 128 + signal.SIGTERM
    return "interrupted", INTERRUPTED


def _parse_box(text: str) -> Box:
    try:
        x, y, w, h = (float(v) for v in text.replace(" ", "").split(","))
    except ValueError:
        raise argparse.ArgumentTypeError(f"a box is x,y,w,h (four numbers), got {text!r}") from None
    return Box(x, y, w, h)


def _open_source(args: argparse.Namespace) -> FrameSource:
    """The frames of ``args.source``, an image folder at ``--fps`` if given.

    Raises
    ------
    ValueError
        The source cannot be read (FrameSourceError), or ``--fps`` is given for a video.
    """
    if args.fps is not None and Path(args.source).is_file():
        raise ValueError("--fps is for image folders: the frames of a video carry their own times")
    return open_frames(args.source, fps=args.fps)


def _model_file(given: Path | None, flag: str, variable: str) -> tuple[Path | None, str]:
    """A model file from its flag, else from its environment variable (as ``vtrack serve``
    reads it; the flag wins), and the name of where it came from, for messages."""
    if given is not None:
        return given, flag
    value = os.environ.get(variable, "")
    return (Path(value) if value else None), variable


def _color_names_file(given: Path | None) -> Path | None:
    """The Color Names table of ``--w2c`` or ``VTRACK_COLOR_NAMES``, loaded once to check it.

    Raises
    ------
    ValueError
        The file is not a w2c table; the message names the flag or variable.
    """
    from tracking.features.colornames import load_w2c_table

    path, origin = _model_file(given, "--w2c", "VTRACK_COLOR_NAMES")
    if path is not None:
        try:
            load_w2c_table(path)
        except ValueError as error:
            raise ValueError(f"{origin}: {error}") from None
    return path


def _warn_unused_table(w2c: Path | None, preset: str) -> None:
    """Say so when ``--w2c`` is given for a preset that uses no Color Names: it is loaded,
    checked and then has no effect on the boxes."""
    if w2c is not None and preset in PRESETS and "cn" not in PRESETS[preset].colour_features:
        print(
            f"vtrack: warning: --w2c: preset {preset} uses no Color Names "
            f"({PRESETS[preset].feature} features); the table has no effect",
            file=sys.stderr,
        )


def _dpm_model_file(given: Path | None) -> Path | None:
    """The DPM model of ``--dpm-model`` or ``VTRACK_DPM_MODEL``, loaded once to check it.

    Raises
    ------
    ValueError
        A missing file, or one that is not a voc-release5 model (the detection layer's reason);
        the message names the flag or variable.
    """
    from tracking.detection.dpm.model import ModelFileError, load_dpm_model

    path, origin = _model_file(given, "--dpm-model", "VTRACK_DPM_MODEL")
    if path is None:
        return None
    if not path.exists():
        raise ValueError(f"{origin}: {path} does not exist")
    if not path.is_file():
        raise ValueError(f"{origin}: {path} is not a file")
    try:
        load_dpm_model(path)
    except ModelFileError as error:
        reason = str(error).removeprefix(f"{path}: ")
        raise ValueError(f"{origin}: {path} is not a voc-release5 DPM model: {reason}") from None
    return path


def _format_row(index: int, box: Box, out: TrackerOutput | None, fmt: str) -> str:
    """One output row; the first frame (the given box) has no peak or PSR."""
    peak, psr = (out.peak, out.psr) if out is not None else (None, None)
    if fmt == "json":
        record = {"frame": index, "box": [box.x, box.y, box.w, box.h], "peak": peak, "psr": psr}
        return json.dumps(record)
    scores = f"{peak:.4f},{psr:.2f}" if out is not None else ","
    return f"{index},{box.x:.2f},{box.y:.2f},{box.w:.2f},{box.h:.2f},{scores}"


def _progress_bar(total: int, quiet: bool) -> tqdm:
    """The progress bar on standard error: redrawn ten times a second on a terminal, every
    30 s into a log file or a pipe (each redraw is a line there); ``TQDM_MININTERVAL`` (tqdm's
    own variable) sets the seconds for both."""
    if "TQDM_MININTERVAL" in os.environ:  # tqdm reads it when nothing is passed
        timing = {}
    else:
        timing = {"mininterval": 0.1 if sys.stderr.isatty() else 30.0}
    return tqdm(total=total or None, unit="frame", disable=quiet, **timing)


def _track(args: argparse.Namespace) -> int:
    _warn_unknown_variables()
    start = args.start or 0.0
    if args.end is not None and args.end <= start:
        print(
            f"vtrack: --end ({args.end:g} s) must come after --start ({start:g} s)", file=sys.stderr
        )
        return 2
    try:
        source = _open_source(args)
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
        frame = source.image_range(start).start + 1
        where = "--box" if args.box else f"the ground truth's box of frame {frame}"
        print(f"vtrack: {where} {problem}", file=sys.stderr)
        return 2
    config = PRESETS[args.preset]
    _warn_unused_table(args.w2c, args.preset)
    # a file named .json gets JSON lines unless --format says otherwise
    json_name = args.out is not None and args.out.suffix.lower() in (".json", ".jsonl")
    fmt = args.format or ("json" if json_name else "csv")
    from tracking.correlation import CorrelationTracker

    try:
        if color_names := _color_names_file(args.w2c):
            config = dataclasses.replace(config, color_names_path=str(color_names))
        tracker = CorrelationTracker(config)
        target, partial = staged_output(output_file(args.out)) if args.out else (None, None)
        out_file = open(partial or target, "w") if target else sys.stdout  # noqa: SIM115
    except (ValueError, OSError) as error:
        print(f"vtrack: {error}", file=sys.stderr)
        return 2
    read, written, greyscale = ReadProgress(), 0, False
    bar = _progress_bar(source.frames_until(args.end), args.quiet)
    read.on_read = lambda: bar.update(read.frames - bar.n)
    try:
        for frame in source.timed(1, read, start, args.end):
            number = frame.index + 1  # the video's own: damaged frames leave their gap
            if written == 0:
                if fmt == "csv":  # with the first row: a range without frames prints nothing
                    print("frame,x,y,w,h,peak,psr", file=out_file)
                tracker.initialize(frame.image, box)
                greyscale = is_greyscale(frame.image)
                row = _format_row(number, box, None, fmt)
            else:
                output = tracker.update(frame.image)
                row = _format_row(number, output.box, output, fmt)
            print(row, file=out_file)
            written += 1
        if written == 0:
            raise ValueError(
                f"no frame lies between --start {start:g} s and --end {args.end:g} s"
                if read.reached_end
                else f"no frame is at or after --start {start:g} s: the last is at "
                f"{read.end_time:.2f} s"
            )
        bar.close()
        if partial:
            out_file.close()
            os.replace(partial, target)
    except ValueError as error:
        bar.close()
        print(f"vtrack: {error}", file=sys.stderr)
        return 2
    except KeyboardInterrupt as error:
        bar.close()
        verb = "printed" if target is None else "written"
        kept = "nothing written" if partial else f"the {written} rows {verb} are complete"
        what, status = _stopped(error)
        print(f"vtrack: {what} after {written} frames; {kept}", file=sys.stderr)
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
        print(f"vtrack: wrote {written} boxes to {args.out}", file=sys.stderr)
    return 0


def _truth_box(source: FrameSource, start: float) -> Box:
    """The box of an OTB folder's ground truth on the first frame at ``start`` seconds.

    Raises
    ------
    ValueError
        The folder has no ground truth, or none for that frame, or it is not OTB's.
    """
    from tracking.evaluation.otb import parse_ground_truth

    path = source.path / "groundtruth_rect.txt"
    if not source.path.is_dir() or not path.is_file():
        raise ValueError("give the first box with --box x,y,w,h")
    truth = parse_ground_truth(path.read_text(), str(path))
    index = source.image_range(start).start
    if index >= len(truth):
        raise ValueError(f"{path} has no box for frame {index + 1}: give the first box with --box")
    return Box(*(float(v) for v in truth[index]))


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
        ("detector", "name"): ("--dpm-model", "dpm" if args.dpm_model else None),
        ("detector", "upscale"): ("--upscale", args.upscale),
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
    flags = {"--dpm-model": args.dpm_model, "--upscale": args.upscale}
    idle = [flag for flag, value in flags.items() if value is not None]
    if args.detection_interval is not None:
        idle.append("--detection-interval")
    elif options.tracker.full_detection_interval:
        idle.append("--options: tracker.full_detection_interval")
    if args.dpm_model is None and args.upscale is None and options.detector != DetectorOptions():
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
    since a DPM set in VTRACK_DPM_MODEL is used only when the options ask for it."""
    if options.mode == "single_target":
        return f"the {options.preset} tracker"
    if detections is not None:
        return f"the detections of {detections}"
    if options.detector.name == "dpm" and dpm_model is not None:
        return f"the DPM {dpm_model.name}"
    return "the embedded detector (OpenCV's HOG people detector)"


def _warn_unknown_variables() -> None:
    """Name a misspelt ``VTRACK_*`` variable, as ``vtrack serve`` does (these commands read
    VTRACK_DPM_MODEL and VTRACK_COLOR_NAMES)."""
    from service.settings import unknown_variables

    for line in unknown_variables(os.environ):
        print(f"vtrack: {line}", file=sys.stderr)


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

    _warn_unknown_variables()
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
    from service.analysis import PipelineResources, analyze, check_options, publish

    try:
        # VTRACK_DPM_MODEL is read only for a run that detects with it; --dpm-model always
        needs_dpm = options.mode == "people" and options.detector.name == "dpm"
        dpm_model = _dpm_model_file(args.dpm_model) if needs_dpm or args.dpm_model else None
        if needs_dpm and dpm_model is None:
            raise ValueError(
                "detector 'dpm' needs a voc-release5 model: give --dpm-model MODEL.mat or set "
                "VTRACK_DPM_MODEL"
            )
        resources = PipelineResources(dpm_model=dpm_model, color_names=_color_names_file(args.w2c))
        if options.mode == "single_target":
            _warn_unused_table(args.w2c, options.preset)
        source = _open_source(args)
        detections = _public_detections(args, source)
        if options.mode == "single_target" and options.first_box is not None:
            b = options.first_box
            if problem := box_problem(Box(b.x, b.y, b.w, b.h), (source.height, source.width)):
                raise ValueError(f"{given.get(('first_box',), '--options: first_box')} {problem}")
        # before the bar
        check_options(options, resources, source)
        created = not args.out_dir.exists()
        output_folder(args.out_dir)  # before the work, not after it
        _lock_out_dir(args.out_dir)
    except (OSError, ValueError) as error:  # FrameSourceError is a ValueError
        print(f"vtrack: {error}", file=sys.stderr)
        return 2
    bar = _progress_bar(source.frames_until(options.end), args.quiet)
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
            options,
            scratch,
            resources=resources,
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
            what, status = _stopped(error)
            print(f"vtrack: {what} after {frames_read} frames; nothing written", file=sys.stderr)
            return status
        if isinstance(error, OSError) and error.filename is None and error.strerror:
            error = f"cannot write the results into {args.out_dir}: {error.strerror}"  # disk full
        print(f"vtrack: {error}", file=sys.stderr)  # OptionsError is a ValueError
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
        print(
            f"vtrack: tracked {result.frames_processed} frames in {result.seconds:.1f} s "
            f"({rate:.1f} frames/s) with {_tracked_with(options, dpm_model, args.detections)}",
            file=sys.stderr,
        )
    for fmt, path in files.items():
        print(f"{fmt.value}\t{path}")
    return 0


def _serve(args: argparse.Namespace) -> int:
    from service.data_folder import DataFolderError, claim_data_folder
    from service.logs import quiet_ffmpeg, uvicorn_log_config
    from service.settings import InvalidSettings, load_settings
    from service.worker_processes import start_fork_server

    overrides = {
        name: value
        for name, value in (
            ("host", args.host),
            ("port", args.port),
            ("workers", args.workers),
            ("data_dir", args.data_dir),
            ("log_level", args.log_level),
        )
        if value is not None
    }
    try:
        settings = load_settings(overrides)
    except InvalidSettings as error:
        for problem in error.problems:
            print(f"vtrack: {problem}", file=sys.stderr)
        return 2
    try:
        # writable (with its subfolders and job database) and ours alone, locked until we exit
        data_folder = claim_data_folder(settings)
    except DataFolderError as error:
        print(f"vtrack: the data folder (--data-dir, VTRACK_DATA_DIR): {error}", file=sys.stderr)
        return 2
    # The port is taken here, before the workers start and "serving" is said: a port in use
    # is then a setting that cannot work, stopped at once like the others.
    family = socket.AF_INET6 if ":" in settings.host else socket.AF_INET
    try:
        listener = socket.create_server((settings.host, settings.port), family=family)
    except OSError as error:
        # create_server words every failure alike; errno tells the port's from the address's
        # (a name that does not resolve has a negative errno, that of getaddrinfo)
        reason = (error.strerror or str(error)).partition(" (while attempting")[0]
        if error.errno in (errno.EADDRINUSE, errno.EACCES):
            problem = (
                f"--port, VTRACK_PORT: cannot listen on {settings.host}:{settings.port} "
                f"({reason}); another program (another vtrack serve?) may use it, or the port "
                "needs privileges (under 1024): stop it or choose another port"
            )
        else:  # not an address of this machine, or a name that does not resolve
            problem = (
                f"--host, VTRACK_HOST: cannot listen on {settings.host!r} ({reason}): give an "
                "address of this machine, e.g. 127.0.0.1, or 0.0.0.0 for all"
            )
        print(f"vtrack: {problem}", file=sys.stderr)
        return 2
    host = settings.host
    # a wildcard address is where the service listens, not an address a browser can open
    wildcard = host in ("0.0.0.0", "::", "")
    url = f"http://{'localhost' if wildcard else f'[{host}]' if ':' in host else host}:"
    url += str(settings.port)
    where = f"every address of this machine, port {settings.port}" if wildcard else url
    workers = f"{settings.workers} worker{'s' if settings.workers != 1 else ''}"
    print(
        f"vtrack: serving on {where} with {workers}, data in {settings.data_dir}\n"
        f"vtrack: open the API docs at {url}/docs (Ctrl-C stops)",
        file=sys.stderr,
        flush=True,
    )
    for warning in _exposure_warnings(settings, where):
        print(f"vtrack: warning: {warning}", file=sys.stderr, flush=True)
    quiet_ffmpeg(settings.log_level)  # for the workers, which inherit the fork server's
    start_fork_server()
    # the application (half of the command's imports) only once the settings are known good:
    # a wrong one is then said at once
    import uvicorn

    from service.app import StoppingServer, create_app

    config = uvicorn.Config(
        create_app(settings, data_folder),
        host=settings.host,
        port=settings.port,
        log_config=uvicorn_log_config(settings.log_level),
        log_level=settings.log_level.lower(),
        timeout_graceful_shutdown=10,
    )
    StoppingServer(config).run(sockets=[listener])
    return 0


def _exposure_warnings(settings: Settings, where: str) -> list[str]:
    """What anyone on the network can do with a service listening beyond loopback: the whole
    API without a token, and the Zenoh side always (the token does not cover it; only Zenoh's
    own configuration can)."""
    from service.settings import is_loopback

    warnings = []
    if settings.api_token is None and not is_loopback(settings.host):
        warnings.append(
            f"no VTRACK_API_TOKEN, and the API listens on {where}: anyone who reaches it can "
            "upload, download and delete jobs and stream recordings; set VTRACK_API_TOKEN "
            "(docs/service.md, Security)"
        )
    if settings.zenoh_enabled and settings.zenoh_config is None:
        from service.streams.session import endpoint_address

        for endpoint in settings.zenoh_listen:
            address = endpoint_address(endpoint)
            if address is not None and not is_loopback(address):
                warnings.append(
                    f"Zenoh listens on {endpoint} without access control: anyone who reaches "
                    "it can read every camera's frames and tracks and send frames of their "
                    "own (VTRACK_API_TOKEN does not cover Zenoh); give Zenoh TLS and access "
                    "control with VTRACK_ZENOH_CONFIG, or listen on 127.0.0.1"
                )
    return warnings


QUIET_HELP = "no progress bar or closing summary (warnings and errors still print)"
W2C_HELP = "van de Weijer w2c.mat Color Names table (VTRACK_COLOR_NAMES; default: embedded)"


def _add_fps_argument(command: argparse.ArgumentParser) -> None:
    command.add_argument(
        "--fps",
        type=number_type(float, 0, above=True),
        metavar="F",
        help="frames per second of an image folder (default: its seqinfo.ini's, else 25); "
        "a video's frames carry their own times",
    )


def _add_range_arguments(command: argparse.ArgumentParser, note: str) -> None:
    command.add_argument(
        "--start",
        type=time_type,
        metavar="TIME",
        help=f"begin at this time of the video, seconds or [H:]M:S (default 0; {note}; the "
        "frames before it are read, not tracked)",
    )
    command.add_argument(
        "--end",
        type=time_type,
        metavar="TIME",
        help="stop at this time of the video, seconds or [H:]M:S (default: its end)",
    )


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="vtrack", description=__doc__)
    parser.add_argument("--version", action="version", version=f"%(prog)s {__version__}")
    commands = parser.add_subparsers(dest="command", required=True)
    track = commands.add_parser(
        "track",
        help="follow one target through a video or image folder from its first box",
        description="Follow one target with a correlation-filter tracker (preset hog_cn_scale "
        "by default: HOG and Color Names with scale adaptation).",
    )
    track.add_argument("source", help="video file, image folder, or OTB sequence folder")
    track.add_argument(
        "--box",
        type=_parse_box,
        metavar="X,Y,W,H",
        help="first-frame box x,y,w,h in pixels, 0-based (default: an OTB folder's ground truth)",
    )
    track.add_argument(
        "--preset",
        default="hog_cn_scale",
        choices=sorted(PRESETS),
        help="tracker variant (default hog_cn_scale)",
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
    _add_range_arguments(track, "the first box is drawn on the first frame at or after it")
    _add_fps_argument(track)
    track.add_argument("-q", "--quiet", action="store_true", help=QUIET_HELP)
    track.set_defaults(handler=_track)

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
    _add_range_arguments(
        analyze, "results keep the video's times and frame numbers, the MP4 starts at 0"
    )
    _add_fps_argument(analyze)
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
        type=_parse_box,
        metavar="X,Y,W,H",
        help="follow one object from this first box instead",
    )
    analyze.add_argument(
        "--preset", choices=sorted(PRESETS), help="tracker for --box (default hog_cn_scale)"
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

    serve = commands.add_parser(
        "serve",
        help="start the HTTP service",
        description="Start the HTTP service. Every setting can also come from a VTRACK_* "
        "environment variable (see the README); options here win.",
    )
    serve.add_argument("--host", help="address to bind (VTRACK_HOST, default 127.0.0.1)")
    serve.add_argument("--port", type=int, help="port (VTRACK_PORT, default 8000)")
    serve.add_argument(
        "--workers", type=int, help="worker processes (VTRACK_WORKERS, default: cores)"
    )
    serve.add_argument(
        "--data-dir",
        type=Path,
        help="job store and files (VTRACK_DATA_DIR, default: vtrack-data in the current folder)",
    )
    serve.add_argument("--log-level", help="debug, info, warning... (VTRACK_LOG_LEVEL)")
    serve.set_defaults(handler=_serve)
    add_stream_commands(commands)  # publish, subscribe
    return parser


def _attach_box_values(argv: list[str]) -> list[str]:
    """``--box -5,-5,20,20`` as ``--box=-5,-5,20,20``: argparse takes a value that starts with
    "-" and is not a plain number for an option, so a box partly left of or above the frame was
    refused with "expected one argument"."""
    attached: list[str] = []
    tokens = iter(argv)
    for token in tokens:
        attached.append(token)
        if token == "--":  # the rest is positional
            attached += tokens
        elif token == "--box" and (value := next(tokens, None)) is not None:
            if re.match(r"-[\d.]", value):
                attached[-1] = f"--box={value}"
            else:
                attached.append(value)
    return attached


def _names_as_they_are(error: UnicodeError) -> tuple[str | bytes, int]:
    """Encoding errors of our output: the bytes of a file name that is not text in the locale
    (Python holds them as surrogates) are written back as they are, so the name printed opens
    the file; a character the terminal's encoding lacks (é on an ASCII terminal) as ``\\xe9``."""
    if not isinstance(error, UnicodeEncodeError):
        raise error
    bad = error.object[error.start : error.end]
    if all("\udc80" <= c <= "\udcff" for c in bad):
        return codecs.lookup_error("surrogateescape")(error)
    return codecs.backslashreplace_errors(error)


def _print_any_name() -> None:
    """Output whose encoding fails on a name, in a UTF-8 or an ASCII locale, no longer
    ends a run that has done its work with a traceback."""
    codecs.register_error("vtrack-names", _names_as_they_are)
    for stream in (sys.stdout, sys.stderr):
        if isinstance(stream, io.TextIOWrapper) and stream.errors == "strict":
            stream.reconfigure(errors="vtrack-names")


def main(argv: list[str] | None = None) -> int:
    _print_any_name()
    args = build_parser().parse_args(_attach_box_values(sys.argv[1:] if argv is None else argv))
    if args.command != "serve":  # the service has its own shutdown and log
        signal.signal(signal.SIGTERM, _terminate)
        # FFmpeg's own lines ([h264 @ 0x...] error while decoding MB) would break the one-line
        # errors and warnings, which say what damage cost (OPENCV_FFMPEG_LOGLEVEL=16 shows them)
        quiet_ffmpeg("info")
    try:
        status = args.handler(args)
        sys.stdout.flush()  # a reader gone before the last buffered lines shows here
    except BrokenPipeError:
        # the reader of our output went away (`| head`): stop quietly, as `yes | head` does;
        # stdout to devnull so that the interpreter's final flush does not fail again
        # (https://docs.python.org/3/library/signal.html#note-on-sigpipe)
        with contextlib.suppress(OSError, ValueError):  # no descriptor (captured in tests)
            os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return CLOSED_OUTPUT
    except KeyboardInterrupt as error:  # a command that has nothing to clean up
        what, status = _stopped(error)
        print(f"vtrack: {what}", file=sys.stderr)
    return status


if __name__ == "__main__":
    sys.exit(main())
