"""`vtrack analyze`: the service's pipeline on a file, without a server."""

from __future__ import annotations

import itertools
import json
import os
import re
import shutil
import signal
import subprocess
import sys
from pathlib import Path

import cv2
import jsonschema
import pytest
from mcap.reader import make_reader

from devtools.clips import cut_video
from devtools.testing import wait_for
from service.frames import open_frames
from tests.conftest import REPO_ROOT
from tests.service.conftest import PETS_VIDEO, schema_for, write_gray
from tests.service.test_cli import vtrack_interrupted

DPM_MODEL = Path("dpm") / "INRIA" / "inriaperson_final.mat"
DPM_OPTIONS = json.dumps({"detector": {"name": "dpm"}})
# The embedded detector, named: without a CNN model detector 'auto' runs it with a warning
EMBEDDED = ("--options", json.dumps({"detector": {"name": "default"}}))


def vtrack(*args, env=None):
    """``vtrack ARGS`` with ``env`` over this environment (without its model variables)."""
    models = (
        "VTRACK_DPM_MODEL",
        "VTRACK_COLOR_NAMES",
        "VTRACK_MODELS_DIR",
        "VTRACK_CNN_MODEL",
        "VTRACK_POSE_MODEL",
        "VTRACK_REID_MODEL",
    )
    base = {k: v for k, v in os.environ.items() if k not in models}
    return subprocess.run(
        [sys.executable, "-m", "service.cli", *map(str, args)],
        capture_output=True,
        text=True,
        timeout=300,
        cwd=REPO_ROOT,
        env={**base, **(env or {})},
    )


def fill(text: str, **values) -> str:
    """``text`` with ``{name}`` replaced by ``values[name]`` (JSON braces left alone)."""
    for name, value in values.items():
        text = text.replace(f"{{{name}}}", str(value))
    return text


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


@pytest.mark.slow
def test_analyze_follows_parts_with_part_trackers_on_request(pets_short, tmp_path):
    def tracks(tracker_options: dict | None) -> list:
        out = tmp_path / f"out-{json.dumps(tracker_options)}"
        arguments = ["--format", "json", "--quiet"]
        if tracker_options is not None:
            arguments += ["--options", json.dumps({"tracker": tracker_options})]
        result = vtrack("analyze", pets_short, "--out-dir", out, *arguments)
        assert result.returncode == 0, result.stderr  # was: a traceback for true
        return json.loads((out / "trajectories.json").read_text())["tracks"]

    def measured(found: list) -> int:
        return sum(
            part["measured"]
            for track in found
            for point in track["frames"]
            for part in point["parts"]
        )

    default = tracks(None)
    assert measured(default) == 0  # the default detector gives no parts
    assert tracks({"part_appearance": False}) == default  # was: part trackers half switched on
    followed = tracks({"part_appearance": True})
    assert measured(followed) > 0  # the part trackers' peaks are measurements


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["--format", "json,avi"], "comma-separated list"),  # unknown format
        (["--frame-step", "0"], "--frame-step: Input should be greater than or equal to 1"),
        (["--upscale", "-1"], "--upscale: Input should be greater than 0"),
        # a decimal comma; before: "invalid float value: '1,5'"
        (["--upscale", "1,5"], "got '1,5' (decimals take a point: 1.5)"),
        (["--start", "1,5"], "got '1,5' (decimals take a point: 1.5)"),
        (["--box", "1,1,-5,3"], "--box: width and height must be at least 1 pixel"),
        (["--box", "1,1,0.5,3"], "--box: width and height must be at least 1 pixel"),
        # first box outside the frame; before: "first_box: box Box(x=900.0, ...) lies ..."
        (["--box", "900,10,20,20"], "--box 900,10,20,20 lies entirely outside the 480x360 frame"),
        (["--fill-gaps", "-1"], "--fill-gaps: Input should be greater than or equal to 0"),
        (  # an option of the other mode, named by its flag; before: "fill_gaps is for mode..."
            ["--box", "150,130,28,65", "--fill-gaps", "0.5"],
            "--fill-gaps: only for tracking people (without --box): a single target is never",
        ),
        # before: ignored, exit status 0
        (["--preset", "rcsk_cn"], "--preset: only for --box: people are followed by"),
        (["--box", "150,130,28,65", "--upscale", "2"], "--upscale: only for tracking people"),
        (  # a rule across options, named by no flag (the --format beside it is fine)
            ["--options", '{"mode": "single_target"}', "--format", "json"],
            "vtrack: mode 'single_target' needs first_box",
        ),
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


