"""Both pipelines behind the one FramePipeline contract, on a real video file."""

import numpy as np
import pytest

from service.frames import open_frames
from tracking.detection import HogPeopleConfig, make_detector
from tracking.pipeline import PeoplePipeline, SingleTargetPipeline
from tracking.types import Box


@pytest.fixture(scope="module")
def pets_frames(shared_data):
    """The first 12 frames of the real H.264 PETS video (480x360, 10 fps)."""
    frames = []
    for frame in open_frames(shared_data / "video" / "pets09_s2l1_480x360.avi"):
        frames.append(frame)
        if len(frames) == 12:
            break
    return frames


def test_people_pipeline_finds_and_keeps_people_in_a_real_video(pets_frames):
    # People in this 480x360 cut are 40-55 pixels tall: the HOG window needs them enlarged 2x.
    pipeline = PeoplePipeline(make_detector("default", HogPeopleConfig(upscale=2.0)))
    results = [pipeline.process(f, i / 10.0) for i, f in enumerate(pets_frames)]
    assert [r.frame_index for r in results] == list(range(12))
    assert results[-1].timestamp == pytest.approx(1.1)
    last = results[-1]
    assert len(last) >= 2  # PETS09-S2L1 opens with several people in view
    for track in last:
        assert len(track.parts) == len(pipeline.part_names) > 0
        assert 0.0 <= track.score <= 1.0
    assert last.part_xy.shape == (len(last), len(pipeline.part_names), 2)
    ids = last.track_ids.tolist()
    assert len(set(ids)) == len(ids)


def test_single_target_pipeline_reports_one_track(pets_frames):
    pipeline = SingleTargetPipeline(Box(300, 140, 25, 60))
    results = [pipeline.process(f, i / 10.0) for i, f in enumerate(pets_frames[:5])]
    assert all(r.track_ids.tolist() == [1] for r in results)
    assert results[0].boxes.tolist() == [[300, 140, 25, 60]]
    assert np.isfinite(results[-1].boxes).all()
    with pytest.raises(ValueError, match="no detections"):
        pipeline.process(
            pets_frames[5], 0.5, detections=make_detector("submitted").detect(pets_frames[5])
        )


def test_single_target_pipeline_takes_four_numbers_and_checks_its_timestamps(pets_frames):
    # before: frame 0's box was the caller's tuple (not a Box: no .x), and time going back
    # or a string passed silently
    pipeline = SingleTargetPipeline((300, 140, 25, 60), "rcsk_cn")
    (first,) = pipeline.process(pets_frames[0], 0.0)  # the row as a TrackEstimate
    assert isinstance(first.box, Box) and first.box == Box(300.0, 140.0, 25.0, 60.0)
    pipeline.process(pets_frames[1], 0.1)
    with pytest.raises(ValueError, match=r"timestamp -5.000 s is before the previous frame's"):
        pipeline.process(pets_frames[2], -5.0)
    with pytest.raises(TypeError, match=r"timestamp must be a number of seconds, got '0\.2'"):
        pipeline.process(pets_frames[2], "0.2")
    assert pipeline.process(pets_frames[2], 0.2).frame_index == 2  # nothing was spoiled


def test_people_trackers_say_which_argument_went_where():
    from tracking.detection import HogPeopleDetector
    from tracking.people import MultiPersonTracker, PeopleTrackerConfig

    # before: AttributeError: 'HogPeopleDetector' object has no attribute 'appearance'
    with pytest.raises(TypeError, match=r"got HogPeopleDetector \(pass a detector as detector="):
        MultiPersonTracker(HogPeopleDetector())
    with pytest.raises(TypeError, match=r"got PeopleTrackerConfig \(pass it as config=\.\.\.\)"):
        PeoplePipeline(PeopleTrackerConfig())
    with pytest.raises(TypeError, match="timestamp must be a number of seconds, got '0'"):
        MultiPersonTracker(detector=HogPeopleDetector()).update(
            np.zeros((120, 160, 3), np.uint8), "0"
        )
