"""A MOTChallenge sequence's ``seqinfo.ini``, and the error for a malformed sequence.

Apart from :mod:`tracking.detection.sequences` (which re-exports both) so that reading a
folder's frame rate (:mod:`service.frames`) does not import the detectors.
"""

from __future__ import annotations

import configparser
import math
import os
from collections.abc import Mapping
from pathlib import Path

__all__ = ["MotFormatError", "read_seqinfo", "seqinfo_frame_rate", "seqinfo_whole_number"]


class MotFormatError(ValueError):
    """A MOTChallenge file or folder is missing or malformed."""


def read_seqinfo(folder: str | os.PathLike[str]) -> Mapping[str, str]:
    """The ``[Sequence]`` entries of ``folder/seqinfo.ini`` (``name``, ``frameRate``,
    ``imDir``, ...; keys in any case), ``{}`` when the folder has no such file.

    Raises
    ------
    MotFormatError
        If the file cannot be parsed or has no ``[Sequence]`` section.
    """
    ini = Path(folder) / "seqinfo.ini"
    if not ini.is_file():
        return {}
    parser = configparser.ConfigParser()
    try:
        parser.read(ini, encoding="utf-8")
    except (configparser.Error, UnicodeDecodeError) as exc:
        raise MotFormatError(f"{ini}: {exc}") from exc
    if not parser.has_section("Sequence"):
        raise MotFormatError(f"{ini}: no [Sequence] section")
    return parser["Sequence"]


def seqinfo_frame_rate(ini: Path, section: Mapping[str, str]) -> float | None:
    """``frameRate`` of ``ini``'s ``[Sequence]`` (``None`` when the file has none).

    Raises
    ------
    MotFormatError
        If it is not a finite, positive number; the message names the file and the value.
    """
    if "frameRate" not in section:  # keys in any case, as configparser reads them
        return None
    text = section["frameRate"]
    try:
        rate = float(text)
    except ValueError:
        raise MotFormatError(
            f"{ini}: frameRate {text!r} is not a number of frames per second"
        ) from None
    if not (math.isfinite(rate) and rate > 0):
        raise MotFormatError(
            f"{ini}: frameRate {text!r} is not a positive number of frames per second"
        )
    return rate


def seqinfo_whole_number(ini: Path, section: Mapping[str, str], key: str) -> int | None:
    """Integer ``key`` of ``ini``'s ``[Sequence]`` (``None`` when the file has none).

    Raises
    ------
    MotFormatError
        If it is not a whole number; the message names the file, the key and the value.
    """
    if key not in section:
        return None
    text = section[key]
    try:
        return int(text)
    except ValueError:
        raise MotFormatError(f"{ini}: {key} {text!r} is not a whole number") from None
