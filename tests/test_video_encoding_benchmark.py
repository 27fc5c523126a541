"""``benchmarks/video_encoding.py``: both encoders measured on real frames, one JSON object."""

from __future__ import annotations

import json

import pytest

from tests.conftest import benchmark_module


@pytest.mark.slow
def test_prints_time_and_size_per_frame_for_each_encoder(shared_data, capsys):
    with benchmark_module("video_encoding") as module:
        module.main(
            [
                "--video",
                str(shared_data / "video" / "pets09_s2l1_480x360.avi"),
                *("--frames", "6", "--heights", "120", "241", "--repeats", "1", "--json"),
            ]
        )
    report = json.loads(capsys.readouterr().out)
    assert report["frames"] == 6 and set(report["heights"]) == {"120", "241"}
    for row in report["heights"].values():
        assert set(row) == {"h264", "mp4v", "h264-units", "jpeg"}
        for figures in row.values():
            assert figures["ms_per_frame"] > 0 and figures["kb_per_frame"] > 0
