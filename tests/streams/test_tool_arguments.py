"""`vtrack publish` and `vtrack subscribe` refuse arguments that cannot work, before any Zenoh
session opens: exit 2 and a line naming the argument (argparse's usage error)."""

from __future__ import annotations

import subprocess
import sys

import pytest

from tests.conftest import REPO_ROOT


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["publish", "v.avi", "--camera", "gate/2"], "--camera: 'gate/2' is not a valid camera"),
        (["publish", "v.avi", "--camera", "c", "--prefix", "a//b"], "'a//b' is not a valid key"),
        (["publish", "v.avi", "--camera", "c", "--connect", "7447"], "'7447' is not a Zenoh"),
        (["publish", "v.avi", "--camera", "c", "--fps", "0"], "--fps: must be greater than 0"),
        # before: accepted, and the frames went out as fast as they could be sent
        (["publish", "v.avi", "--camera", "c", "--fps", "inf"], "--fps: expected a finite number"),
        (["publish", "v.avi", "--camera", "c", "--limit", "-1"], "--limit: must be at least 1"),
        (["publish", "v.avi", "--camera", "c", "--limit", "2.5"], "expected a whole number"),
        (["publish", "v.avi", "--camera", "c", "--quality", "200"], "at least 1 and at most 100"),
        (["publish", "v.avi", "--camera", "c", "--wait", "-1"], "--wait: must be at least 0"),
        (["publish", "v.avi", "--camera", "c", "--detections-scale", "nan"], "a finite number"),
        (["publish", "v.avi", "--camera", "c", "--raw", "--h264"], "not allowed with argument"),
        # options that would do nothing for this source: refused, where they were ignored
        (["publish", "v.avi", "--camera", "c", "--timeout", "3"], "are for network cameras"),
        (["publish", "v.avi", "--camera", "c", "--input-option", "a=b"], "for network cameras"),
        (["publish", "v.avi", "--camera", "c", "--h264", "--quality", "50"], "not with --raw"),
        (["publish", "v.avi", "--camera", "c", "--raw", "--quality", "50"], "not with --raw"),
        (
            ["publish", "v.avi", "--camera", "c", "--detections-scale", "0.5"],
            "--detections-scale scales the boxes of --detections, which is not given",
        ),
        (["subscribe", "--camera", "c", "--count", "0"], "--count: must be at least 1"),
        (["subscribe", "--camera", "c", "--duration", "-1"], "--duration: must be greater"),
    ],
)
def test_bad_arguments_are_refused_by_name(args, message):
    result = subprocess.run(
        [sys.executable, "-m", "service.cli", *args],
        capture_output=True,
        text=True,
        timeout=60,
        cwd=REPO_ROOT,
    )
    assert result.returncode == 2 and "Traceback" not in result.stderr
    assert message in result.stderr
