"""The ``vtrack`` command line: ``track`` one target, ``analyze`` a video, ``serve`` the API,
``publish`` a video as a Zenoh camera and ``subscribe`` to its tracks, and make what secured
``zenoh`` links need."""

from __future__ import annotations

import argparse
import codecs
import contextlib
import io
import os
import re
import signal
import sys

from service import __version__
from service.cli import analyze, models, serve, track, zenoh
from service.cli.common import CLOSED_OUTPUT, stopped, terminate
from service.logs import quiet_ffmpeg
from service.streams.cli import add_commands as add_stream_commands


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="vtrack", description=__doc__)
    parser.add_argument("--version", action="version", version=f"%(prog)s {__version__}")
    commands = parser.add_subparsers(dest="command", required=True)
    track.add_command(commands)
    analyze.add_command(commands)
    serve.add_command(commands)
    models.add_command(commands)  # models fetch, models list
    add_stream_commands(commands)  # publish, subscribe
    zenoh.add_command(commands)  # zenoh certificates, zenoh router-config
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
        signal.signal(signal.SIGTERM, terminate)
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
        what, status = stopped(error)
        print(f"vtrack: {what}", file=sys.stderr)
    return status
