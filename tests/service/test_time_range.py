"""A part of a video: ``start``/``end`` of a job, ``--start``/``--end`` of `vtrack analyze` and
`vtrack track`. Results keep the video's own times and frame numbers."""

from __future__ import annotations

import json
from itertools import islice

import av
import pytest
from mcap.reader import make_reader
from pydantic import ValidationError

from api_schemas.jobs import JobOptions
from service.analysis import AnalysisStopped, analyze, damage_warnings
from service.frames import ReadProgress, open_frames
from service.outputs.json_out import read_trajectories
from service.pipelines import OptionsError
from tests.service.conftest import PETS_VIDEO, VFR_MS, error_of, submit, wait_for_state
from tests.service.test_analyze_cli import EMBEDDED, vtrack

pytestmark = pytest.mark.slow


def test_a_range_of_a_constant_rate_video_keeps_its_frame_numbers(shared_data):
    source = open_frames(shared_data / PETS_VIDEO)  # 10 frames per second
    read = ReadProgress()
    frames = [(f.index, f.timestamp) for f in source.timed(1, read, start=10, end=14.5)]
    assert frames == [(i, pytest.approx(i / 10)) for i in range(100, 145)]
    # reading stopped at frame 145, the first at 14.5 s: no truncation to report
    assert (read.frames, read.reached_end) == (145, True)
    assert damage_warnings(source, read) == []
    assert source.frames_until(14.5) == 145 and source.frames_until(None) == 795


def test_the_step_counts_from_the_first_frame_of_the_range(vfr_video):
    # frames at 0.8, 0.9, 1.0, 2.2, 2.3 s lie in [0.85, 2.35): 5-8 (0.8 s is before start)
    source = open_frames(vfr_video)
    timed = source.timed(2, start=0.85, end=2.35)
    assert [(f.index, f.timestamp) for f in timed] == [
        (i, pytest.approx(VFR_MS[i] / 1000)) for i in (5, 7)
    ]


def test_a_range_of_an_image_folder(shared_data):
    source = open_frames(shared_data / "mot" / "PETS09-S2L1")  # 7 frames per second
    read = ReadProgress()
    frames = [(f.index, f.timestamp) for f in source.timed(2, read, start=1, end=2)]
    assert frames == [(i, pytest.approx(i / 7)) for i in (7, 9, 11, 13)]
    assert read.reached_end and read.frames == 14


def test_progress_and_cancelling_go_on_through_the_frames_before_start(long_video, tmp_path):
    calls = []

    def progress(read: int, processed: int, fps: float | None) -> bool:
        calls.append((read, processed))
        return read < 30  # cancelled at the 30th frame read, 60 before the first tracked

    options = JobOptions(formats=["json"], start=9)
    with pytest.raises(AnalysisStopped):
        analyze(long_video, options, tmp_path / "out", progress=progress, progress_interval=0)
    assert calls[-1] == (30, 0) and len(calls) == 30


def test_a_job_with_a_range_writes_the_part_with_the_video_times(pets_cut, tmp_path):
    options = JobOptions(
        formats=["json", "mot", "mp4", "mcap"], start=1.05, end=2.0, detector={"name": "default"}
    )
    result = analyze(pets_cut, options, tmp_path / "out")
    assert result.frames_processed == 9 and result.warnings == []  # frames 11-19
    trajectories = read_trajectories(result.files["json"])
    assert (trajectories.video.start, trajectories.video.end) == (1.05, 2.0)
    assert trajectories.video.frames_read == 20
    points = [p for t in trajectories.tracks for p in t.frames]
    assert points and {p.frame_index for p in points} <= set(range(11, 20))
    for point in points:
        assert point.timestamp == pytest.approx(point.frame_index / 10)
    mot_frames = {int(line.split(",")[0]) for line in result.files["mot"].read_text().split()}
    assert mot_frames <= set(range(12, 21))  # 1-based
    # the annotated video is the clip: 9 frames from time 0
    with av.open(str(result.files["mp4"])) as container:
        times = [frame.time for frame in container.decode(video=0)]
    assert times == pytest.approx([i / 10 for i in range(9)])
    with result.files["mcap"].open("rb") as handle:
        reader = make_reader(handle)
        stamps = sorted({m.log_time for _, _, m in reader.iter_messages()})
        metadata = next(reader.iter_metadata()).metadata
    assert stamps == [round(i / 10 * 1e9) for i in range(11, 20)]
    assert (metadata["start"], metadata["end"]) == ("1.05", "2.0")