def test_analyze_refuses_an_enlargement_beyond_8k_before_its_progress_bar(tmp_path):
    uhd = write_gray(tmp_path / "uhd.mp4", 3840, 2160)
    result = vtrack("analyze", uhd, "--out-dir", tmp_path / "o", "--upscale", "4")
    assert result.returncode == 2
    assert result.stderr == (
        "vtrack: detector.upscale 4 enlarges frames of 3840x2160 to 15360x8640, beyond the "
        "7680x4320 the detector takes: use at most 2, or leave it unset to let the detector "
        "choose\n"
    )
    assert not (tmp_path / "o").exists()


@pytest.mark.slow
@pytest.mark.parametrize(
    ("variable", "flags"),
    [
        # the variable alone, as the README says; before: "this service has none: set
        # VTRACK_DPM_MODEL"
        ("{model}", ["--options", DPM_OPTIONS]),
        ("{tmp}/missing.mat", ["--dpm-model", "{model}"]),  # the flag wins over the variable
        ("", ["--dpm-model", "{renamed}"]),  # a model is read as one whatever its name
    ],
)
def test_analyze_detects_with_the_dpm_model_of_the_flag_or_the_environment(
    shared_data, pets_short, tmp_path, variable, flags
):
    renamed = tmp_path / "inria-person.model"
    shutil.copyfile(shared_data / DPM_MODEL, renamed)
    values = {"model": shared_data / DPM_MODEL, "tmp": tmp_path, "renamed": renamed}
    arguments = [fill(a, **values) for a in flags]
    env = {"VTRACK_DPM_MODEL": fill(variable, **values)}
    out = tmp_path / "out"
    result = vtrack(
        "analyze", pets_short, "--out-dir", out, "--format", "json", *arguments, env=env
    )
    assert result.returncode == 0, result.stderr
    assert "with the DPM " in result.stderr  # the closing line says which detector ran
    document = json.loads((out / "trajectories.json").read_text())
    # only the DPM places body parts; the embedded detector's are predicted from the box
    parts = [p for t in document["tracks"] for f in t["frames"] for p in f["parts"]]
    assert any(part["measured"] for part in parts)


@pytest.mark.parametrize(
    ("args", "env", "message"),
    [
        # before: "detector 'dpm' needs a voc-release5 model, and this service has none"
        (["--dpm-model", "{tmp}/missing.mat"], {}, "--dpm-model: {tmp}/missing.mat does not exist"),
        (  # a video given as the model; before: "unknown detector '...avi': expected one of"
            ["--dpm-model", "{video}"],
            {},
            "--dpm-model: {video} is not a voc-release5 DPM model: it is not a readable MATLAB",
        ),
        (  # the variable is read, and checked the same way
            ["--options", DPM_OPTIONS],
            {"VTRACK_DPM_MODEL": "{video}"},
            "VTRACK_DPM_MODEL: {video} is not a voc-release5 DPM model",
        ),
        (  # a DPM job and no model anywhere: say both ways to give one
            ["--options", DPM_OPTIONS],
            {},
            "detector 'dpm' needs a voc-release5 model: give --dpm-model MODEL.mat or set "
            "VTRACK_DPM_MODEL",
        ),
        # the Color Names table comes from the variable as from --w2c; before: ignored
        ([], {"VTRACK_COLOR_NAMES": "{video}"}, "VTRACK_COLOR_NAMES: colour-name table '{video}'"),
    ],
)
def test_analyze_refuses_a_model_file_that_is_not_one_before_it_starts(
    pets_short, tmp_path, args, env, message
):
    values = {"video": pets_short, "tmp": tmp_path}
    arguments = [fill(a, **values) for a in args]
    env = {key: fill(value, **values) for key, value in env.items()}
    out = tmp_path / "out"
    result = vtrack("analyze", pets_short, "--out-dir", out, "--quiet", *arguments, env=env)
    assert result.returncode == 2
    assert result.stderr.startswith(f"vtrack: {fill(message, **values)}")
    assert result.stderr.count("\n") == 1  # one line, no traceback
    assert not out.exists()


@pytest.mark.slow
def test_ctrl_c_ends_analyze_with_one_line_and_no_partial_results(shared_data, tmp_path):
    # before: a KeyboardInterrupt traceback and out/.vtrack-partial/ with half-written files
    out = tmp_path / "out"
    video = shared_data / PETS_VIDEO  # 795 frames: a minute of work to interrupt
    status, stderr = vtrack_interrupted("analyze", video, "--out-dir", out, cwd=REPO_ROOT)
    assert status == 130 and "Traceback" not in stderr, stderr
    assert re.search(r"\nvtrack: interrupted after [1-9]\d* frames; nothing written\n$", stderr)
    assert not out.exists()  # the folder this run made is gone with the partial files


