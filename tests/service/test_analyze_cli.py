"""`vtrack analyze`: the service's pipeline on a file, without a server."""

from __future__ import annotations

import json
import subprocess
import sys

import cv2
import jsonschema
import pytest
from mcap.reader import make_reader

from tests.conftest import REPO_ROOT
from tests.service.conftest import schema_for


def vtrack(*args):
    return subprocess.run(
        [sys.executable, "-m", "service.cli", *map(str, args)],
        capture_output=True,
        text=True,
        timeout=300,
        cwd=REPO_ROOT,
    )


@pytest.mark.slow
def test_analyze_writes_the_requested_results(pets_short, tmp_path):
    out = tmp_path / "out"
    result = vtrack("analyze", pets_short, "--out-dir", out, "--format", "json,mot,mp4")
    assert result.returncode == 0, result.stderr
    assert {p.name for p in out.iterdir()} == {
        "annotated.mp4",
        "trajectories.json",
        "tracks_mot.txt",
    }
    document = json.loads((out / "trajectories.json").read_text())
    jsonschema.validate(document, schema_for("Trajectories"))
    assert document["job_id"] is None and document["video"]["filename"] == pets_short.name
    assert document["frames_processed"] == 8
    assert cv2.VideoCapture(str(out / "annotated.mp4")).get(cv2.CAP_PROP_FRAME_COUNT) == 8
    assert "tracked 8 frames" in result.stderr


@pytest.mark.slow
def test_analyze_writes_jpeg_images_into_the_mcap_on_request(pets_short, tmp_path):
    names = {}
    for images in ("h264", "jpeg"):
        out = tmp_path / images
        arguments = ["--format", "mcap", "--mcap-images", images, "--quiet"]
        result = vtrack("analyze", pets_short, "--out-dir", out, *arguments)
        assert result.returncode == 0, result.stderr
        with (out / "tracks.mcap").open("rb") as handle:
            summary = make_reader(handle).get_summary()
        channel = next(c for c in summary.channels.values() if c.topic == "/camera/image")
        names[images] = summary.schemas[channel.schema_id].name
    assert names == {"h264": "foxglove.CompressedVideo", "jpeg": "foxglove.CompressedImage"}


def test_analyze_follows_one_box_every_other_frame(pets_short, tmp_path):
    out = tmp_path / "single"
    result = vtrack(
        "analyze",
        pets_short,
        "--out-dir",
        out,
        "--format",
        "json",
        "--box",
        "150,130,28,65",
        "--frame-step",
        "2",
        "--quiet",
        "--preset",
        "rcsk_gray",
    )
    assert result.returncode == 0, result.stderr
    document = json.loads((out / "trajectories.json").read_text())
    assert document["mode"] == "single_target" and document["frames_processed"] == 4
    (track,) = document["tracks"]
    assert [p["frame_index"] for p in track["frames"]] == [0, 2, 4, 6]
    assert track["frames"][0]["box"] == {"x": 150.0, "y": 130.0, "w": 28.0, "h": 65.0}


def test_analyze_takes_the_service_job_options_with_its_flags_over_them(pets_short, tmp_path):
    out = tmp_path / "out"
    options = {"frame_step": 2, "formats": ["json", "mot"], "tracker": {"report_missing": 0.15}}
    arguments = ["--options", json.dumps(options), "--format", "json", "--quiet"]
    result = vtrack("analyze", pets_short, "--out-dir", out, *arguments)
    assert result.returncode == 0, result.stderr
    assert [p.name for p in out.iterdir()] == ["trajectories.json"]  # --format won
    document = json.loads((out / "trajectories.json").read_text())
    assert document["frames_processed"] == 4  # every other frame of 8, from --options
    assert document["mode"] == "people"


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["--format", "json,avi"], "comma-separated list"),  # unknown format
        (["--frame-step", "0"], "--frame-step: Input should be greater than or equal to 1"),
        (["--upscale", "-1"], "--upscale: Input should be greater than 0"),
        (["--box", "1,1,-5,3"], "--box: Input should be greater than 0"),
        (["--box", "900,10,20,20"], "outside"),  # first box outside the frame
        (["--options", "{"], "--options: not JSON"),
        (["--options", "[1]"], "--options: a JSON object of job options"),
        (["--options", '{"trackr": {}}'], "--options: trackr: Extra inputs are not permitted"),
        (
            ["--options", '{"tracker": {"report_missing": -1}}'],
            "--options: tracker.report_missing: Input should be greater than or equal to 0",
        ),
        (  # the flag's value is the one refused, so the flag is named
            ["--options", '{"frame_step": 2}', "--frame-step", "0"],
            "--frame-step: Input should be greater than or equal to 1",
        ),
    ],
)
def test_analyze_rejects_bad_arguments(pets_short, tmp_path, args, message):
    result = vtrack("analyze", pets_short, "--out-dir", tmp_path / "o", *args)
    assert result.returncode == 2
    assert message in result.stderr
