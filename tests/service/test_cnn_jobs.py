"""The CNN detector in the service: detector 'auto' with and without a model, 'cnn' end to end
on the PETS clip, the detector named in the results and in /readyz, and model files that are
not models (refused at start, or failing the one job that meets them)."""

from __future__ import annotations

import io
import json
import shutil
from pathlib import Path

import pytest
from mcap.reader import make_reader

from service.pipelines import NO_CNN_WARNING
from service.streams.keys import StreamKeys
from service.streams.session import ZenohOptions
from service.streams.tools import member_session, publish_frames, video_frames
from tests.service.conftest import (
    FAST_OPTIONS,
    PETS_VIDEO,
    error_of,
    submit,
    wait_for,
    wait_for_state,
)
from tests.service.test_analyze_cli import vtrack

DEFAULT_MODEL = Path("person-detection-0202") / "FP16"


def models_folder(shared_data: Path, target: Path) -> Path:
    """A models folder as `vtrack models fetch` lays it out, with the default model's files
    copied from the reference data."""
    (target / DEFAULT_MODEL).mkdir(parents=True)
    for source in (shared_data / "models" / DEFAULT_MODEL).iterdir():
        shutil.copy(source, target / DEFAULT_MODEL / source.name)
    return target


def _result(client, status: dict, fmt: str) -> bytes:
    response = client.get(status["links"]["results"][fmt])
    assert response.status_code == 200, response.text
    return response.content


@pytest.fixture(scope="module")
def cnn_server(tmp_path_factory, shared_data):
    from devtools.testing import Server

    root = tmp_path_factory.mktemp("cnn")
    models = models_folder(shared_data, root / "models")
    server = Server(root / "data", workers=1, models_dir=models).start()
    yield server
    server.stop()


@pytest.mark.slow
def test_auto_runs_the_cnn_and_the_results_say_so(cnn_server, pets_cut):
    with cnn_server.client() as client:
        ready = client.get("/readyz").json()
        assert ready["detector"] == {
            "name": "cnn",
            "model": "person-detection-0202",
            "warning": None,
        }
        response = submit(client, pets_cut, {"formats": ["json", "mcap"]})
        assert response.status_code == 202, response.text
        status = wait_for_state(client, response.json()["id"], ("succeeded", "failed"))
        assert status["state"] == "succeeded", status
        assert status["warnings"] == []
        result = json.loads(_result(client, status, "json"))
        assert result["options"]["detector"]["name"] == "cnn"
        assert result["options"]["detector"]["model"] == "person-detection-0202"
        # the clip's people walk through the middle of the scene: the CNN finds them at 360 px
        assert len(result["tracks"]) >= 3
        mcap = _result(client, status, "mcap")
        metadata = next(make_reader(io.BytesIO(mcap)).iter_metadata()).metadata
        assert json.loads(metadata["options"])["detector"] == result["options"]["detector"]


@pytest.mark.slow
def test_a_live_stream_tracks_with_the_cnn_and_its_status_says_so(cnn_server, shared_data):
    from tests.streams.live import Follower, all_taken, start_stream, status

    session = member_session(ZenohOptions(listen=cnn_server.zenoh_listen))
    try:
        with cnn_server.client() as client:
            start_stream(client, session, "cnn_gate", record=True)
            shown = status(client, "cnn_gate")
            assert shown["detector"]["name"] == "cnn" and shown["detector_warning"] is None
            assert shown["detector"]["model"] == "person-detection-0202"
            assert shown["spec"]["detector"]["name"] == "auto"  # as it was asked for
            # the folder has no pose or re-identification model: the tracker runs without
            assert (shown["tracker"]["pose"], shown["tracker"]["reid"]) == (False, False)
            follower = Follower(session, StreamKeys("vtrack", "cnn_gate"))
            frames, _ = video_frames(str(shared_data / PETS_VIDEO))
            publish_frames(session, StreamKeys("vtrack", "cnn_gate"), frames, 10.0, limit=30)
            # a busy machine's worker skips frames (the newest is tracked): one message per
            # frame tracked, however many that was
            tracked = all_taken(client, "cnn_gate", 30)["frames_processed"]
            assert tracked >= 10, "most frames skipped"
            messages = wait_for(
                lambda: len(follower.received()) >= tracked and follower.received(),
                30,
                "the tracks",
            )
            assert any(m.tracks for m in messages), "nobody tracked in 3 s of PETS09-S2L1"
            assert {m.detections for m in messages} == {"service"}
            follower.close()
            # the recording says what ran, as a job's results do
            stopped = client.delete("/v1/streams/cnn_gate").json()
            recording = wait_for(
                lambda: status(client, "cnn_gate")["recordings"], 30, "a recording"
            )
            mcap = client.get(recording[0]).content
            metadata = next(make_reader(io.BytesIO(mcap)).iter_metadata()).metadata
            assert json.loads(metadata["options"])["detector"]["name"] == "cnn", stopped
    finally:
        session.close()


