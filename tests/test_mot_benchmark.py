"""The MOT benchmark's own machinery: seeded runs, replayed detections, configuration options."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import cv2
import numpy as np
import pytest

from tests.conftest import benchmark_module
from tracking.detection import DPM_TRACKING_CONFIG, make_detector
from tracking.people import PeopleTrackerConfig


@pytest.fixture(scope="module")
def mot():
    with benchmark_module("mot") as module:  # it imports its sibling _mot_env
        yield module


class CountingDetector:
    """The embedded detector, counting its full-frame calls."""

    def __init__(self) -> None:
        self.inner = make_detector("default")
        self.part_names = self.inner.part_names
        self.calls = 0

    def detect(self, frame: np.ndarray):
        self.calls += 1
        return self.inner.detect(frame)


def _frame(shared_data: Path, index: int) -> np.ndarray:
    path = shared_data / "mot" / "PETS09-S2L1" / "img1" / f"{index:06d}.jpg"
    return cv2.cvtColor(cv2.imread(str(path)), cv2.COLOR_BGR2RGB)


def test_seeded_runs_replay_the_recorded_detections(mot, shared_data: Path) -> None:
    counting = CountingDetector()
    recorder = mot.RecordingDetector(lambda: counting)
    replayed = mot.ReplayedDetector(recorder)
    first, second = _frame(shared_data, 1), _frame(shared_data, 2)
    a = recorder.detect(first)
    assert len(a) > 0  # PETS09-S2L1 frame 1 has people
    recorder.detect(first)  # the recording run always detects: its timings include it
    assert counting.calls == 2
    again = replayed.detect(first.copy())  # the same pixels in another array
    assert counting.calls == 2
    np.testing.assert_array_equal(again.boxes, a.boxes)
    replayed.detect(second)  # not recorded yet: detected, and recorded
    replayed.detect(second)
    assert counting.calls == 3
    # A frame that differs in one pixel is detected anew.
    changed = first.copy()
    changed[0, 0, 0] ^= 1
    replayed.detect(changed)
    assert counting.calls == 4
    assert replayed.part_names == counting.part_names  # other attributes pass through


def test_seeded_runs_share_one_detector(mot, tmp_path: Path) -> None:
    config = PeopleTrackerConfig(report_missing=0.5)
    ours = mot.build_ours(["ours", "ours_hog"], tmp_path / "none.mat", 3, None, None, config)
    assert list(ours) == ["ours", "ours_seed1", "ours_seed2", "ours_hog", "ours_hog_seed1",
                          "ours_hog_seed2"]  # fmt: skip
    trackers = {name: entry.factory() for name, entry in ours.items()}
    assert [t.config.seed for t in trackers.values()] == [0, 1, 2, 0, 1, 2]
    assert all(t.config.report_missing == 0.5 for t in trackers.values())
    hog = [trackers[n]._detector for n in ("ours_hog", "ours_hog_seed1", "ours_hog_seed2")]
    assert isinstance(hog[0], mot.RecordingDetector)
    assert all(isinstance(d, mot.ReplayedDetector) for d in hog[1:])
    assert hog[1]._recorder is hog[2]._recorder is hog[0]
    assert trackers["ours"]._detector is None and ours["ours"].public
    assert ours["ours_hog_seed1"].details["seed"] == 1


def test_dpm_runs_at_its_tracking_operating_point(mot, tmp_path: Path) -> None:
    ours = mot.build_ours(["ours_dpm"], tmp_path / "none.mat")  # the model loads on first use
    assert ours["ours_dpm"].details["detector_options"] == dataclasses.asdict(DPM_TRACKING_CONFIG)
    args = mot.parse_args(["--dpm-config", '{"upscale": 1.3}'])  # fields over the preset
    assert args.dpm_config == dataclasses.replace(DPM_TRACKING_CONFIG, upscale=1.3)


def test_config_options_are_checked(mot) -> None:
    args = mot.parse_args(["--tracker-config", '{"report_missing": 0.6, "particles": 64}'])
    assert args.tracker_config == PeopleTrackerConfig(report_missing=0.6, particles=64)
    for bad in ('{"no_such_field": 1}', '{"particles": 1}', "[1]", "not json"):
        with pytest.raises(SystemExit):
            mot.parse_args(["--tracker-config", bad])
    with pytest.raises(SystemExit):
        mot.parse_args(["--dpm-config", '{"nms_criterion": "area"}'])


@pytest.mark.slow
def test_filled_gaps_add_rows_and_keep_the_tracked_ones(mot, shared_data: Path) -> None:
    from tqdm import tqdm

    from tracking.evaluation.mot import check_unique_ids, read_sequence_info

    sequence = read_sequence_info(shared_data / "mot" / "PETS09-S2L1")
    rows = {}
    for fill in (0.0, 1.0):
        (ours,) = mot.build_ours(["ours"], Path("none.mat"), fill_gaps=fill).values()
        assert ours.details["fill_gaps"] == fill
        with tqdm(disable=True) as bar:
            rows[fill], _, _ = mot.track_ours(ours, sequence, 60, bar, False)
    check_unique_ids(rows[1.0])
    tracked = {tuple(r) for r in rows[0.0]}
    filled = [r for r in rows[1.0] if tuple(r) not in tracked]
    assert tracked <= {tuple(r) for r in rows[1.0]}
    # on the public detections of these 60 frames (7 fps) tracks break and come back
    assert len(filled) >= 3
    assert all(r[0] < 60 for r in filled)
