"""Shared fixtures: where the third-party reference data lives.

Tests read `../shared/data` beside the checkout (CI puts it there) or the folder named by
``VTRACK_SHARED_DATA``. A missing folder fails loudly rather than skipping: a test that cannot see
its data has not shown anything.
"""

from __future__ import annotations

import os
from pathlib import Path

import pytest

REPO_ROOT = Path(__file__).resolve().parents[1]


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
