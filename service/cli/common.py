"""What the ``vtrack`` commands share: how a run says it was stopped, the frames of a source,
the model files they load and check, the progress bar, and the arguments they have in common."""

from __future__ import annotations

import argparse
import os
import signal
import sys
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from tqdm import tqdm

from service.argument_types import number_type, time_type
from service.frames import FrameSource, open_frames
from tracking.correlation import PRESETS
from tracking.types import Box

INTERRUPTED = 130
"""Exit status after Ctrl-C (128 + SIGINT), as a shell reports a program the signal ended."""


CLOSED_OUTPUT = 141
"""Exit status when the reader of our standard output went away (``vtrack track ... | head``):
128 + SIGPIPE, what the shell reports for ``yes | head``."""


class Terminated(KeyboardInterrupt):
    """SIGTERM (``kill``, ``timeout``, systemd, ``docker stop``), raised where the program is,
    as Ctrl-C raises KeyboardInterrupt: a run stops the same way and cleans up after itself."""


def terminate(signum: int, frame: object) -> None:
    """The SIGTERM handler of the commands that are not the service."""
    raise Terminated


def stopped(error: KeyboardInterrupt) -> tuple[str, int]:
    """How to say what stopped a run, and its exit status (128 + the signal)."""
    if isinstance(error, Terminated):
        return "stopped by SIGTERM", 128 + signal.SIGTERM
    return "interrupted", INTERRUPTED


def parse_box(text: str) -> Box:
    """``--box x,y,w,h``: four numbers, spaces allowed."""
    try:
        x, y, w, h = (float(v) for v in text.replace(" ", "").split(","))
    except ValueError:
        raise argparse.ArgumentTypeError(f"a box is x,y,w,h (four numbers), got {text!r}") from None
    return Box(x, y, w, h)


def open_source(args: argparse.Namespace) -> FrameSource:
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


def color_names_file(given: Path | None) -> Path | None:
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


def warn_unused_table(w2c: Path | None, preset: str) -> None:
    """Say so when ``--w2c`` is given for a preset that uses no Color Names: it is loaded,
    checked and then has no effect on the boxes."""
    if w2c is not None and preset in PRESETS and "cn" not in PRESETS[preset].colour_features:
        print(
            f"vtrack: warning: --w2c: preset {preset} uses no Color Names "
            f"({PRESETS[preset].feature} features); the table has no effect",
            file=sys.stderr,
        )


@dataclass(frozen=True, slots=True)
class NetworkFiles:
    """The networks of ``vtrack analyze``: the models folder, and the file of the CNN
    detector, the pose and the re-identification network (each None: none; a default model of
    the folder may be missing: what would run it then goes without, as in the service)."""

    models_dir: Path | None
    cnn: Path | None
    pose: Path | None
    reid: Path | None


def network_files(cnn: Path | None, pose: Path | None, reid: Path | None) -> NetworkFiles:
    """The networks of ``--cnn-model``, ``--pose-model`` and ``--reid-model``, else of
    ``VTRACK_CNN_MODEL``, ``VTRACK_POSE_MODEL``, ``VTRACK_REID_MODEL`` and
    ``VTRACK_MODELS_DIR`` as ``vtrack serve`` reads them (:mod:`service.models.resolve`: a
    model name of the folder or a file; unset, the task's default model of the folder). Each
    file that is there is loaded once to check it.

    Raises
    ------
    ValueError
        A network named but missing or unreadable, one of another task, a models folder that
        is none; the message names the flag or variable.
    """
    from service.models.resolve import (
        CNN_SETTING,
        POSE_SETTING,
        REID_SETTING,
        check_model_setting,
    )

    value = os.environ.get("VTRACK_MODELS_DIR", "")
    folder = Path(value) if value else None
    if folder is not None and not folder.is_dir():
        raise ValueError(f"VTRACK_MODELS_DIR: {folder} is not a folder")
    found = []
    for given, flag, setting in (
        (cnn, "--cnn-model", CNN_SETTING),
        (pose, "--pose-model", POSE_SETTING),
        (reid, "--reid-model", REID_SETTING),
    ):
        if given is not None:
            found.append(check_model_setting(setting, str(given), folder, flag))
        else:
            named = os.environ.get(setting.variable, "") or None  # empty: unset, as elsewhere
            found.append(check_model_setting(setting, named, folder))
    return NetworkFiles(folder, *found)


def dpm_model_file(given: Path | None) -> Path | None:
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


def progress_bar(total: int, quiet: bool) -> tqdm:
    """The progress bar on standard error: redrawn ten times a second on a terminal, every
    30 s into a log file or a pipe (each redraw is a line there); ``TQDM_MININTERVAL`` (tqdm's
    own variable) sets the seconds for both."""
    timing: dict[str, Any]
    if "TQDM_MININTERVAL" in os.environ:  # tqdm reads it when nothing is passed
        timing = {}
    else:
        timing = {"mininterval": 0.1 if sys.stderr.isatty() else 30.0}
    return tqdm(total=total or None, unit="frame", disable=quiet, **timing)


def warn_unknown_variables() -> None:
    """Name a misspelt ``VTRACK_*`` variable, as ``vtrack serve`` does (these commands read
    VTRACK_DPM_MODEL and VTRACK_COLOR_NAMES)."""
    from service.settings import unknown_variables

    for line in unknown_variables(os.environ):
        print(f"vtrack: {line}", file=sys.stderr)


QUIET_HELP = "no progress bar or closing summary (warnings and errors still print)"
W2C_HELP = "van de Weijer w2c.mat Color Names table (VTRACK_COLOR_NAMES; default: embedded)"


def add_fps_argument(command: argparse.ArgumentParser) -> None:
    command.add_argument(
        "--fps",
        type=number_type(float, 0, above=True),
        metavar="F",
        help="frames per second of an image folder (default: its seqinfo.ini's, else 25); "
        "a video's frames carry their own times",
    )


def add_range_arguments(command: argparse.ArgumentParser, note: str) -> None:
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
