"""What the multi-object peer scripts (``mot_trackers.py``, ``reid_trackers.py``) share: the
digest of the detections they were fed, their common arguments and the loop over sequences.

Imported by those scripts as a sibling module (each runs as a script from this folder, in its
own environment); it needs only numpy and the standard library, and nothing of the project.
"""

from __future__ import annotations

import argparse
import contextlib
import hashlib
import sys
from collections.abc import Callable, Iterable

import numpy as np


def fed_digest(rows: np.ndarray) -> str:
    """Digest of detections ``frame, x, y, w, h`` (file units), rounded to 1e-4 px; mirrored in
    ``benchmarks/mot.py``."""
    values = np.round(np.asarray(rows, dtype=np.float64).reshape(-1, 5), 4) + 0.0  # no -0.0
    return hashlib.sha256(np.ascontiguousarray(values).tobytes()).hexdigest()[:16]


def add_run_arguments(parser: argparse.ArgumentParser, frame_rate_help: str) -> None:
    """``--frames``, ``--repeats`` and ``--frame-rate``, as every peer script takes them."""
    parser.add_argument("--frames", type=int, help="only the first N frames of each sequence")
    parser.add_argument("--repeats", type=int, default=1, help="timed runs per sequence")
    parser.add_argument(
        "--frame-rate", choices=("sequence", "library"), default="sequence", help=frame_rate_help
    )


def check_run_arguments(parser: argparse.ArgumentParser, args: argparse.Namespace) -> None:
    """Refuse (``parser.error``) a count that is not positive."""
    if args.repeats < 1 or (args.frames is not None and args.frames < 1):
        parser.error("--repeats and --frames must be positive")


def run_sequences(
    kind: str,
    runs: Iterable[tuple[str, Callable[[], dict]]],
    errors: tuple[type[BaseException], ...],
    repeats: int,
) -> list[dict]:
    """Each ``(name, run)``'s result: ``run()`` with stdout sent to stderr (a library that
    prints must not spoil the JSON on stdout), or ``{"name", "error"}`` when it raises one of
    ``errors``; a line per sequence on stderr."""
    results = []
    for name, run in runs:
        try:
            with contextlib.redirect_stdout(sys.stderr):
                result = run()
        except errors as exc:
            result = {"name": name, "error": f"{type(exc).__name__}: {exc}"}
            print(f"{kind} {name}: {result['error']}", file=sys.stderr)
        else:
            fps = result["frames"] / max(float(np.median(result["seconds"])), 1e-12)
            print(
                f"{kind} {result['name']}: {result['frames']} frames, {len(result['rows'])} "
                f"boxes, {fps:.0f} fps (median of {repeats})",
                file=sys.stderr,
            )
        results.append(result)
    return results
