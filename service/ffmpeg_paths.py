"""The name FFmpeg, inside OpenCV and PyAV, is given for a file.

Two things go wrong when it is given the path as the user typed it:

- In a relative name a colon makes the part before it a protocol: ``2026-11-26T08:00:00.avi``
  and ``C:clip.avi`` are "not a video" ("Protocol not found"). An absolute name starts with
  ``/`` and is always a file.
- Both libraries hand the name on as UTF-8. A name whose bytes on disk are not UTF-8 (a file
  named on a Latin-1 system, or any non-ASCII name under a Latin-1 locale) then names another
  file or none; OpenCV even crashes the process on one that cannot be encoded at all (Python
  holds it with surrogates). Such a file is given through ``/proc/self/fd``: the descriptor
  of the file itself for one that exists, that of its folder for one about to be written
  (whose own name, chosen by us, is plain).
"""

from __future__ import annotations

import os

_DESCRIPTORS = "/proc/self/fd" if os.path.isdir("/proc/self/fd") else "/dev/fd"


def _passes_as_utf8(name: str) -> bool:
    """Whether ``name`` encoded as UTF-8 is the file system's name for it."""
    try:
        return name.encode("utf-8") == os.fsencode(name)
    except UnicodeEncodeError:  # surrogates: bytes that were not text in the locale
        return False


class FfmpegPath:
    """The name to give FFmpeg for ``path``, valid until :meth:`close` (or the ``with``
    block) ends; ``writing``: a file about to be created, in a folder that exists.

    Raises ``OSError`` when the file (or, for ``writing``, its folder) cannot be opened.
    """

    def __init__(self, path: str | os.PathLike[str], writing: bool = False) -> None:
        absolute = os.path.abspath(path)
        self._descriptor: int | None = None
        if _passes_as_utf8(absolute):
            self.name = absolute
            return
        folder, leaf = os.path.split(absolute)
        if writing and _passes_as_utf8(leaf):
            self._descriptor = os.open(folder, os.O_RDONLY | os.O_DIRECTORY)
            self.name = f"{_DESCRIPTORS}/{self._descriptor}/{leaf}"
        else:
            self._descriptor = os.open(absolute, os.O_RDONLY)
            self.name = f"{_DESCRIPTORS}/{self._descriptor}"

    def close(self) -> None:
        if self._descriptor is not None:
            os.close(self._descriptor)
            self._descriptor = None

    def __enter__(self) -> str:
        return self.name

    def __exit__(self, *exc_info: object) -> None:
        self.close()
