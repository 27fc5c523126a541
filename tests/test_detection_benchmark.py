"""The detection benchmark's detector names (``dpm-<model>[@upscale][:levels][>min][+exact]``,
``opencv-hog@<upscale>``, ``default@<upscale>``) and its resized sequences (``--height``)."""

from __future__ import annotations

import json

import numpy as np
import pytest

from tests.conftest import benchmark_module


@pytest.fixture(scope="module")
def detection():
    with benchmark_module("detection") as module:
        yield module


@pytest.mark.parametrize(
    "name, fields",
    [
        ("dpm-inria", {"cascade": True}),
        ("dpm-inria+exact", {"cascade": False}),
        ("dpm-inria>128", {"cascade": True, "min_height": 128.0}),
        ("dpm-voc2007@1.3:5", {"cascade": True, "upscale": 1.3, "levels_per_octave": 5}),
        ("dpm-inria@2:5>96+exact",
         {"cascade": False, "upscale": 2.0, "levels_per_octave": 5, "min_height": 96.0}),
    ],
)  # fmt: skip
def test_dpm_names_give_config_fields(detection, name, fields):
    model, parsed = detection.parse_dpm_name(name)
    assert model.endswith(".mat")
    assert parsed == fields


@pytest.mark.parametrize(
    "name",
    ["dpm-nomodel", "dpm-inria+fast", "dpm-inria@x", "dpm-", "dpm-inria@1..2", "dpm-inria@0",
     "dpm-inria:0", "dpm-inria>."],
)  # fmt: skip
def test_bad_dpm_names_are_refused(detection, name):
    with pytest.raises(SystemExit, match="detector name"):
        detection.parse_dpm_name(name)


@pytest.mark.parametrize("detector", ["opencv-hog", "default"])
def test_hog_names_give_their_scale(detection, detector):
    assert detection._upscale(f"{detector}@1", detector) == 1.0
    assert detection._upscale(f"{detector}@2.5", detector) == 2.5


@pytest.mark.parametrize("name", ["opencv-hog@", "opencv-hog@x", "opencv-hog@0", "opencv-hog@inf"])
def test_bad_hog_names_are_refused(detection, name):
    with pytest.raises(SystemExit, match="bad detector name"):
        detection._upscale(name, "opencv-hog")


@pytest.mark.slow
def test_height_resizes_frames_ground_truth_and_public_detections(detection, shared_data):
    """``--height 1080``: the PETS09-S2L1 scene as a 1440x1080 camera shows it."""
    args = detection.argparse.Namespace(sequences=["PETS09-S2L1"], data=shared_data, height=1080)
    (sequence,) = detection._sequences(args)
    source = sequence.source
    assert sequence.scale == pytest.approx(1080 / 576)
    assert sequence.read_frame(10).shape == (1080, 1440, 3)
    np.testing.assert_allclose(sequence.gt[10], source.gt[10] * 1080 / 576)
    public = detection.MotDetections.from_file(source.detections_file).for_frame(10)
    boxes, scores = sequence.public(10)
    np.testing.assert_allclose(boxes, public.boxes * 1080 / 576)
    np.testing.assert_array_equal(scores, public.scores)
    (native,) = detection._sequences(detection.argparse.Namespace(**{**vars(args), "height": None}))
    assert native.read_frame(10).shape == (576, 768, 3)


def _strict(constant: str) -> None:
    raise ValueError(f"not JSON: {constant}")


def test_json_report_is_strict_json_when_a_figure_is_missing(detection, shared_data, capsys):
    """The public detections have no time per frame: ``--json`` writes null, not NaN (which
    JavaScript's and most other parsers refuse)."""
    code = detection.main(
        ["--data", str(shared_data), "--sequences", "TUD-Stadtmitte", "--step", "30",
         "--detectors", "public", "--no-timing", "--picture", "", "--json"]
    )  # fmt: skip
    assert code == 0
    report = json.loads(capsys.readouterr().out, parse_constant=_strict)
    public = report["accuracy"]["TUD-Stadtmitte"]["public"]
    assert public["seconds_per_frame"] is None
    assert 0 < public["ap"] <= 1
