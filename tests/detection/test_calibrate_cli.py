"""The calibration command on a small MOTChallenge sequence made from PETS09-S2L1 frames."""

from __future__ import annotations

import json
import shutil

import numpy as np
import pytest

from devtools.calibrate import main
from tracking.datasets.mot import image_to_mot_boxes
from tracking.detection.calibration import load_calibration


@pytest.fixture(scope="module")
def cnn_model(shared_data):
    """The product's CNN person detector (an OpenVINO IR in the read-only shared folder)."""
    return shared_data / "models" / "person-detection-0202" / "FP16" / "person-detection-0202.xml"


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


def test_calibrate_a_cnn(small_sequence, cnn_model, tmp_path, capsys):
    """Frames 1 and 301 of PETS09-S2L1: the network's logit, its confidence's log-odds, is
    mapped to rising probabilities."""
    out = tmp_path / "cnn.calibration.json"
    argv = ["--detector", "cnn", "--model", str(cnn_model), "--sequences", str(small_sequence),
            "--step", "3", "--out", str(out)]  # fmt: skip
    status = main(argv)
    assert status == 0, capsys.readouterr().err
    calibration = load_calibration(out)
    assert calibration.a > 0
    assert "person-detection-0202.xml, confidence >= 0.05" in calibration.source
    assert "PETS-small (1 frame in 3)" in calibration.source
    logit = np.log(np.array([0.1, 0.5, 0.9]) / (1 - np.array([0.1, 0.5, 0.9])))
    assert np.all(np.diff(calibration.probability(logit)) > 0)
    assert json.loads(out.read_text())["type"] == "logistic"


def test_a_cnn_in_a_read_only_folder_needs_out(small_sequence, cnn_model, tmp_path, capsys):
    """The shared model folder is read-only (root could write into it all the same): the
    default output beside the model is refused with a hint, before any frame is detected."""
    folder = tmp_path / "models"
    folder.mkdir()
    for suffix in (".xml", ".bin"):
        shutil.copy(cnn_model.with_suffix(suffix), folder)
    folder.chmod(0o555)
    try:
        argv = ["--detector", "cnn", "--model", str(folder / cnn_model.name),
                "--sequences", str(small_sequence)]  # fmt: skip
        assert main(argv) == 2
    finally:
        folder.chmod(0o755)
    err = capsys.readouterr().err
    assert "is read-only; pass --out PATH" in err
    assert not list(folder.glob("*.json"))


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (["--detector", "dpm", "--sequences", "{seq}"], "needs --model"),
        (["--detector", "cnn", "--sequences", "{seq}"], "needs --model PATH (.xml or .onnx)"),
        (["--detector", "cnn", "--model", "{tmp}/m.mat", "--sequences", "{seq}"],
         "not a CNN model file"),
        (["--detector", "cnn", "--model", "{tmp}/m.xml", "--sequences", "{seq}"],
         "cannot read the CNN model"),
        (["--detector", "cnn", "--model", "{model}", "--sequences", "{seq}", "--upscale", "2"],
         "--upscale is not a CNN option"),
        (["--detector", "cnn", "--model", "{model}", "--sequences", "{seq}",
          "--out", "{tmp}/typo/c.json"], "typo does not exist"),
        (["--detector", "default", "--sequences", "{seq}"], "needs --out"),
        (["--detector", "default", "--sequences", "{tmp}/nothing", "--out", "x"], "not a MOT"),
        (["--detector", "dpm", "--model", "{tmp}/m.mat", "--sequences", "{seq}"], "not found"),
        (["--detector", "default", "--sequences", "{seq}", "--out", "{tmp}/typo/c.json"],
         "typo does not exist"),
    ],
)  # fmt: skip
def test_bad_arguments_exit_with_a_message_before_detecting(
    argv, message, small_sequence, cnn_model, tmp_path, capsys, caplog
):
    args = [a.format(seq=small_sequence, tmp=tmp_path, model=cnn_model) for a in argv]
    with caplog.at_level("INFO", logger="devtools.calibrate"):
        assert main(args) == 2
    assert message in capsys.readouterr().err
    assert "done" not in caplog.text  # no sequence was run through the detector
