"""Uploads are probed (opened, their first frame decoded) in helper processes, not in the API's.

The probe runs FFmpeg's demuxers and decoders on bytes a client chose. A file crafted or
damaged so that a decoder crashes would, in the API process, take the whole service down with
every upload in progress; one that makes a decoder hang would hold a thread of the API for
ever. In a helper process a crash answers that upload (415, the decoder crashed) and a hang
ends after ``timeout`` seconds (the helper is killed); the next probe starts a new helper.

Helpers are started on the first upload and kept (a probe then costs a message each way, not
a process start), at most ``processes`` of them, each probing one file at a time.
"""

from __future__ import annotations

import logging
import multiprocessing
import os
import threading
from multiprocessing.connection import Connection
from pathlib import Path
from typing import Any

from service.frames import FrameSource, FrameSourceError, open_frames
from service.worker_processes import describe_exit, ended_by_stop_signal, ignore_stop_signals

__all__ = ["ProbeInterrupted", "VideoProber"]

log = logging.getLogger(__name__)


class ProbeInterrupted(RuntimeError):
    """A stop signal ended the helper during the probe (the service is stopping)."""


def _serve(requests: Connection, log_level: str) -> None:
    """A helper's loop: probe each path it is sent; end when the service closes the pipe."""
    ignore_stop_signals()  # the service closes the pipe when it stops
    logging.basicConfig(
        level=log_level.upper(),
        format=f"%(asctime)s %(levelname)s probe[{os.getpid()}] %(name)s: %(message)s",
    )
    while True:
        try:
            path = requests.recv()
        except (EOFError, OSError):  # the service stopped or died
            return
        try:
            answer: tuple[str, Any] = ("ok", open_frames(path))
        except FrameSourceError as error:
            answer = ("refused", (str(error), error.reason))
        except Exception as error:  # a bug of ours: the API answers 500 with it
            answer = ("error", f"{type(error).__name__}: {error}")
        requests.send(answer)


class _Helper:
    """One helper process and the service's end of its pipe."""

    def __init__(self, ctx: Any, log_level: str) -> None:
        self._requests, theirs = ctx.Pipe()
        self.process = ctx.Process(
            target=_serve, args=(theirs, log_level), name="vtrack-probe", daemon=True
        )
        self.process.start()
        theirs.close()

    def probe(self, path: Path, timeout: float) -> FrameSource:
        try:
            self._requests.send(str(path))
            if not self._requests.poll(timeout):
                self.close()
                log.warning("the probe of %s took more than %g s: helper killed", path, timeout)
                raise FrameSourceError(
                    f"{path}: reading its first frame took more than {timeout:g} s",
                    f"the video decoder did not read its first frame in {timeout:g} s "
                    "(a damaged file)",
                )
            kind, value = self._requests.recv()
        except (EOFError, OSError):
            self.process.join(5.0)
            exitcode = self.process.exitcode
            how = describe_exit(exitcode)
            self.close()
            if ended_by_stop_signal(exitcode):
                # a stop signal to the service's process group, before the helper (starting)
                # ignored it: the file is not to blame
                raise ProbeInterrupted(f"the probe of {path} was interrupted ({how})") from None
            log.warning("the probe of %s crashed its helper process (%s)", path, how)
            raise FrameSourceError(
                f"{path}: the video decoder crashed on it ({how})",
                f"the video decoder crashed on it ({how}; a damaged or crafted file)",
            ) from None
        if kind == "refused":
            raise FrameSourceError(*value)
        if kind == "error":
            raise RuntimeError(f"probing {path} failed: {value}")
        return value

    def alive(self) -> bool:
        return self.process.is_alive()

    def close(self) -> None:
        """End the helper: its pipe closes (an idle one leaves at that), then it is killed."""
        self._requests.close()
        self.process.join(1.0)
        if self.process.is_alive():
            self.process.kill()
            self.process.join(5.0)


class VideoProber:
    """:func:`~service.frames.open_frames` of uploads, in up to ``processes`` helper processes.

    ``probe`` blocks (call it from a thread); it raises :class:`FrameSourceError` for a file
    that is no video, that crashed its helper, or that took more than ``timeout`` seconds, and
    :class:`ProbeInterrupted` when a stop signal ended the helper.
    """

    def __init__(self, processes: int = 2, timeout: float = 60.0, log_level: str = "info"):
        self._ctx = multiprocessing.get_context("spawn")
        self._timeout = timeout
        self._log_level = log_level
        self._idle: list[_Helper] = []
        self._busy = 0
        self._room = threading.Condition()
        self._processes = processes
        self._closed = False

    def probe(self, path: Path) -> FrameSource:
        helper = self._take()
        try:
            return helper.probe(path, self._timeout)
        finally:
            self._give_back(helper)

    def close(self) -> None:
        """End the idle helpers; a busy one ends when its probe returns."""
        with self._room:
            self._closed = True
            helpers, self._idle = self._idle, []
        for helper in helpers:
            helper.close()

    def _take(self) -> _Helper:
        with self._room:
            self._room.wait_for(lambda: self._idle or self._busy < self._processes)
            self._busy += 1
            helper = self._idle.pop() if self._idle else None
        if helper is not None:
            if helper.alive():
                return helper
            helper.close()  # it died idle (the OOM killer): its successor probes the file
        try:
            return _Helper(self._ctx, self._log_level)
        except BaseException:
            with self._room:
                self._busy -= 1
                self._room.notify()
            raise

    def _give_back(self, helper: _Helper) -> None:
        keep = helper.alive()
        with self._room:
            self._busy -= 1
            keep = keep and not self._closed
            if keep:
                self._idle.append(helper)
            self._room.notify()
        if not keep:
            helper.close()
