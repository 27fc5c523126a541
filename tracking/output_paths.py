"""Checking where a command will write before it starts the work whose results go there.

A calibration fit, an analysis or a tracking run takes minutes; finding only at the end that
its output folder cannot be made or written loses them. The command-line tools check first,
and the ``OSError`` these raise says what is wrong in words a user can act on.
"""

from __future__ import annotations

import hashlib
import os
import tempfile
from pathlib import Path

__all__ = ["output_file", "output_folder", "staged_output"]


def output_folder(path: str | os.PathLike[str]) -> Path:
    """``path`` as a folder this process can write into, created with its parents if missing.

    Raises
    ------
    OSError
        The folder cannot be created (a missing or read-only parent, a file in the way) or
        written into; the message names the folder and the reason.
    """
    folder = Path(path)
    try:
        folder.mkdir(parents=True, exist_ok=True)
    except FileExistsError:
        raise NotADirectoryError(f"{folder} exists and is not a folder") from None
    except OSError as error:
        raise type(error)(f"cannot create the folder {folder}: {error.strerror}") from None
    try:
        # a real write rather than os.access, which root passes everywhere and which misses
        # some refusals (read-only mounts, pseudo file systems)
        tempfile.TemporaryFile(dir=folder).close()
    except OSError as error:
        raise type(error)(f"cannot write into the folder {folder}: {error.strerror}") from None
    return folder


def output_file(path: str | os.PathLike[str]) -> Path:
    """``path`` as a file this process can create or append to, in a folder that exists (a
    mistyped folder is an error, not a new folder). An existing file is left as it is; a file
    the check creates is removed again.

    Raises
    ------
    OSError
        The path is a folder, its folder does not exist, or the file cannot be opened for
        writing; the message names the file and the reason.
    """
    file = Path(path)
    if file.is_dir():
        raise IsADirectoryError(f"{file} is a folder: give a file name")
    if not file.parent.is_dir():
        raise FileNotFoundError(f"cannot write {file}: the folder {file.parent} does not exist")
    if file.exists() and not file.is_file():
        # a device or a pipe: opened and closed to try it, a pipe would end its reader's input
        if not os.access(file, os.W_OK):
            raise PermissionError(f"cannot write {file}: permission denied")
        return file
    existed = file.exists()
    try:
        open(file, "a").close()  # opened only to see that it can be
    except OSError as error:
        raise type(error)(f"cannot write {file}: {error.strerror}") from None
    if not existed:
        file.unlink()
    return file


def staged_output(path: str | os.PathLike[str]) -> tuple[Path, Path | None]:
    """Where a command writes the file ``path`` names: ``(target, partial)``.

    ``target`` is the file, or the one a symbolic link points to (the link stays a link).
    ``partial``, beside it, takes the content until the run is complete and is then renamed
    over ``target``, so a run that fails leaves no half-written file and an older file as it
    was. It is ``None`` for a device or a pipe (``/dev/null``, a FIFO), which a rename would
    replace by a plain file: those are written directly.
    """
    target = Path(path).resolve()
    if target.exists() and not target.is_file():
        return target, None
    partial = f".{target.name}.partial"
    if len(os.fsencode(partial)) > _longest_name(target.parent):
        # a target of a name as long as its file system allows: a shorter one of its own
        partial = f".{hashlib.sha256(os.fsencode(target.name)).hexdigest()[:16]}.partial"
    return target, target.with_name(partial)


def _longest_name(folder: Path) -> int:
    """The longest file name, in bytes, ``folder`` takes (255 where it cannot be asked)."""
    try:
        return os.pathconf(folder, "PC_NAME_MAX")
    except (OSError, ValueError):
        return 255
