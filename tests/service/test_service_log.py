"""What an operator reads in the log at ``VTRACK_LOG_LEVEL=debug`` (a real server, a damaged
video); the lines at ``info`` are checked where their events are (housekeeping, refusals, the
truncated-video job of test_api)."""

from __future__ import annotations

import pytest

from tests.service.conftest import FAST_OPTIONS, submit, wait_for_state

pytestmark = pytest.mark.slow


def test_debug_adds_each_jobs_video_and_options_and_ffmpegs_own_errors(
    make_server, pets_cut, tmp_path
):
    truncated = tmp_path / "truncated.avi"
    truncated.write_bytes(pets_cut.read_bytes()[: len(pets_cut.read_bytes()) // 2])
    server = make_server(workers=1, log_level="debug")
    with server.client() as client:
        job_id = submit(client, truncated, FAST_OPTIONS).json()["id"]
        assert wait_for_state(client, job_id, ("succeeded", "failed"))["state"] == "succeeded"
    log = server.log()
    # before: the same lines as at info; the options as they run (no pose or re-identification
    # network in this service)
    assert (
        f"job {job_id}: 480x360 video, 10.000 frames per second, 24 frames announced; "
        'options {"detector":{"name":"default","upscale":1.0},"tracker":{"pose":false,'
        '"reid":false},"formats":["json"]}'
    ) in log
    # FFmpeg's complaint about the cut frame, which info leaves out: from the decoder of the
    # frames (PyAV's FFmpeg, in FFmpeg's own words; OpenCV's, which reads the first frame, has
    # the prefix [OPENCV:FFMPEG:16])
    assert "[mjpeg @ 0x" in log and "EOI missing" in log