@pytest.mark.parametrize(
    ("options", "message"),
    [
        ({"start": 2.4}, "start 2.4 s is not within the video, which lasts 2.40 s"),
        # before: accepted, and the job found no frame to track
        ({"start": 2.35}, r"start 2.35 s is after the video's last frame, at 2.30 s \(the video"),
        ({"start": 1.01, "end": 1.05}, "no frame of the video lies between start 1.01 s and end"),
    ],
)
def test_a_range_without_frames_is_refused(pets_cut, tmp_path, options, message):
    with pytest.raises(OptionsError, match=message):
        analyze(pets_cut, JobOptions(formats=["json"], **options), tmp_path / "out")
    assert not (tmp_path / "out" / "trajectories.json").exists()


@pytest.mark.parametrize(
    ("options", "message"),
    [
        ({"start": 5, "end": 5}, r"end \(5 s\) must come after start \(5 s\)"),
        ({"start": -1}, "greater than or equal to 0"),
        ({"start": "10"}, "valid number"),
        ({"end": 0}, "greater than 0"),
    ],
)
def test_bad_range_options_are_refused(options, message):
    with pytest.raises(ValidationError, match=message):
        JobOptions.model_validate(options)


def test_analyze_takes_clock_times(pets_cut, tmp_path):
    out = tmp_path / "out"
    result = vtrack(
        "analyze", pets_cut, "--out-dir", out, "--start", "0:01", "--end", "0:01.5", "--quiet"
    )
    assert result.returncode == 0, result.stderr
    document = json.loads((out / "trajectories.json").read_text())
    assert (document["video"]["start"], document["video"]["end"]) == (1.0, 1.5)
    assert document["frames_processed"] == 5


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["--start", "99"], "vtrack: start 99 s is not within the video, which lasts 2.40 s\n"),
        (
            ["--start", "2.35"],
            "vtrack: start 2.35 s is after the video's last frame, at 2.30 s (the video lasts "
            "2.40 s)\n",
        ),
        (["--start", "2", "--end", "1:00:00"], None),  # an end past the video's is its end
        (["--start", "1:75"], "a time is seconds (90, 12.5) or [H:]M:S"),
        (["--start", "-3"], "a time is seconds"),
    ],
)
def test_analyze_refuses_a_range_outside_the_video(pets_cut, tmp_path, args, message):
    out = tmp_path / "out"
    result = vtrack("analyze", pets_cut, "--out-dir", out, "--format", "json", "--quiet", *args)
    if message is None:
        assert result.returncode == 0, result.stderr
        assert json.loads((out / "trajectories.json").read_text())["frames_processed"] == 4
        return
    assert result.returncode == 2
    assert message in result.stderr
    assert not out.exists()


def test_track_from_start_takes_the_ground_truth_box_of_that_frame(shared_data):
    sequence = shared_data / "otb" / "Crossing"  # image folder: 25 frames per second
    result = vtrack("track", sequence, "--start", "2", "--end", "2.5", "--quiet")
    assert result.returncode == 0, result.stderr
    rows = result.stdout.splitlines()
    assert rows[0] == "frame,x,y,w,h,peak,psr,occluded"
    assert [int(row.split(",")[0]) for row in rows[1:]] == list(range(51, 64))
    truth = (sequence / "groundtruth_rect.txt").read_text().splitlines()[50]
    x, y, w, h = (float(v) for v in truth.replace(",", " ").split())
    assert rows[1] == f"51,{x - 1:.2f},{y - 1:.2f},{w:.2f},{h:.2f},,,"


