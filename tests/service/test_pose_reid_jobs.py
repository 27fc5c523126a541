"""The pose and re-identification networks in the service: job options ``tracker.pose`` and
``tracker.reid`` (unset: on when the service has the model), the results and /readyz saying what
runs, the settings that name the networks, and ``vtrack analyze``'s flags."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import pytest

from service.models.catalog import CATALOG, DEFAULT_DETECTOR, DEFAULT_POSE, DEFAULT_REID
from tests.service.conftest import error_of, submit, wait_for_state
from tests.service.test_analyze_cli import vtrack
from tests.service.test_cnn_jobs import _result, models_folder

KEYPOINTS = [
    "nose",
    "neck",
    "right_shoulder",
    "right_elbow",
    "right_wrist",
    "left_shoulder",
    "left_elbow",
    "left_wrist",
    "right_hip",
    "right_knee",
    "right_ankle",
    "left_hip",
    "left_knee",
    "left_ankle",
    "right_eye",
    "left_eye",
    "right_ear",
    "left_ear",
]
"""The parts of tracks measured by the pose network (written out: the API's promise)."""

DEFAULTS = (DEFAULT_POSE, DEFAULT_REID)


def add_models(shared_data: Path, folder: Path, *names: str) -> Path:
    """``folder`` with the files of the catalog models ``names`` copied from the reference
    data, laid out as `vtrack models fetch` lays them out."""
    for name in names:
        for file in CATALOG[name].files:
            (folder / file.path).parent.mkdir(parents=True, exist_ok=True)
            shutil.copy(shared_data / "models" / file.path, folder / file.path)
    return folder


def graph(folder: Path, name: str) -> Path:
    return folder / CATALOG[name].graph


@pytest.fixture(scope="module")
def networks_server(tmp_path_factory, shared_data):
    """A service whose models folder has the detector, the pose and the re-identification
    networks (their defaults)."""
    from devtools.testing import Server

    root = tmp_path_factory.mktemp("networks")
    models = add_models(shared_data, models_folder(shared_data, root / "models"), *DEFAULTS)
    server = Server(root / "data", workers=1, models_dir=models).start()
    yield server
    server.stop()


@pytest.mark.slow
def test_jobs_run_pose_and_reid_when_the_service_has_them_and_the_results_say_so(
    networks_server, pets_cut, pets_short
):
    with networks_server.client() as client:
        ready = client.get("/readyz").json()
        assert ready["pose"] == {"model": DEFAULT_POSE}
        assert ready["reid"] == {"model": DEFAULT_REID}
        default = submit(client, pets_cut, {"formats": ["json"]})
        assert default.status_code == 202, default.text
        without_pose = submit(client, pets_short, {"formats": ["json"], "tracker": {"pose": False}})
        assert without_pose.status_code == 202, without_pose.text

        status = wait_for_state(client, default.json()["id"], ("succeeded", "failed"))
        assert status["state"] == "succeeded", status
        assert status["warnings"] == []
        result = json.loads(_result(client, status, "json"))
        tracker = result["options"]["tracker"]
        assert (tracker["pose"], tracker["pose_model"]) == (True, DEFAULT_POSE)
        assert (tracker["reid"], tracker["reid_model"]) == (True, DEFAULT_REID)
        assert result["part_names"] == KEYPOINTS
        parts = [part for track in result["tracks"] for f in track["frames"] for part in f["parts"]]
        assert parts and {part["name"] for part in parts} <= set(KEYPOINTS)
        # the clip's people are in plain view: the network places many of their keypoints
        assert sum(part["measured"] for part in parts) >= 0.4 * len(parts)
        # the status keeps the options as sent
        assert status["options"]["tracker"]["pose"] is None

        status = wait_for_state(client, without_pose.json()["id"], ("succeeded", "failed"))
        assert status["state"] == "succeeded", status
        result = json.loads(_result(client, status, "json"))
        tracker = result["options"]["tracker"]
        assert (tracker["pose"], tracker["pose_model"]) == (False, None)
        assert (tracker["reid"], tracker["reid_model"]) == (True, DEFAULT_REID)
        assert result["part_names"][:3] == ["head", "left_shoulder", "right_shoulder"]


def test_options_naming_a_network_are_refused_unless_it_can_run(networks_server, pets_short):
    with networks_server.client() as client:
        # options the service cannot run: the sentence says what to do
        cases = {
            # a catalog model the folder lacks: the command that fetches it
            "vtrack models fetch person-reidentification-retail-0288 --dir": {
                "reid": True,
                "reid_model": "person-reidentification-retail-0288",
            },
            "is a person-detection model": {"pose": True, "pose_model": "person-detection-0202"},
        }
        for expected, tracker in cases.items():
            response = submit(client, pets_short, {"formats": ["json"], "tracker": tracker})
            assert expected in error_of(response, "invalid_options")["detail"], tracker
        # options the schema refuses: the failed check's place
        cases = {
            "pose_model": {"pose_model": DEFAULT_POSE},  # only with pose true
            "reid_model": {"reid": True, "reid_model": "a/../../x.xml"},  # outside the folder
        }
        for field, tracker in cases.items():
            response = submit(client, pets_short, {"formats": ["json"], "tracker": tracker})
            checks = error_of(response, "validation_error")["errors"]
            assert [e["loc"] for e in checks] == [["options", "tracker", field]], tracker
        # the tracker's options belong to mode people
        single = {"mode": "single_target", "first_box": {"x": 10, "y": 10, "w": 20, "h": 40}}
        response = submit(client, pets_short, {**single, "tracker": {"reid": False}})
        checks = error_of(response, "validation_error")["errors"]
        assert [e["loc"] for e in checks] == [["options", "tracker"]]


def test_a_network_asked_for_on_a_service_without_its_model_is_refused(
    make_server, shared_data, tmp_path, pets_short
):
    models = add_models(shared_data, tmp_path / "models", DEFAULT_POSE)  # pose only
    server = make_server(workers=1, models_dir=models)
    with server.client() as client:
        ready = client.get("/readyz").json()
        assert ready["pose"] == {"model": DEFAULT_POSE} and ready["reid"] is None
        response = submit(client, pets_short, {"formats": ["json"], "tracker": {"reid": True}})
        detail = error_of(response, "invalid_options")["detail"]
        assert "VTRACK_REID_MODEL" in detail, detail
        assert f"vtrack models fetch {DEFAULT_REID} --dir {models}" in detail, detail


def test_the_settings_name_the_networks_and_jobs_resolve_them(shared_data, tmp_path):
    from api_schemas.jobs import JobOptions, PeopleTrackerOptions
    from api_schemas.streams import StreamSpec
    from service.pipelines import (
        OptionsError,
        PipelineResources,
        check_options,
        choose_networks,
    )
    from service.settings import Settings
    from service.streams.worker import job_options

    models = add_models(shared_data, tmp_path / "models", *DEFAULTS)
    settings = Settings(models_dir=models, inference_threads=1)
    assert settings.pose_model_path == graph(models, DEFAULT_POSE)
    assert settings.reid_model_path == graph(models, DEFAULT_REID)
    resources = PipelineResources.from_settings(settings)
    assert (resources.pose_model, resources.reid_model) == (
        graph(models, DEFAULT_POSE),
        graph(models, DEFAULT_REID),
    )
    other = shared_data / "models" / CATALOG["person-reidentification-retail-0288"].graph
    assert Settings(models_dir=models, reid_model=str(other)).reid_model_path == other
    assert Settings().pose_model_path is None and Settings().reid_model_path is None
    # a folder without them is no error: the jobs run without them
    empty = tmp_path / "empty"
    empty.mkdir()
    bare = PipelineResources.from_settings(Settings(models_dir=empty))
    assert not bare.pose_model.is_file() and not bare.reid_model.is_file()
    tracker = choose_networks(PeopleTrackerOptions(), bare).tracker
    assert (tracker.pose, tracker.reid) == (False, False)
    # named but not there, of another task, or not such a network: the start stops, naming it
    with pytest.raises(ValueError, match="VTRACK_REID_MODEL 'person-reidentification-retail-0288'"):
        Settings(models_dir=models, reid_model="person-reidentification-retail-0288")
    with pytest.raises(ValueError, match="VTRACK_POSE_MODEL 'person-detection-0202' is a person"):
        Settings(models_dir=models, pose_model="person-detection-0202")
    with pytest.raises(ValueError, match=r"VTRACK_POSE_MODEL: .* is not an OpenPose network"):
        Settings(pose_model=str(other))
    with pytest.raises(ValueError, match="is set but empty"):
        Settings(reid_model=" ")
    # what a job and a stream run, as their results say it
    options = check_options(JobOptions(tracker={"reid": False}), resources).options
    assert (options.tracker.pose, options.tracker.pose_model) == (True, DEFAULT_POSE)
    assert (options.tracker.reid, options.tracker.reid_model) == (False, None)
    assert check_options(options, resources).options == options  # the results' options rerun
    streamed = check_options(job_options(StreamSpec(camera="gate")), resources).options.tracker
    assert (streamed.pose, streamed.reid) == (True, True)
    # asked for on a service without any models folder: the setting and the command
    with pytest.raises(OptionsError, match="VTRACK_REID_MODEL") as refused:
        check_options(JobOptions(tracker={"reid": True}), PipelineResources())
    assert f"vtrack models fetch {DEFAULT_REID} --dir DIR" in str(refused.value)


@pytest.mark.slow
def test_analyze_runs_the_networks_of_its_flags(pets_short, shared_data, tmp_path):
    pose = shared_data / "models" / CATALOG[DEFAULT_POSE].graph
    out = tmp_path / "out"
    args = ("analyze", pets_short, "--out-dir", out, "--format", "json", "--upscale", "1.0")
    result = vtrack(*args, "--pose-model", pose)
    assert result.returncode == 0, result.stderr
    assert f"and the pose network {DEFAULT_POSE}" in result.stderr
    document = json.loads((out / "trajectories.json").read_text())
    assert document["part_names"] == KEYPOINTS
    assert document["options"]["tracker"]["reid"] is False  # no models folder: none
    # a file that is no re-identification network stops the command before it starts
    result = vtrack(*args, "--reid-model", pose)
    assert result.returncode == 2, result.stderr
    assert "--reid-model" in result.stderr and "re-identification" in result.stderr


@pytest.mark.slow
def test_a_network_damaged_while_the_service_runs_fails_its_jobs_only(
    make_server, tmp_path, shared_data, pets_short
):
    models = add_models(shared_data, models_folder(shared_data, tmp_path / "models"), *DEFAULTS)
    server = make_server(workers=1, models_dir=models)
    weights = graph(models, DEFAULT_REID).with_suffix(".bin")
    weights.write_bytes(weights.read_bytes()[:1000])  # after the start: the worker meets it
    with server.client() as client:
        response = submit(client, pets_short, {"formats": ["json"]})
        status = wait_for_state(client, response.json()["id"], ("succeeded", "failed"))
        assert status["state"] == "failed"
        assert DEFAULT_REID in status["error"], status["error"]
        # the service goes on: a job without re-identification runs
        options = {"formats": ["json"], "tracker": {"reid": False}}
        response = submit(client, pets_short, options)
        status = wait_for_state(client, response.json()["id"], ("succeeded", "failed"))
        assert status["state"] == "succeeded", status


def test_cnn_jobs_keep_the_detections_box_shape(shared_data, tmp_path):
    """The CNN's boxes fit the people: its tracks report their aspect; the embedded detector's
    are padded: its tracks have the pedestrian aspect 0.41."""
    from api_schemas.jobs import JobOptions
    from service.pipelines import PipelineResources, build_pipeline, check_options

    models = models_folder(shared_data, tmp_path / "models")
    resources = PipelineResources(models_dir=models, cnn_model=graph(models, DEFAULT_DETECTOR))
    plan = check_options(JobOptions(), resources)
    assert plan.people is not None and plan.people.box_aspect is None
    cnn = build_pipeline(plan)
    embedded = build_pipeline(check_options(JobOptions(detector={"name": "default"}), resources))
    assert cnn._tracker.config.box_aspect is None
    assert embedded._tracker.config.box_aspect == 0.41
