"""The public API that docs/detection.md lists is what `tracking.detection` exports."""

from __future__ import annotations

import re
import subprocess
import sys

import tracking.detection
from tests.conftest import REPO_ROOT


def _documented_names() -> set[str]:
    """The names in the first column of the Public API table: capitalised ones, functions
    (a name and its bracket) and lone names; not methods (after a dot, or in the bracketed
    lists of methods) nor arguments."""
    text = (REPO_ROOT / "docs" / "detection.md").read_text()
    table = text.split("## Public API", 1)[1].split("\n## ", 1)[0]
    names = set()
    for row in table.splitlines():
        if not row.startswith("| `"):
            continue
        cell = re.sub(r"\(`.*?`\)", "", row.split(" | ")[0])
        for span in re.findall(r"`([^`]+)`", cell):
            if span.startswith("python "):
                continue
            names.update(re.findall(r"(?<![.\w\"])(?:[A-Z]\w*|[a-z_]\w*(?=\())", span))
            if re.fullmatch(r"[a-z_]\w*", span):
                names.add(span)
    return names


def test_every_name_of_the_public_api_table_imports_from_tracking_detection():
    names = _documented_names()
    assert len(names) > 20  # the table was read
    # before: DpmModel (the type load_dpm_model returns) was in tracking.detection.dpm only
    assert sorted(n for n in names if not hasattr(tracking.detection, n)) == []
    from tracking.detection.dpm import KNOWN_CASCADES  # named in the table's second column

    assert KNOWN_CASCADES


def test_warmup_help_says_what_it_does_without_doing_it():
    # before: --help was ignored and the kernels compiled (about 20 s on a fresh install)
    shown = subprocess.run(
        [sys.executable, "-m", "tracking.warmup", "--help"],
        capture_output=True,
        text=True,
        timeout=120,
        cwd=REPO_ROOT,
    )
    assert shown.returncode == 0, shown.stderr
    assert shown.stdout.startswith("usage: python -m tracking.warmup")
    assert "numba kernels ready" not in shown.stdout
