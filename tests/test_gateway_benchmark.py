"""``benchmarks/gateway.py``: a simulated camera through ``vtrack publish``'s code, each payload
measured, one JSON object."""

from __future__ import annotations

import json
import os
import subprocess
import sys

import pytest

from tests.conftest import BENCHMARKS, REPO_ROOT


@pytest.mark.slow
def test_prints_cpu_and_size_per_frame_for_each_payload(shared_data):
    # Not marked realtime: it checks the report's shape and orderings that hold on a busy
    # machine too (passed beside two busy processes, load 6.8); docs/benchmarks.md's figures
    # come from the benchmark run on its own.
    command = [sys.executable, str(BENCHMARKS / "gateway.py"), "--json", "--frames", "12"]
    command += ["--repeats", "1", "--delay-frames", "20", "--capture-seconds", "4"]
    result = subprocess.run(
        [*command, "--sizes", "160x120"],
        cwd=REPO_ROOT,
        env={**os.environ, "VTRACK_SHARED_DATA": str(shared_data)},
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert result.returncode == 0, result.stderr
    report = json.loads(result.stdout)
    rows = {row["mode"]: row for row in report["sizes"]["160x120"]}
    assert set(rows) == {"forward", "h264", "jpeg", "raw"}
    for mode, row in rows.items():
        assert row["frames_sent"] == 12 and row["cpu_ms_per_frame"] > 0
        if mode in ("forward", "h264"):  # blocking congestion control: every frame arrives
            assert row["frames_received"] == 12
        else:  # raw and JPEG frames are dropped when the link is congested (a busy machine)
            assert 1 <= row["frames_received"] <= 12
    assert rows["raw"]["kb_per_frame"] == pytest.approx(160 * 120 * 3 / 1000)
    assert rows["forward"]["kb_per_frame"] < rows["jpeg"]["kb_per_frame"]
    for camera in ("rtsp", "mpegts-tcp"):
        for study in ("gateway", "ffmpeg_defaults"):
            row = report["first_frame"][camera][study]
            assert row["seconds"] > 0 and 1 <= row["frames_at_once"] <= 30
    delays = report["frame_delay_ms"]
    for mode in ("decoded", "forwarded"):
        # the parser holds each frame until the next one starts: 100 ms at 10 fps
        whole, parsed = (
            delays[f"mpegts-tcp, {way}, {mode}"] for way in ("packet by packet", "parser")
        )
        assert 0 < whole["median"] < parsed["median"]
        assert delays[f"rtsp, {mode}"]["median"] > 0
    stamps = report["capture_times"]
    assert stamps["frames"] == 40
    # the camera's times keep the spacing that congestion breaks up on arrival
    assert stamps["capture_clock"]["frames_within_10ms_of_the_previous"] == 0
    clock, arrival = stamps["capture_clock"], stamps["arrival"]
    assert clock["spacing_error_ms"]["p95"] < arrival["spacing_error_ms"]["p95"]


@pytest.mark.parametrize(
    "arguments, message",
    [
        (["--delay-frames", "10"], "--delay-frames: must be at least 20"),
        (["--sizes", "480"], "--sizes: WIDTHxHEIGHT"),
        (["--modes", "h264,mjpeg"], "--modes: unknown mjpeg"),
        (["--frames", "0"], "--frames: must be at least 1"),
    ],
)
def test_bad_arguments_are_named_before_anything_runs(arguments, message):
    result = subprocess.run(
        [sys.executable, str(BENCHMARKS / "gateway.py"), *arguments],
        cwd=REPO_ROOT,
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert result.returncode == 2
    assert message in result.stderr
