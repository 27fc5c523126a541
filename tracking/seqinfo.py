"""A MOTChallenge sequence's ``seqinfo.ini``, and the error for a malformed sequence.

Apart from :mod:`tracking.detection.sequences` (which re-exports both) so that reading a
folder's frame rate (:mod:`service.frames`) does not import the detectors.
"""

from __future__ import annotations

import configparser
import os
from collections.abc import Mapping
from pathlib import Path

__all__ = ["MotFormatError", "read_seqinfo"]


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
