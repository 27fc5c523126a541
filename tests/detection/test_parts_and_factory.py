"""Part names from anchors, and building detectors by name or path."""

from __future__ import annotations

import pytest

from tracking.detection.dpm.detector import DpmDetector
from tracking.detection.dpm.parts import component_part_names, model_part_names
from tracking.detection.external import MotDetections, SubmittedDetections
from tracking.detection.factory import make_detector
from tracking.detection.hog_people import HogPeopleConfig, HogPeopleDetector


def test_inria_part_names(inria_model):
    original, mirrored = inria_model.components
    # anchors (ax, ay) in part cells of the 10 x 30 part grid: (2,0) top centre, (0,24) bottom
    # left, (4,5) upper right, (4,18) right at 70% height, (0,13) left middle, (0,6) upper left,
    # (4,12) right middle, (4,24) bottom right
    assert component_part_names(original) == (
        "head", "left_foot", "right_shoulder", "right_knee",
        "left_hip", "left_shoulder", "right_hip", "right_foot",
    )  # fmt: skip
    # the mirrored component's parts sit on the other side: names follow the image side
    assert component_part_names(mirrored) == (
        "head", "right_foot", "left_shoulder", "left_knee",
        "right_hip", "right_shoulder", "left_hip", "left_foot",
    )  # fmt: skip
    names, slots = model_part_names(inria_model)
    assert names == (
        "head", "left_shoulder", "right_shoulder", "left_hip", "right_hip",
        "left_knee", "right_knee", "left_foot", "right_foot",
    )  # fmt: skip
    for comp, comp_slots in zip(inria_model.components, slots, strict=True):
        assert [names[s] for s in comp_slots] == list(component_part_names(comp))


def test_factory(inria_path, pets):
    assert isinstance(make_detector("default"), HogPeopleDetector)
    assert isinstance(make_detector("hog", HogPeopleConfig(upscale=1.0)), HogPeopleDetector)
    assert isinstance(make_detector(inria_path), DpmDetector)
    assert isinstance(make_detector(pets.detections_file), MotDetections)
    assert isinstance(make_detector("submitted"), SubmittedDetections)


@pytest.mark.parametrize("name", ["yolo", "model.pt"])
def test_factory_rejects_unknown_detectors(name):
    with pytest.raises(ValueError, match="unknown detector"):
        make_detector(name)


def test_factory_rejects_a_config_of_the_wrong_kind(inria_path):
    with pytest.raises(ValueError, match="DpmConfig"):
        make_detector(inria_path, HogPeopleConfig())
