"""argparse types shared by the ``vtrack`` commands: numbers within bounds, times of a video."""

from __future__ import annotations

import argparse
import math
from collections.abc import Callable

__all__ = ["number_type", "time_type"]


def _comma(text: str) -> str:
    """A hint for a decimal comma (``1,5``), as many locales write numbers."""
    return " (decimals take a point: 1.5)" if "," in text else ""


def number_type(
    convert: Callable[[str], float], low: float, high: float = math.inf, *, above: bool = False
):
    """An argparse type: ``convert(text)`` from ``low`` (excluded when ``above``) to ``high``,
    a finite number."""

    def parse(text: str) -> float:
        try:
            value = convert(text)
            if not math.isfinite(value):
                raise ValueError
        except ValueError:
            kind = "a whole number" if convert is int else "a finite number"
            raise argparse.ArgumentTypeError(
                f"expected {kind}, got {text!r}{_comma(text)}"
            ) from None
        if not ((value > low if above else value >= low) and value <= high):
            bound = f"greater than {low:g}" if above else f"at least {low:g}"
            bound += f" and at most {high:g}" if high < math.inf else ""
            raise argparse.ArgumentTypeError(f"must be {bound}, got {text}")
        return value

    return parse


def time_type(text: str) -> float:
    """An argparse type for ``--start``/``--end``: seconds (``90``, ``12.5``) or a clock time
    (``1:30``, ``1:02:03.5``)."""
    fields = text.strip().split(":")
    try:
        if len(fields) > 3 or not all(f.isdigit() for f in fields[:-1]):
            raise ValueError
        seconds = float(fields[-1])
        if not (0 <= seconds < (60 if len(fields) > 1 else math.inf)):  # NaN, inf, -1, 1:75
            raise ValueError
    except ValueError:
        raise argparse.ArgumentTypeError(
            f"a time is seconds (90, 12.5) or [H:]M:S (1:30, 1:02:03.5), got {text!r}"
            + _comma(text)
        ) from None
    minutes = 0
    for number in fields[:-1]:
        minutes = minutes * 60 + int(number)
    return minutes * 60 + seconds
