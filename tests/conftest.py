"""Shared fixtures: where the third-party reference data lives; the benchmark scripts as modules.

Tests read `../shared/data` beside the checkout (CI puts it there) or the folder named by
``VTRACK_SHARED_DATA``. A missing folder fails loudly rather than skipping: a test that cannot see
its data has not shown anything.
"""

from __future__ import annotations

import contextlib
import importlib.util
import os
import sys
from collections.abc import Iterator
from pathlib import Path
from types import ModuleType

import pytest

REPO_ROOT = Path(__file__).resolve().parents[1]
BENCHMARKS = REPO_ROOT / "benchmarks"


@contextlib.contextmanager
def benchmark_module(name: str) -> Iterator[ModuleType]:
    """``benchmarks/<name>.py`` loaded as a module (the scripts are not a package), with its
    folder on the import path for its siblings; both undone afterwards."""
    sys.path.insert(0, str(BENCHMARKS))
    spec = importlib.util.spec_from_file_location(f"{name}_benchmark", BENCHMARKS / f"{name}.py")
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module  # dataclasses look their module up
    try:
        spec.loader.exec_module(module)
        yield module
    finally:
        sys.modules.pop(spec.name, None)
        sys.path.remove(str(BENCHMARKS))


def _shared_data_root() -> Path:
    configured = os.environ.get("VTRACK_SHARED_DATA")
    return Path(configured) if configured else REPO_ROOT.parent / "shared" / "data"


@pytest.fixture(scope="session")
def shared_data() -> Path:
    """Root of the shared reference data (MOT, OTB, Color Names, DPM models, video)."""
    root = _shared_data_root()
    if not (root / "README.md").is_file():
        pytest.fail(f"shared reference data not found at {root}; set VTRACK_SHARED_DATA")
    return root