@pytest.mark.slow
def test_a_cnn_job_can_name_a_model_of_the_folder(cnn_server, pets_short):
    with cnn_server.client() as client:
        options = {
            "formats": ["json"],
            "detector": {"name": "cnn", "model": "person-detection-0200"},
        }
        response = submit(client, pets_short, options)
        detail = error_of(response, "invalid_options")["detail"]
        assert "person-detection-0200" in detail and "vtrack models fetch" in detail
        options["detector"]["model"] = (
            "../models/person-detection-0202/FP16/person-detection-0202.xml"
        )
        error_of(submit(client, pets_short, options), "validation_error")
        options["detector"]["model"] = "person-detection-0202/FP16/person-detection-0202.xml"
        response = submit(client, pets_short, options)
        assert response.status_code == 202, response.text
        status = wait_for_state(client, response.json()["id"], ("succeeded", "failed"))
        assert status["state"] == "succeeded", status


def test_without_a_model_auto_runs_the_embedded_detector_and_says_how_to_get_one(
    make_server, pets_short
):
    server = make_server(workers=1)
    with server.client() as client:
        ready = client.get("/readyz").json()
        assert ready["detector"]["name"] == "default"
        assert "vtrack models fetch" in ready["detector"]["warning"]
        # FAST_OPTIONS name the embedded detector: 'auto' here
        response = submit(client, pets_short, {"formats": ["json"], "detector": {"upscale": 1.0}})
        status = wait_for_state(client, response.json()["id"], ("succeeded", "failed"))
        assert status["state"] == "succeeded", status
        assert NO_CNN_WARNING in status["warnings"]
        result = json.loads(_result(client, status, "json"))
        assert result["options"]["detector"]["name"] == "default"
        # a stream says what it runs, and what that costs
        created = client.post("/v1/streams", json={"camera": "hog_gate"})
        assert created.status_code == 201, created.text
        shown = client.get("/v1/streams/hog_gate").json()
        assert shown["detector"]["name"] == "default"
        assert shown["detector_warning"] == NO_CNN_WARNING
        # asking for the CNN by name is refused before the upload is kept
        response = submit(client, pets_short, {"detector": {"name": "cnn"}})
        detail = error_of(response, "invalid_options")["detail"]
        assert "VTRACK_MODELS_DIR" in detail and "vtrack models fetch" in detail


def test_a_model_file_that_is_no_model_stops_the_start_with_a_reason(make_server, tmp_path):
    broken = tmp_path / "broken.xml"
    broken.write_text("<net>not a network")
    broken.with_suffix(".bin").write_bytes(b"\0" * 64)
    with pytest.raises(RuntimeError, match="exited early") as failed:
        make_server(cnn_model=broken)
    assert "VTRACK_CNN_MODEL" in str(failed.value) and "not a model OpenVINO can read" in str(
        failed.value
    )


