"""Job options reach what runs: the DPM takes ``upscale`` and ``levels_per_octave``, tracker
options the tracker."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import cv2
import numpy as np
import pytest
from pydantic import ValidationError

from api_schemas.jobs import JobOptions
from service.frames import FrameSource
from service.pipelines import (
    OptionsError,
    PipelineResources,
    check_options,
    people_config,
    plan_detector,
)
from tests.service.conftest import PETS_VIDEO
from tracking.detection import DPM_TRACKING_CONFIG, box_iou
from tracking.people import PeopleTrackerConfig


@pytest.fixture(scope="module")
def resources(shared_data) -> PipelineResources:
    return PipelineResources(dpm_model=shared_data / "dpm" / "INRIA" / "inriaperson_final.mat")


def _confident_people(detections, people: np.ndarray) -> int:
    """Ground-truth people matched (IoU >= 0.5) by a detection of probability >= 0.9."""
    confident = detections.boxes[detections.probabilities >= 0.9]
    if not len(confident):
        return 0
    return int((box_iou(people, confident).max(axis=1) >= 0.5).sum())


def test_dpm_job_with_upscale_finds_small_people_with_parts(resources, shared_data):
    capture = cv2.VideoCapture(str(shared_data / PETS_VIDEO))
    ok, frame = capture.read()
    capture.release()
    assert ok
    frame = cv2.cvtColor(frame, cv2.COLOR_BGR2RGB)
    # Ground truth of the first frame, scaled to the 480x360 video: three people 47-55 px tall,
    # at the bottom of the model's smallest window (60 px at 1x).
    gt = np.loadtxt(shared_data / "mot" / "PETS09-S2L1" / "gt" / "gt.txt", delimiter=",")
    people = gt[gt[:, 0] == 1, 2:6] * 0.625
    people[:, :2] -= 1

    options = JobOptions.model_validate({"detector": {"name": "dpm", "upscale": 1.5}})
    enlarged = plan_detector(check_options(options, resources))
    assert enlarged.config == dataclasses.replace(DPM_TRACKING_CONFIG, upscale=1.5)
    plain = plan_detector(
        check_options(JobOptions.model_validate({"detector": {"name": "dpm"}}), resources)
    )
    assert plain.config == DPM_TRACKING_CONFIG  # the DPM's operating point for tracking
    found = enlarged.detect(frame)
    assert _confident_people(found, people) >= 2 > _confident_people(plain.detect(frame), people)
    assert "head" in found.part_names and np.isfinite(found.parts).any()


def test_dpm_job_without_a_model_is_refused():
    options = JobOptions.model_validate({"detector": {"name": "dpm", "upscale": 1.5}})
    with pytest.raises(OptionsError, match="VTRACK_DPM_MODEL"):
        check_options(options, PipelineResources())


def test_tracker_options_reach_the_tracker_configuration():
    options = JobOptions.model_validate(
        {"tracker": {"report_missing": 0.6, "confirm_hits": 2, "seed": 3}}
    )
    config = people_config(options, PipelineResources())
    assert (config.report_missing, config.confirm_hits, config.seed) == (0.6, 2, 3)
    assert check_options(options, PipelineResources()).people == config  # what the plan runs
    assert config.particles == PeopleTrackerConfig().particles  # unset: the default
    with pytest.raises(ValidationError, match="report_missing"):
        JobOptions.model_validate({"tracker": {"report_missing": -1}})


@pytest.mark.parametrize(
    ("size", "upscale", "refused"),
    [((3840, 2160), 2.0, False), ((3840, 2160), 2.01, True), ((1920, 1080), 4.0, False)],
)
def test_upscale_is_limited_to_an_8k_enlarged_frame(size, upscale, refused):
    options = JobOptions.model_validate({"detector": {"upscale": upscale}})
    video = FrameSource(Path("video.mp4"), 100, 25.0, width=size[0], height=size[1])
    if refused:
        with pytest.raises(OptionsError, match="use at most 2,"):
            check_options(options, PipelineResources(), video)
    else:
        check_options(options, PipelineResources(), video)


def test_dpm_job_with_fewer_pyramid_levels_still_finds_people(resources, shared_data):
    frame = cv2.imread(str(shared_data / "mot" / "PETS09-S2L1" / "img1" / "000100.jpg"))
    frame = cv2.cvtColor(frame, cv2.COLOR_BGR2RGB)
    gt = np.loadtxt(shared_data / "mot" / "PETS09-S2L1" / "gt" / "gt.txt", delimiter=",")
    people = gt[gt[:, 0] == 100, 2:6]
    people[:, :2] -= 1

    options = JobOptions.model_validate({"detector": {"name": "dpm", "levels_per_octave": 5}})
    coarse = plan_detector(check_options(options, resources))
    assert coarse.config == dataclasses.replace(DPM_TRACKING_CONFIG, levels_per_octave=5)
    assert coarse.interval == 5  # the model's own is 10
    found = coarse.detect(frame)
    assert _confident_people(found, people) >= len(people) - 1
    assert "head" in found.part_names and np.isfinite(found.parts).any()
