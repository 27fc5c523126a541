"""``benchmarks/resize_sequence.py``: a MOTChallenge sequence as a camera of another resolution
shows it, readable by the same readers as the original."""

from __future__ import annotations

import numpy as np
import pytest

from tests.conftest import benchmark_module
from tracking.datasets.mot import MotSequence
from tracking.detection import MotDetections


@pytest.fixture(scope="module")
def resize():
    with benchmark_module("resize_sequence") as module:
        yield module


@pytest.mark.slow
def test_frames_ground_truth_and_detections_scale_together(resize, shared_data, tmp_path):
    source = shared_data / "mot" / "TUD-Stadtmitte"
    destination = tmp_path / "TUD-240"
    assert resize.main([str(source), str(destination), "--height", "240"]) == 0

    original, resized = MotSequence.open(source), MotSequence.open(destination)
    assert len(resized) == len(original)
    assert resized.read_frame(0).shape == (240, 320, 3)
    for index in (0, 90, 178):
        # 0-based boxes scale by the factor (here 0.5), to the 3 decimals written
        np.testing.assert_allclose(resized.gt[index], original.gt[index] * 0.5, atol=1e-3)
    before = MotDetections.from_file(original.detections_file).for_frame(50)
    after = MotDetections.from_file(resized.detections_file).for_frame(50)
    np.testing.assert_allclose(after.boxes, before.boxes * 0.5, atol=1e-3)
    np.testing.assert_allclose(after.scores, before.scores, atol=1e-5)
    info = (destination / "seqinfo.ini").read_text()
    assert "imWidth = 320" in info and "imHeight = 240" in info and "frameRate = 25" in info


def test_an_existing_destination_is_refused(resize, tmp_path, capsys):
    with pytest.raises(SystemExit):
        resize.main([str(tmp_path), str(tmp_path), "--height", "240"])
    assert "exists" in capsys.readouterr().err
