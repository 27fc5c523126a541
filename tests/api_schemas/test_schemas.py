"""The public models and their exported JSON Schema."""

from __future__ import annotations

import json
import subprocess
import sys

import jsonschema
import pytest
from pydantic import ValidationError

from api_schemas import JobOptions, Trajectories
from api_schemas.common import BoxModel
from api_schemas.export import SCHEMA_PATH, build_schema, render
from api_schemas.tracks import PartState, TrajectoryPoint
from tests.conftest import REPO_ROOT

BOX = {"x": 1, "y": 1, "w": 5, "h": 5}


def test_exported_schema_is_up_to_date():
    assert SCHEMA_PATH.read_text() == render(), (
        "api_schemas/schema.json is out of date: run python -m api_schemas.export"
    )


def test_export_command_checks_the_file(tmp_path):
    stale = tmp_path / "schema.json"
    stale.write_text("{}\n")
    command = [sys.executable, "-m", "api_schemas.export", "--out", str(stale)]
    check = subprocess.run([*command, "--check"], cwd=REPO_ROOT, capture_output=True, text=True)
    assert check.returncode == 1 and "out of date" in check.stderr
    assert subprocess.run(command, cwd=REPO_ROOT, capture_output=True).returncode == 0
    assert json.loads(stale.read_text()) == build_schema()
    check = subprocess.run([*command, "--check"], cwd=REPO_ROOT, capture_output=True)
    assert check.returncode == 0


def test_default_options_and_their_schema_agree():
    schema = {**build_schema(), "$ref": "#/$defs/JobOptions"}
    defaults = JobOptions().model_dump(mode="json")
    jsonschema.validate(defaults, schema)
    assert defaults["formats"] == ["json", "mcap", "mot", "mp4"] and defaults["mode"] == "people"


@pytest.mark.parametrize(
    ("options", "message"),
    [
        ({"colour": "red"}, "Extra inputs are not permitted"),  # unknown field
        ({"detector": {"name": "yolo"}}, "'default' or 'dpm'"),  # unknown detector
        ({"frame_step": 0}, "greater than or equal to 1"),  # no frame would be tracked
        ({"formats": []}, "at least 1 item"),  # nothing to write
        ({"formats": ["json", "json"]}, "must not repeat"),  # a format twice
        # images of an mcap not written, which was ignored
        ({"formats": ["json"], "mcap_images": "jpeg"}, "only with the mcap format"),
        ({"mode": "single_target"}, "needs first_box"),  # single target without its box
        ({"first_box": {"x": 1, "y": 1, "w": 5, "h": 5}}, "only for mode 'single_target'"),
        # an option of the other mode, which was ignored
        ({"preset": "rcsk_cn"}, "only for mode 'single_target'"),
        (
            {"mode": "single_target", "first_box": BOX, "detector": {"upscale": 2}},
            "only for mode 'people'",
        ),
        ({"mode": "single_target", "first_box": BOX, "tracker": {"particles": 50}}, "'people'"),
        ({"mode": "single_target", "first_box": BOX, "fill_gaps": 1}, "never dropped"),
        # an empty box, a negative or sub-pixel size: one sentence (was pydantic's "greater
        # than 0" for 0 and "at least 1 pixel" for 0.5, from the job's own check)
        *(
            (
                {"mode": "single_target", "first_box": {"x": 1, "y": 1, "w": w, "h": 5}},
                "first_box\n.*width and height must be at least 1 pixel",
            )
            for w in (0, -3, 0.5)
        ),
    ],
)
def test_invalid_options_are_rejected(options, message):
    with pytest.raises(ValidationError, match=message):
        JobOptions.model_validate(options)


def test_an_option_of_the_other_mode_is_refused_where_it_was_given():
    # its default, given explicitly, changes nothing and passes
    JobOptions.model_validate(
        {"mode": "single_target", "first_box": BOX, "detector": {}, "fill_gaps": 0}
    )
    # the preset's former default in every mode, as earlier people jobs' statuses show it
    for former in ("hog_cn_scale", "strcf_hog_cn"):  # the default before issue 77, and now
        people = JobOptions.model_validate({"preset": former, "tracker": {"particles": 50}})
        assert people.preset is None  # before: the preset, for a job that uses none
    assert JobOptions.model_validate({"mode": "single_target", "first_box": BOX}).preset == (
        "strcf_hog_cn"
    )
    with pytest.raises(ValidationError) as caught:
        JobOptions.model_validate({"mode": "single_target", "first_box": BOX, "fill_gaps": 1})
    assert [e["loc"] for e in caught.value.errors()] == [("fill_gaps",)]


def test_trajectories_reject_scores_outside_unit_interval():
    point = {
        "frame_index": 0,
        "timestamp": 0.0,
        "box": {"x": 0, "y": 0, "w": 1, "h": 1},
        "score": 1.5,
        "occluded": False,
    }
    document = {
        "vtrack_version": "0.1.0",
        "options": {},
        "mode": "people",
        "video": {
            "width": 4,
            "height": 4,
            "frames_announced": 1,
            "frames_read": 1,
            "frame_step": 1,
        },
        "part_names": [],
        "frames_processed": 1,
        "tracks": [{"track_id": 1, "frames": [point]}],
    }
    with pytest.raises(ValidationError, match="less than or equal to 1"):
        Trajectories.model_validate(document)
    point["score"] = 0.5
    Trajectories.model_validate(document)


@pytest.mark.parametrize("value", [float("nan"), float("inf")])
def test_coordinates_must_be_finite(value):
    # was accepted, then written as null, which the same models could not read back
    with pytest.raises(ValidationError, match="finite number"):
        BoxModel(x=value, y=0, w=1, h=1)
    with pytest.raises(ValidationError, match="finite number"):
        PartState(name="head", x=value, y=0, visible=True)


def test_results_are_written_to_the_precision_a_tracker_has():
    # 17 digits per float made an hour's trajectories hundreds of MB
    point = TrajectoryPoint(
        frame_index=3,
        timestamp=0.30000000000000004,
        box=BoxModel(x=311.2019680793346, y=101.25390787006302, w=18.36181, h=0.01),
        score=0.9998441028312726,
        occluded=False,
        parts=[PartState(name="head", x=320.3828734479729, y=-3.825811, visible=True)],
    )
    written = json.loads(point.model_dump_json())
    assert written["timestamp"] == 0.3
    assert written["box"] == {"x": 311.2, "y": 101.25, "w": 18.36, "h": 0.01}
    assert written["score"] == 0.9998
    assert (written["parts"][0]["x"], written["parts"][0]["y"]) == (320.38, -3.83)
    assert point.model_dump(mode="json")["box"]["x"] == 311.2  # both JSON dumps
    assert point.box.x == 311.2019680793346  # the model keeps the value
    assert TrajectoryPoint.model_validate(written).box.h == 0.01  # and reads its JSON back
