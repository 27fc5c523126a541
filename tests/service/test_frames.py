"""Frame timestamps: a frame is stamped with its presentation time in the video, so the frames of
a variable-frame-rate video keep their real spacing in the results and in the motion model."""

from __future__ import annotations

from itertools import islice

import pytest

from api_schemas.jobs import JobOptions
from service.analysis import analyze
from service.frames import open_frames
from service.outputs.json_out import read_trajectories
from tests.service.conftest import PETS_VIDEO, VFR_MS

pytestmark = pytest.mark.slow


def test_a_constant_rate_video_is_stamped_index_over_fps(shared_data):
    # The H.264 AVI puts its first frame at 0.2 s (B-frame delay); the first frame is time 0.
    source = open_frames(shared_data / PETS_VIDEO)
    stamps = [(f.index, f.timestamp) for f in islice(source.timed(), 30)]
    assert stamps == [(i, pytest.approx(i / 10)) for i in range(30)]
    stepped = [(f.index, f.timestamp) for f in islice(source.timed(4), 5)]
    assert stepped == [(i, pytest.approx(i / 10)) for i in range(0, 20, 4)]


def test_a_variable_rate_video_keeps_its_presentation_times(vfr_video):
    source = open_frames(vfr_video)
    assert [f.timestamp for f in source.timed()] == pytest.approx([ms / 1000 for ms in VFR_MS])
    # skipped frames are grabbed, and the kept ones still carry their own times
    assert [(f.index, f.timestamp) for f in source.timed(3)] == [
        (i, pytest.approx(VFR_MS[i] / 1000)) for i in range(0, len(VFR_MS), 3)
    ]


def test_the_json_result_carries_the_presentation_times(vfr_video, tmp_path):
    result = analyze(vfr_video, JobOptions(formats=["json"]), tmp_path / "out")
    trajectories = read_trajectories(result.files["json"])
    points = [p for t in trajectories.tracks for p in t.frames]
    assert points, "people are tracked in the PETS frames"
    for point in points:
        assert point.timestamp == pytest.approx(VFR_MS[point.frame_index] / 1000)
