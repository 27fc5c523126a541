"""Where the benchmarks find the repository and the shared third-party data."""

from __future__ import annotations

import os
from pathlib import Path

REPO_ROOT = Path(__file__).resolve().parents[1]

SHARED_DATA = Path(os.environ.get("VTRACK_SHARED_DATA") or REPO_ROOT.parent / "shared" / "data")
"""``$VTRACK_SHARED_DATA`` if set and not empty, else ``shared/data`` beside the checkout (where
CI puts it). Read once, at import: the benchmarks take it as their default data folder."""