@pytest.mark.slow
def test_a_model_damaged_while_the_service_runs_fails_its_jobs_only(
    make_server, tmp_path, shared_data, pets_short
):
    models = models_folder(shared_data, tmp_path / "models")
    server = make_server(workers=1, models_dir=models)
    weights = models / DEFAULT_MODEL / "person-detection-0202.bin"
    weights.write_bytes(weights.read_bytes()[:1000])  # after the start: the worker meets it
    with server.client() as client:
        response = submit(client, pets_short, {"formats": ["json"]})
        status = wait_for_state(client, response.json()["id"], ("succeeded", "failed"))
        assert status["state"] == "failed"
        assert "person-detection-0202" in status["error"], status["error"]
        # the service goes on: the embedded detector still runs
        response = submit(
            client, pets_short, {**FAST_OPTIONS, "detector": {"name": "default", "upscale": 1.0}}
        )
        status = wait_for_state(client, response.json()["id"], ("succeeded", "failed"))
        assert status["state"] == "succeeded", status


@pytest.mark.slow
def test_analyze_runs_the_cnn_of_the_models_folder_or_of_its_flag(
    pets_short, shared_data, tmp_path
):
    models = models_folder(shared_data, tmp_path / "models")
    out = tmp_path / "auto"
    result = vtrack(
        "analyze",
        pets_short,
        "--out-dir",
        out,
        "--format",
        "json",
        env={"VTRACK_MODELS_DIR": str(models)},
    )
    assert result.returncode == 0, result.stderr
    assert "with the CNN detector person-detection-0202" in result.stderr
    assert "warning" not in result.stderr
    options = json.loads((out / "trajectories.json").read_text())["options"]
    assert options["detector"]["name"] == "cnn"
    yolox = shared_data / "models" / "yolox-nano" / "yolox_nano.onnx"
    result = vtrack(
        "analyze",
        pets_short,
        "--out-dir",
        tmp_path / "yolox",
        "--format",
        "json",
        "--cnn-model",
        yolox,
    )
    assert result.returncode == 0, result.stderr
    assert "with the CNN detector yolox_nano" in result.stderr
    # without a model: the embedded detector, and the warning says how to get the model
    result = vtrack("analyze", pets_short, "--out-dir", tmp_path / "none", "--format", "json")
    assert result.returncode == 0, result.stderr
    assert "vtrack models fetch" in result.stderr and "embedded detector" in result.stderr
    # a network that is none stops the command before it starts, naming the flag
    broken = tmp_path / "broken.onnx"
    broken.write_bytes(b"not a network")
    result = vtrack("analyze", pets_short, "--out-dir", tmp_path / "bad", "--cnn-model", broken)
    assert result.returncode == 2 and "--cnn-model" in result.stderr, result.stderr


def test_the_settings_name_the_cnn_by_model_name_or_by_path(shared_data, tmp_path):
    from service.pipelines import PipelineResources
    from service.settings import Settings

    models = models_folder(shared_data, tmp_path / "models")
    default = models / DEFAULT_MODEL / "person-detection-0202.xml"
    assert Settings(models_dir=models).cnn_model_path == default
    assert Settings(models_dir=models, cnn_model="person-detection-0202").cnn_model_path == default
    yolox = shared_data / "models" / "yolox-nano" / "yolox_nano.onnx"
    assert Settings(cnn_model=str(yolox)).cnn_model_path == yolox
    assert Settings().cnn_model_path is None
    # a folder without the model is no error: 'auto' falls back and says so
    empty = tmp_path / "empty"
    empty.mkdir()
    assert not Settings(models_dir=empty).cnn_model_path.is_file()
    with pytest.raises(ValueError, match="VTRACK_CNN_MODEL 'person-detection-0200'"):
        Settings(models_dir=models, cnn_model="person-detection-0200")  # not fetched
    with pytest.raises(ValueError, match="not a folder"):
        Settings(models_dir=tmp_path / "missing")
    # the inference threads reach what the workers build their detectors from
    resources = PipelineResources.from_settings(Settings(models_dir=models, inference_threads=1))
    assert (resources.cnn_model, resources.inference_threads) == (default, 1)
    assert PipelineResources.from_settings(Settings(models_dir=models)).inference_threads >= 1
