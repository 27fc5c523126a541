"""The benchmarks' ``--json`` output: one strict JSON object on standard output."""

from __future__ import annotations

import json
import math
import sys


def finite(value: object) -> object:
    """``value`` with every non-finite float replaced by None (strict JSON has no NaN or
    infinity, and parsers other than Python's refuse them)."""
    if isinstance(value, dict):
        return {k: finite(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [finite(v) for v in value]
    if isinstance(value, float) and not math.isfinite(value):
        return None
    return value


def print_json(report: object, indent: int | None = 1) -> None:
    """Print ``report`` as strict JSON; values JSON has no type for are written as text."""
    json.dump(finite(report), sys.stdout, indent=indent, allow_nan=False, default=str)
    print()
