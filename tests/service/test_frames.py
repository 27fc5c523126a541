"""Frame timestamps: a frame is stamped with its presentation time in the video, so the frames of
a variable-frame-rate video keep their real spacing in the results and in the motion model."""

from __future__ import annotations

import fractions
from itertools import islice

import av
import pytest

from api_schemas.jobs import JobOptions
from service.analysis import analyze
from service.frames import open_frames
from service.outputs.json_out import read_trajectories
from tests.service.conftest import PETS_VIDEO

pytestmark = pytest.mark.slow

# Presentation times in milliseconds of a video whose recorder dropped frames: steady 10 fps
# runs broken by gaps of 0.5 s and 1.2 s.
VFR_MS = [0, 100, 200, 300, 800, 900, 1000, 2200, 2300, 2400, 2500, 2600]


@pytest.fixture(scope="module")
def vfr_video(shared_data, tmp_path_factory):
    """An MPEG-4 file of real PETS frames stamped with ``VFR_MS`` (written by PyAV: OpenCV's
    writer has one frame rate)."""
    frames = list(islice(open_frames(shared_data / PETS_VIDEO), len(VFR_MS)))
    path = tmp_path_factory.mktemp("vfr") / "dropped_frames.mp4"
    millisecond = fractions.Fraction(1, 1000)
    with av.open(str(path), "w") as container:
        stream = container.add_stream("mpeg4", rate=10)
        stream.width, stream.height, stream.pix_fmt = 480, 360, "yuv420p"
        stream.time_base = millisecond
        for image, ms in zip(frames, VFR_MS, strict=True):
            frame = av.VideoFrame.from_ndarray(image, format="rgb24")
            frame.pts, frame.time_base = ms, millisecond
            container.mux(stream.encode(frame))
        container.mux(stream.encode())
    return path


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