@pytest.mark.slow
def test_sigterm_ends_analyze_as_ctrl_c_does(shared_data, tmp_path):
    # kill, timeout, systemd and docker stop send SIGTERM; before, the run died at once and
    # left out/.vtrack-partial/ with half-written files, saying nothing
    out = tmp_path / "out"
    status, stderr = vtrack_interrupted(
        "analyze", shared_data / PETS_VIDEO, "--out-dir", out, cwd=REPO_ROOT, stop=signal.SIGTERM
    )
    assert status == 128 + signal.SIGTERM and "Traceback" not in stderr, stderr
    assert re.search(
        r"\nvtrack: stopped by SIGTERM after [1-9]\d* frames; nothing written\n$", stderr
    )
    assert not out.exists()


@pytest.mark.slow
def test_two_runs_into_one_folder_do_not_mix_their_results(shared_data, tmp_path):
    # before: both failed on each other's moved files, leaving a mix of their results
    out = tmp_path / "out"
    first = subprocess.Popen(
        [
            sys.executable,
            "-m",
            "service.cli",
            "analyze",
            shared_data / PETS_VIDEO,
            "--out-dir",
            out,
        ],
        stdout=subprocess.DEVNULL,
        stderr=subprocess.PIPE,
        cwd=REPO_ROOT,
    )
    try:
        wait_for(lambda: (out / ".vtrack-partial").exists(), 60, "the first run's scratch")
        second = vtrack("analyze", shared_data / PETS_VIDEO, "--out-dir", out, "--quiet")
        assert second.returncode == 2
        assert second.stderr == (
            f"vtrack: another vtrack analyze is writing into {out}: wait for it to end or give "
            "another --out-dir\n"
        )
        assert first.poll() is None  # undisturbed
    finally:
        first.kill()
        first.wait()


@pytest.fixture(scope="module")
def damaged(shared_data, tmp_path_factory):
    """30 frames of PETS09-S2L1 (an MJPG AVI) with frames 10 and 20 made undecodable: their
    JPEG's start-of-frame marker says arithmetic coding, which FFmpeg's decoder refuses."""
    folder = tmp_path_factory.mktemp("damaged")
    data = bytearray(cut_video(shared_data / PETS_VIDEO, folder / "whole.avi", 30).read_bytes())
    starts = [m.start() for m in re.finditer(rb"\xff\xd8\xff", data)]
    for frame in (10, 20):
        marker = data.index(b"\xff\xc0", starts[frame])
        data[marker + 1] = 0xC9
    path = folder / "damaged.avi"
    path.write_bytes(data)
    return path


@pytest.mark.slow
def test_analyze_passes_over_damaged_frames_and_goes_on(damaged, tmp_path):
    # before: the video "ended" at frame 10, and the rest of it was not tracked
    out = tmp_path / "out"
    result = vtrack(
        "analyze", damaged, "--out-dir", out, "--format", "json,mot", "--quiet", *EMBEDDED
    )
    assert result.returncode == 0, result.stderr
    frames = cv2.VideoCapture(str(damaged)).get(cv2.CAP_PROP_FRAME_COUNT)
    assert result.stderr == (
        "vtrack: warning: 2 frames (10, 20) were damaged and did not decode (frame_index "
        "counting from 0): they have no tracks, and tracking went on with the frames after "
        "them\n"
    )  # and no line of FFmpeg's own ([mjpeg @ 0x...] ...)
    tracked = {
        point["frame_index"]
        for track in json.loads((out / "trajectories.json").read_text())["tracks"]
        for point in track["frames"]
    }
    assert max(tracked) == frames - 1 and not tracked & {10, 20}
    mot_frames = {int(line.split(",")[0]) for line in (out / "tracks_mot.txt").read_text().split()}
    assert max(mot_frames) == frames and not mot_frames & {11, 21}  # MOT counts from 1
    assert len(list(open_frames(damaged))) == frames - 2  # as vtrack publish reads a file


def test_track_numbers_rows_by_the_video_frame_and_writes_json_to_a_json_file(damaged, tmp_path):
    out = tmp_path / "boxes.json"
    result = vtrack("track", damaged, "--box", "150,130,28,65", "--out", out, "--quiet")
    assert result.returncode == 0, result.stderr
    rows = [json.loads(line) for line in out.read_text().splitlines()]  # before: CSV
    numbers = [row["frame"] for row in rows]
    assert 11 not in numbers and 21 not in numbers and numbers[:3] == [1, 2, 3]
    assert numbers[-1] == cv2.VideoCapture(str(damaged)).get(cv2.CAP_PROP_FRAME_COUNT)


@pytest.fixture(scope="module")
def pets_45(shared_data, tmp_path_factory):
    """45 frames (4.5 s) of PETS09-S2L1; the embedded detector misses people for a frame or
    two several times in it (frames 32-42), so tracks break and come back."""
    return cut_video(shared_data / PETS_VIDEO, tmp_path_factory.mktemp("pets") / "p45.avi", 45)


