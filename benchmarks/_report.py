"""The benchmarks' ``--json`` output: one strict JSON object on standard output."""

from __future__ import annotations

import importlib.metadata
import json
import math
import os
import platform
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


# The instruction sets OpenVINO's CPU plugin picks its kernels by: with AMX, int8 and bf16
# networks run several times faster than with AVX-512 alone (the pose network's crops took 5.7
# ms on the machine of 2026-12-06 and 20 ms on an AVX-512 machine without AMX on 2026-12-07).
_INFERENCE_FLAGS = ("avx2", "avx512f", "avx512_vnni", "avx512_bf16", "amx_bf16", "amx_int8")


def machine() -> dict[str, object]:
    """The machine a speed was measured on: CPU model, cores, the instruction sets of
    :data:`_INFERENCE_FLAGS` it has, and OpenVINO's version, so that figures measured on two
    machines are not read as one (the speed benchmarks' ``machine`` field)."""
    model, flags = platform.processor() or platform.machine(), set[str]()
    try:
        with open("/proc/cpuinfo", encoding="utf-8") as cpuinfo:
            for line in cpuinfo:
                key, _, value = line.partition(":")
                if key.strip() == "model name":
                    model = value.strip()
                elif key.strip() == "flags":
                    flags = set(value.split())
                    break
    except OSError:  # not Linux: the model from platform, no flags
        pass
    try:
        openvino = importlib.metadata.version("openvino")
    except importlib.metadata.PackageNotFoundError:
        openvino = None
    return {
        "cpu": model,
        "cpu_count": os.cpu_count(),
        "cpu_flags": [flag for flag in _INFERENCE_FLAGS if flag in flags],
        "openvino": openvino,
    }
