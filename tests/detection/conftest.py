"""Fixtures of the detection tests: the voc-release5 models and frames of the MOT sequences."""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
import pytest

from tracking.datasets.mot import MotSequence
from tracking.detection.dpm.model import DpmModel, load_dpm_model


@pytest.fixture(scope="session")
def inria_path(shared_data: Path) -> Path:
    return shared_data / "dpm" / "INRIA" / "inriaperson_final.mat"


@pytest.fixture(scope="session")
def voc_path(shared_data: Path) -> Path:
    return shared_data / "dpm" / "VOC2007" / "person_final.mat"


@pytest.fixture(scope="session")
def inria_model(inria_path: Path) -> DpmModel:
    return load_dpm_model(inria_path)


@pytest.fixture(scope="session")
def pets(shared_data: Path) -> MotSequence:
    return MotSequence.open(shared_data / "mot" / "PETS09-S2L1")


@pytest.fixture(scope="session")
def tud(shared_data: Path) -> MotSequence:
    return MotSequence.open(shared_data / "mot" / "TUD-Stadtmitte")


@pytest.fixture(scope="session")
def pets_frame(pets: MotSequence) -> np.ndarray:
    """Frame 1 of PETS09-S2L1 (0-based index 0): three people, 75-89 px tall."""
    return pets.read_frame(0)


@pytest.fixture
def opencv_threads():
    """Sets OpenCV's thread count for a test and restores it afterwards."""
    before = cv2.getNumThreads()
    yield cv2.setNumThreads
    cv2.setNumThreads(before)