def points_by_track(path):
    return {t["track_id"]: t["frames"] for t in json.loads(path.read_text())["tracks"]}


@pytest.mark.slow
def test_analyze_fills_short_gaps_in_the_trajectories_only(pets_45, tmp_path):
    plain, filled = tmp_path / "plain", tmp_path / "filled"
    result = vtrack("analyze", pets_45, "--out-dir", plain, "--format", "json", "--quiet")
    assert result.returncode == 0, result.stderr
    arguments = ["--format", "json,mot,mcap", "--fill-gaps", "0.5", "--quiet"]
    result = vtrack("analyze", pets_45, "--out-dir", filled, *arguments)
    assert result.returncode == 0, result.stderr

    before, after = (
        points_by_track(plain / "trajectories.json"),
        points_by_track(filled / "trajectories.json"),
    )
    assert before.keys() == after.keys()
    gaps = 0
    for track_id, points in after.items():
        # what the tracker reported is untouched; the rest is marked
        assert [p for p in points if not p["interpolated"]] == before[track_id]
        indices = [p["frame_index"] for p in points]
        assert indices == sorted(set(indices))
        measured = [k for k, p in enumerate(points) if not p["interpolated"]]
        for a, b in itertools.pairwise(measured):
            first, last = points[a], points[b]
            span = last["timestamp"] - first["timestamp"]
            if b - a == 1 and last["frame_index"] - first["frame_index"] > 1:
                assert span > 0.5 - 1e-6  # a gap left open is longer than the limit
            if b - a > 1:  # a filled gap: every frame between, on the line between its ends
                gaps += 1
                assert span <= 0.5 + 1e-6
                assert indices[a : b + 1] == list(range(indices[a], indices[b] + 1))
                for point in points[a + 1 : b]:
                    w = (point["timestamp"] - first["timestamp"]) / span
                    for key in "xywh":
                        expected = first["box"][key] + w * (last["box"][key] - first["box"][key])
                        # each of the three written to 0.01 px
                        assert point["box"][key] == pytest.approx(expected, abs=0.0101)
    assert gaps >= 2

    # the mot rows are the json's points; the mcap shows the frames as tracked
    rows = (filled / "tracks_mot.txt").read_text().split()
    mot = sorted((int(r.split(",")[0]) - 1, int(r.split(",")[1])) for r in rows)
    assert mot == sorted((p["frame_index"], t) for t, ps in after.items() for p in ps)
    with (filled / "tracks.mcap").open("rb") as handle:
        recorded = [
            track
            for _, channel, message in make_reader(handle).iter_messages(topics=["/tracks"])
            for track in json.loads(message.data)["tracks"]
        ]
    assert len(recorded) == sum(len(ps) for ps in before.values())
    assert not any(track["interpolated"] for track in recorded)


def test_analyze_leaves_only_this_runs_results_and_says_what_detected(pets_short, tmp_path):
    out = tmp_path / "out"
    out.mkdir()
    for name in ("tracks.mcap", "tracks_mot.txt", "annotated.mp4", "notes.txt"):
        (out / name).write_text("an earlier run's file")  # notes.txt: not a result
    # a model set for the service but not asked for, and a misspelt variable
    env = {"VTRACK_DPM_MODEL": str(tmp_path / "model.mat"), "VTRACK_DMP_MODEL": "x"}
    result = vtrack("analyze", pets_short, "--out-dir", out, "--format", "json", *EMBEDDED, env=env)
    assert result.returncode == 0, result.stderr
    # before: the earlier mcap, mot and mp4 stayed beside the new json
    assert sorted(p.name for p in out.iterdir()) == ["notes.txt", "trajectories.json"]
    assert "with the embedded detector (OpenCV's HOG people detector)" in result.stderr
    assert "ignoring VTRACK_DMP_MODEL: not a setting (did you mean VTRACK_DPM_MODEL?)" in (
        result.stderr
    )
    quiet = vtrack(
        "analyze", pets_short, "--out-dir", out, "--format", "json", "--quiet", *EMBEDDED
    )
    assert quiet.returncode == 0 and quiet.stderr == "", quiet.stderr


def test_analyze_takes_a_box_partly_left_of_and_above_the_frame(pets_short, tmp_path):
    out = tmp_path / "out"
    # before: "argument --box: expected one argument", the value read as an option
    result = vtrack(
        "analyze", pets_short, "--out-dir", out, "--format", "json", "--box", "-5,-5,30,60"
    )
    assert result.returncode == 0, result.stderr
    first = json.loads((out / "trajectories.json").read_text())["tracks"][0]["frames"][0]
    assert first["box"] == {"x": -5, "y": -5, "w": 30, "h": 60}
    assert "with the strcf_hog_cn tracker" in result.stderr