def _crossing_cut(shared_data, tmp_path, frames: int):
    """The first ``frames`` images of OTB's Crossing with its ground truth (links)."""
    folder = tmp_path / "Crossing"
    (folder / "img").mkdir(parents=True)
    source = shared_data / "otb" / "Crossing"
    for image in islice(sorted((source / "img").iterdir()), frames):
        (folder / "img" / image.name).symlink_to(image)
    (folder / "groundtruth_rect.txt").symlink_to(source / "groundtruth_rect.txt")
    return folder


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (
            ["--start", "60"],
            "vtrack: warning: the image folder states no frame rate (no seqinfo.ini frameRate): "
            "--start and --end count 25 frames per second; give its rate with --fps\n"
            "vtrack: no frame is at or after --start 60 s: the last is at 4.76 s\n",
        ),
        (["--start", "3", "--end", "2"], "vtrack: --end (2 s) must come after --start (3 s)\n"),
    ],
)
def test_track_refuses_a_range_outside_the_video(shared_data, tmp_path, args, message):
    result = vtrack("track", _crossing_cut(shared_data, tmp_path, 120), *args)
    assert (result.returncode, result.stderr, result.stdout) == (2, message, "")


def test_the_api_runs_a_range_and_refuses_one_outside_the_video(pets_cut, make_server):
    with make_server(workers=1).client() as client:
        refused = submit(client, pets_cut, {"formats": ["json"], "start": 30})
        assert "lasts 2.40 s" in error_of(refused, "invalid_options")["detail"]
        refused = submit(client, pets_cut, {"formats": ["json"], "start": 2.35})
        assert "last frame, at 2.30 s" in error_of(refused, "invalid_options")["detail"]
        backwards = submit(client, pets_cut, {"start": 2, "end": 1})
        checks = error_of(backwards, "validation_error")["errors"]
        assert [(e["loc"], e["type"]) for e in checks] == [(["options"], "value_error")]
        created = submit(client, pets_cut, {"formats": ["json"], "start": 1.5, "end": 2.0})
        assert created.status_code == 202, created.text
        job = created.json()["id"]
        queued = client.get(f"/v1/jobs/{job}").json()
        assert queued["options"]["start"] == 1.5 and queued["progress"]["frames_total"] == 20
        # an end past any video is its end; before: 500 (infinitely many frames to it), and the
        # upload stayed on disk with no job to own it until the service restarted
        endless = submit(client, pets_cut, {"formats": ["json"], "start": 2.2, "end": 1e308})
        assert endless.status_code == 202, endless.text
        assert client.get(endless.json()["status_url"]).json()["progress"]["frames_total"] == 24
        status = wait_for_state(client, job, ("succeeded", "failed"))
        assert status["state"] == "succeeded", status
        document = client.get(status["links"]["results"]["json"]).json()
        assert document["frames_processed"] == 5
        assert (document["video"]["start"], document["video"]["end"]) == (1.5, 2.0)


def test_an_image_folder_plays_at_the_rate_given(shared_data, tmp_path):
    folder = _crossing_cut(shared_data, tmp_path, 12)
    out = tmp_path / "out"
    # OTB folders state no rate: 25 per second, and a warning says how to give theirs
    result = vtrack("analyze", folder, "--out-dir", out, "--format", "json", "--quiet")
    assert result.returncode == 0, result.stderr
    assert (
        "no seqinfo.ini frameRate): its frames are stamped 25 per second; give its rate"
        in result.stderr
    )
    result = vtrack(
        "analyze",
        folder,
        "--fps",
        "5",
        "--start",
        "1",
        "--out-dir",
        out,
        "--format",
        "json",
        *EMBEDDED,
    )
    assert result.returncode == 0, result.stderr
    assert "warning" not in result.stderr
    document = json.loads((out / "trajectories.json").read_text())
    assert document["video"]["fps"] == 5 and document["frames_processed"] == 7  # frames 5-11
    track = vtrack("track", folder, "--fps", "5", "--start", "1", "--end", "1.5", "--quiet")
    assert [row.split(",")[0] for row in track.stdout.splitlines()] == ["frame", "6", "7", "8"]


@pytest.mark.parametrize("command", ["analyze", "track"])
def test_a_rate_for_a_video_is_refused(pets_cut, tmp_path, command):
    args = ["--out-dir", tmp_path / "out"] if command == "analyze" else ["--box", "1,1,9,9"]
    result = vtrack(command, pets_cut, "--fps", "12", *args)
    assert result.returncode == 2
    assert result.stderr == (
        "vtrack: --fps is for image folders: the frames of a video carry their own times\n"
    )
