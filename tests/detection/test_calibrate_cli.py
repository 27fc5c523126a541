"""The calibration command on a small MOTChallenge sequence made from PETS09-S2L1 frames."""

from __future__ import annotations

import shutil

import numpy as np
import pytest

from tracking.detection.calibrate import main
from tracking.detection.calibration import load_calibration
from tracking.detection.sequences import image_to_mot_boxes


@pytest.fixture
def small_sequence(tmp_path, pets):
    """Frames 1, 101, ..., 501 of PETS09-S2L1 renumbered 1..6, with their ground truth."""
    root = tmp_path / "PETS-small"
    (root / "img1").mkdir(parents=True)
    (root / "gt").mkdir()
    rows = []
    for new, old in enumerate(range(0, 600, 100), start=1):
        shutil.copy(pets.frames[old], root / "img1" / f"{new:06d}.jpg")
        for x, y, w, h in image_to_mot_boxes(pets.gt[old]):  # back to the file's 1-based pixels
            rows.append(f"{new},1,{x},{y},{w},{h},1,-1,-1,-1")
    (root / "gt" / "gt.txt").write_text("\n".join(rows) + "\n")
    return root


@pytest.mark.slow
def test_calibrate_the_embedded_detector(small_sequence, tmp_path, capsys):
    out = tmp_path / "hog.calibration.json"
    status = main(["--detector", "default", "--sequences", str(small_sequence), "--out", str(out)])
    assert status == 0, capsys.readouterr().err
    calibration = load_calibration(out)
    assert calibration.a > 0  # higher SVM scores are likelier people
    assert "PETS-small" in calibration.source
    # p rises across the detector's operating point
    assert calibration.probability(-0.5) < calibration.probability(1.0)
    assert np.isfinite(calibration.b)


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (["--detector", "dpm", "--sequences", "{seq}"], "needs --model"),
        (["--detector", "default", "--sequences", "{seq}"], "needs --out"),
        (["--detector", "default", "--sequences", "{tmp}/nothing", "--out", "x"], "not a MOT"),
        (["--detector", "dpm", "--model", "{tmp}/m.mat", "--sequences", "{seq}"], "not found"),
        (["--detector", "default", "--sequences", "{seq}", "--out", "{tmp}/typo/c.json"],
         "typo does not exist"),
    ],
)  # fmt: skip
def test_bad_arguments_exit_with_a_message_before_detecting(
    argv, message, small_sequence, tmp_path, capsys, caplog
):
    args = [a.format(seq=small_sequence, tmp=tmp_path) for a in argv]
    with caplog.at_level("INFO", logger="tracking.detection.calibrate"):
        assert main(args) == 2
    assert message in capsys.readouterr().err
    assert "done" not in caplog.text  # no sequence was run through the detector
