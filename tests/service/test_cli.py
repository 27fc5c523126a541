"""The `vtrack track` command, run as a user runs it: a subprocess on real files."""

import json
import os
import re
import signal
import socket
import subprocess
import sys
import threading

import cv2
import numpy as np
import pytest

from devtools.testing import free_port, try_get, wait_for
from service.cli import _attach_box_values, build_parser
from tests.conftest import sigint_as_in_a_terminal
from tests.correlation.test_tracker import moving_target_scene
from tests.service.conftest import PETS_VIDEO


def vtrack(*args, check=False):
    return subprocess.run(
        [sys.executable, "-m", "service.cli", *map(str, args)],
        capture_output=True,
        text=True,
        timeout=300,
        check=check,
    )


# the progress bar once a frame is done: "  3%|▎         | 24/795 [00:00<00:07, ...]"
PROGRESS = re.compile(rb"\| *[1-9]\d*/\d+ \[")


def vtrack_interrupted(*args, cwd=None, stop=signal.SIGINT) -> tuple[int, str]:
    """Run ``vtrack ARGS``, press Ctrl-C (SIGINT; or send ``stop``) once its progress bar shows
    tracked frames, and return its exit status and standard error."""
    process = subprocess.Popen(
        [sys.executable, "-m", "service.cli", *map(str, args)],
        stdout=subprocess.DEVNULL,
        stderr=subprocess.PIPE,
        cwd=cwd,
        # the bar as often as on a terminal (into a pipe, every 30 s)
        env={**os.environ, "TQDM_MININTERVAL": "0.1"},
        preexec_fn=sigint_as_in_a_terminal,
    )
    stderr = bytearray()

    def read() -> None:
        while chunk := process.stderr.read1(4096):
            stderr.extend(chunk)

    reader = threading.Thread(target=read, daemon=True)
    reader.start()
    try:
        wait_for(
            lambda: PROGRESS.search(bytes(stderr)) or process.poll() is not None,
            120,
            "the first tracked frames",
            interval=0.05,
        )
        assert process.poll() is None, stderr.decode()  # still running when interrupted
        process.send_signal(stop)
        status = process.wait(timeout=60)
    finally:
        if process.poll() is None:
            process.kill()
            process.wait()
    reader.join(timeout=10)
    return status, stderr.decode(errors="replace")


@pytest.fixture(scope="module")
def scene_video(tmp_path_factory):
    """An MJPG AVI of the synthetic moving target, and its true boxes."""
    images, truth = moving_target_scene(frames=30)
    path = tmp_path_factory.mktemp("video") / "scene.avi"
    height, width = images[0].shape[:2]
    writer = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*"MJPG"), 10.0, (width, height))
    for image in images:
        writer.write(cv2.cvtColor(image, cv2.COLOR_RGB2BGR))
    writer.release()
    return path, truth


def test_tracks_a_video_file_and_writes_csv(scene_video, tmp_path):
    path, truth = scene_video
    out = tmp_path / "boxes.csv"
    box = ",".join(str(int(v)) for v in truth[0])
    result = vtrack("track", path, "--box", box, "--out", out, "--preset", "rcsk_cn")
    assert result.returncode == 0, result.stderr
    rows = np.genfromtxt(out, delimiter=",", skip_header=1)
    assert rows.shape == (30, 8)
    np.testing.assert_array_equal(rows[:, 0], np.arange(1, 31))
    assert np.isnan(rows[0, 7]) and np.all(rows[1:, 7] == 0)  # occluded: empty, then never
    centres = rows[:, 1:3] + rows[:, 3:5] / 2
    true_centres = truth[:, :2] + truth[:, 2:] / 2
    assert np.abs(centres - true_centres).max() < 6.0


def test_a_box_partly_left_of_and_above_the_frame_is_taken_as_given(scene_video, tmp_path):
    path, _ = scene_video
    out = tmp_path / "boxes.csv"
    # before: "argument --box: expected one argument" (argparse took the value for an option)
    result = vtrack("track", path, "--box", "-5,-5,20,20", "--out", out, "--quiet")
    assert result.returncode == 0, result.stderr
    assert out.read_text().splitlines()[1] == "1,-5.00,-5.00,20.00,20.00,,,"
    assert result.stderr == ""  # --quiet: no bar and no closing line


def test_otb_folder_takes_its_first_ground_truth_box_and_prints_json(shared_data, tmp_path):
    # A 15-frame cut of Crossing, in OTB layout, in a temporary folder.
    source = shared_data / "otb" / "Crossing"
    cut = tmp_path / "Crossing"
    (cut / "img").mkdir(parents=True)
    for index in range(1, 16):
        name = f"{index:04d}.jpg"
        (cut / "img" / name).write_bytes((source / "img" / name).read_bytes())
    lines = (source / "groundtruth_rect.txt").read_text().splitlines()[:15]
    (cut / "groundtruth_rect.txt").write_text("\n".join(lines) + "\n")
    result = vtrack("track", cut, "--format", "json", "--quiet")
    assert result.returncode == 0, result.stderr
    records = [json.loads(line) for line in result.stdout.splitlines()]
    assert [r["frame"] for r in records] == list(range(1, 16))
    first = [float(v) for v in lines[0].split()]
    assert records[0]["box"] == [first[0] - 1, first[1] - 1, first[2], first[3]]
    assert records[0]["psr"] is None and records[1]["psr"] > 0
    assert records[0]["occluded"] is None and records[1]["occluded"] is False


def _otb_folder_with_ground_truth(truth: bytes):
    def make(folder):
        (folder / "img").mkdir()
        cv2.imwrite(str(folder / "img" / "0001.jpg"), np.zeros((40, 40, 3), np.uint8))
        _write(folder / "groundtruth_rect.txt", truth)
        return folder

    return make


@pytest.mark.parametrize(
    ("make_source", "extra", "message"),
    [
        (lambda d: d / "missing.avi", ["--box", "1,1,5,5"], "no such file"),
        (
            lambda d: _write(d / "junk.avi", b"\x00not a video" * 100),
            ["--box", "1,1,5,5"],
            "not a video",
        ),
        (lambda d: d, ["--box", "1,1,5,5"], "no image files"),  # an empty folder
        (lambda d: _write(d / "clip.avi", b""), ["--box", "1,2,3"], "four numbers"),  # bad --box
        # before: a ValueError traceback
        (_otb_folder_with_ground_truth(b"12 34 56\n"), [], "line 1: expected 4 values x,y,w,h"),
    ],
)
def test_bad_input_exits_with_a_clear_message(tmp_path, make_source, extra, message):
    result = vtrack("track", make_source(tmp_path), *extra)
    assert result.returncode == 2
    assert message in result.stderr


def test_video_without_box_asks_for_one(scene_video):
    result = vtrack("track", scene_video[0])
    assert result.returncode == 2
    assert "--box" in result.stderr


@pytest.mark.parametrize("to_file", [False, True])
@pytest.mark.parametrize(
    ("box", "message"),
    [
        # before: "box Box(x=5000.0, ...) lies entirely outside", after the CSV header
        ("5000,10,20,20", "--box 5000,10,20,20 lies entirely outside the 320x240 frame"),
        # before: refused at the first frame, once the progress bar had started
        ("300,100,-20,50", "--box 300,100,-20,50: width and height must be at least 1 pixel"),
    ],
)
def test_a_bad_box_stops_track_before_any_output(scene_video, tmp_path, box, message, to_file):
    out = ["--out", tmp_path / "boxes.csv"] if to_file else []
    result = vtrack("track", scene_video[0], "--box", box, *out)
    assert result.returncode == 2
    assert result.stderr == f"vtrack: {message}\n"  # one line: no progress bar, no repr
    assert result.stdout == "" and list(tmp_path.iterdir()) == []  # no header, no file


def test_track_warns_of_a_truncated_video(pets_cut, tmp_path):
    # the first half of the 24-frame file's bytes: its header still announces 24 frames
    data = pets_cut.read_bytes()
    truncated = tmp_path / "truncated.avi"
    truncated.write_bytes(data[: len(data) // 2])
    result = vtrack("track", truncated, "--box", "150,130,28,65", "--quiet")
    assert result.returncode == 0, result.stderr
    rows = result.stdout.splitlines()[1:]
    assert 1 < len(rows) < 24
    assert (
        f"vtrack: warning: the video ended after {len(rows)} of the 24 frames its container "
        "announces (truncated or damaged file)" in result.stderr
    )


@pytest.mark.parametrize(
    ("source", "args"),
    [
        ("otb/Crossing", ["--format", "json"]),  # 120 rows: the pipe breaks during the run
        ("cut", ["--box", "150,130,28,65"]),  # 8 rows: it breaks at the final flush
    ],
)
def test_a_closed_output_ends_track_quietly(shared_data, pets_short, source, args):
    # `vtrack track ... | head` whose reader is gone at once; before: a BrokenPipeError
    # traceback (exit status 1), or "Exception ignored ... BrokenPipeError" (120)
    path = pets_short if source == "cut" else shared_data / source
    process = subprocess.Popen(
        [sys.executable, "-m", "service.cli", "track", path, "--quiet", *args],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    process.stdout.close()
    stderr = process.stderr.read()
    assert process.wait(timeout=300) == 141  # 128 + SIGPIPE, as `yes | head` ends
    assert stderr == ""


def test_ctrl_c_ends_track_leaving_the_output_file_as_it_was(shared_data, tmp_path):
    # before: a KeyboardInterrupt traceback and a half-written boxes.csv over the old one
    out = tmp_path / "boxes.csv"
    out.write_text("an earlier run\n")
    video = shared_data / PETS_VIDEO  # 795 frames: seconds of work to interrupt
    status, stderr = vtrack_interrupted("track", video, "--box", "150,130,28,65", "--out", out)
    assert status == 130 and "Traceback" not in stderr, stderr
    assert re.search(r"\nvtrack: interrupted after [1-9]\d* frames; nothing written\n$", stderr)
    assert list(tmp_path.iterdir()) == [out] and out.read_text() == "an earlier run\n"


def test_a_colour_table_that_is_not_one_is_reported(scene_video, tmp_path):
    table = _write(tmp_path / "w2c.mat", b"\x00not a table" * 50)
    result = vtrack("track", scene_video[0], "--box", "1,1,5,5", "--w2c", table)
    assert result.returncode == 2 and "Traceback" not in result.stderr
    assert f"colour-name table '{table}'" in result.stderr


def _write(path, data):
    path.write_bytes(data)
    return path


@pytest.mark.parametrize(
    ("variable", "content", "message"),
    [
        ("VTRACK_DPM_MODEL", None, "is not a file"),
        ("VTRACK_DPM_MODEL", b"\x00not a model" * 50, "not a readable MATLAB"),
        ("VTRACK_COLOR_NAMES", b"\x00not a table" * 50, "VTRACK_COLOR_NAMES: "),
    ],
)
def test_serve_refuses_a_model_setting_that_is_not_a_model(tmp_path, variable, content, message):
    # checked when the service starts, not when the first job needs the file
    path = tmp_path / "model.mat"
    if content is not None:
        path.write_bytes(content)
    env = {**os.environ, variable: str(path), "VTRACK_DATA_DIR": str(tmp_path / "data")}
    result = subprocess.run(
        [sys.executable, "-m", "service.cli", "serve", "--port", "0"],
        capture_output=True,
        text=True,
        timeout=60,  # a service that started would run until killed here
        env=env,
    )
    assert result.returncode == 2
    assert message in result.stderr and str(path) in result.stderr


@pytest.mark.parametrize(
    ("env", "args", "message"),
    [
        ({"VTRACK_WORKERS": "abc"}, [], "VTRACK_WORKERS: Input should be a valid integer"),
        ({}, ["--workers", "0"], "--workers: Input should be greater than or equal to 1"),
        ({}, ["--port", "99999"], "--port: Input should be less than or equal to 65535"),
        ({"VTRACK_LOG_LEVEL": "loud"}, [], "VTRACK_LOG_LEVEL: must be one of critical"),
        ({}, ["--log-level", "loud"], "--log-level: must be one of critical"),
        ({"VTRACK_ZENOH_CONNECT": "tcp/a:7447"}, [], "VTRACK_ZENOH_CONNECT is not valid JSON"),
        ({"VTRACK_ZENOH_CONNECT": '["a:7447"]'}, [], "'a:7447' is not a Zenoh endpoint"),
        ({"VTRACK_ZENOH_CONFIG": "{tmp}/zenoh.yaml"}, [], "VTRACK_ZENOH_CONFIG: {tmp}/zenoh.yaml"),
        ({"VTRACK_STREAMS": '[{{"camera": "a/b"}}]'}, [], "VTRACK_STREAMS[0].camera: String"),
        # an unset ${TOKEN} in a unit file: every request would be refused
        ({"VTRACK_API_TOKEN": ""}, [], "VTRACK_API_TOKEN: is set but empty"),
        # before: "Input should be a valid number" and ". is not a file"
        (
            {"VTRACK_RETENTION_HOURS": ""},
            [],
            "VTRACK_RETENTION_HOURS: is set but empty: unset it for finished jobs kept until "
            "deleted, or give hours",
        ),
        ({"VTRACK_DPM_MODEL": " "}, [], "VTRACK_DPM_MODEL: is set but empty: unset it for no DPM"),
        ({"VTRACK_COLOR_NAMES": ""}, [], "VTRACK_COLOR_NAMES: is set but empty"),
        # before: 1e-6 was taken, and the idle service swept half a core away
        ({"VTRACK_HOUSEKEEPING_INTERVAL": "1e-6"}, [], "VTRACK_HOUSEKEEPING_INTERVAL: Input"),
        # Zenoh would listen on a random port of every interface
        ({"VTRACK_ZENOH_LISTEN": "[]"}, [], "VTRACK_ZENOH_LISTEN: give at least one endpoint"),
        # a misspelt setting is named (and the service stops here for the bad port)
        (
            {"VTRACK_WORKER": "3", "VTRACK_PORT": "x"},
            [],
            "ignoring VTRACK_WORKER: not a setting (did you mean VTRACK_WORKERS?)",
        ),
    ],
)
def test_serve_names_the_setting_that_is_wrong(tmp_path, env, args, message):
    (tmp_path / "zenoh.yaml").write_text("mode: [unclosed\n")
    env = {key: value.format(tmp=tmp_path) for key, value in env.items()}
    result = subprocess.run(
        [sys.executable, "-m", "service.cli", "serve", "--data-dir", tmp_path / "d", *args],
        capture_output=True,
        text=True,
        timeout=60,  # a service that started would run until killed here
        env={**os.environ, **env},
    )
    assert result.returncode == 2 and "Traceback" not in result.stderr
    assert message.format(tmp=tmp_path) in result.stderr


def test_serve_on_a_port_in_use_stops_at_once(tmp_path):
    # before: "serving on ..." and workers started, then uvicorn's own error and exit 3
    with socket.create_server(("127.0.0.1", 0)) as taken:
        port = taken.getsockname()[1]
        result = subprocess.run(
            [sys.executable, "-m", "service.cli", "serve", "--port", str(port)],
            capture_output=True,
            text=True,
            timeout=60,  # a service that started would run until killed here
            env={**os.environ, "VTRACK_DATA_DIR": str(tmp_path / "data")},
        )
    assert result.returncode == 2 and "Traceback" not in result.stderr
    assert f"VTRACK_PORT: cannot listen on 127.0.0.1:{port}" in result.stderr
    assert "serving on" not in result.stderr


@pytest.mark.parametrize("host", ["10.255.255.254", "no-such-host.invalid"])
def test_serve_on_a_host_address_it_cannot_have_names_the_host(tmp_path, host):
    # before: "--port, VTRACK_PORT: ... choose another port" for an address problem
    result = subprocess.run(
        [sys.executable, "-m", "service.cli", "serve", "--port", "0", "--host", host],
        capture_output=True,
        text=True,
        timeout=60,  # a service that started would run until killed here
        env={**os.environ, "VTRACK_DATA_DIR": str(tmp_path / "data")},
    )
    assert result.returncode == 2 and "Traceback" not in result.stderr
    assert f"vtrack: --host, VTRACK_HOST: cannot listen on '{host}'" in result.stderr
    assert "VTRACK_PORT" not in result.stderr


def test_version():
    result = subprocess.run(
        [sys.executable, "-m", "service.cli", "--version"], capture_output=True, text=True
    )
    assert result.returncode == 0
    assert re.fullmatch(r"vtrack \d+\.\d+\.\d+\n", result.stdout), result.stdout


@pytest.mark.parametrize(
    ("short", "long"),
    [
        (["track", "v.mp4", "-o", "b.csv", "-q", "--box", "-5,-5,20,20"],
         ["track", "v.mp4", "--out", "b.csv", "--quiet", "--box", "-5,-5,20,20"]),
        (["analyze", "v.mp4", "-qo", "results"],
         ["analyze", "v.mp4", "--out-dir", "results", "--quiet"]),
        (["subscribe", "--camera", "c", "-o", "t.jsonl"],
         ["subscribe", "--camera", "c", "--output", "t.jsonl"]),
    ],
)  # fmt: skip
def test_short_options_for_the_output_and_quiet(short, long):
    parse = build_parser().parse_args
    assert parse(_attach_box_values(short)) == parse(_attach_box_values(long))


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["track", "{video}", "--box", "1,1,5,5", "--out", "{tmp}/typo/out.csv"], "does not exist"),
        (["track", "{video}", "--box", "1,1,5,5", "--out", "{tmp}"], "is a folder"),
        (["analyze", "{video}", "--out-dir", "{file}"], "exists and is not a folder"),
        (["analyze", "{video}", "--out-dir", "{file}/results"], "cannot create the folder"),
        (["serve", "--port", "0", "--data-dir", "{file}"], "the data folder"),
        (["subscribe", "--camera", "c", "--output", "{tmp}/typo/t.jsonl"], "does not exist"),
    ],
)  # fmt: skip
def test_an_output_that_cannot_be_written_stops_the_command_before_it_starts(
    scene_video, tmp_path, args, message
):
    # before: a traceback, after the whole video for track and analyze
    blocker = tmp_path / "a-file"
    blocker.write_text("not a folder")
    values = {"video": scene_video[0], "tmp": tmp_path, "file": blocker}
    result = vtrack(*(a.format(**values) for a in args))
    assert result.returncode == 2, result.stderr
    assert message in result.stderr and "Traceback" not in result.stderr
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a-file"]  # nothing written


def test_serve_on_every_address_prints_a_link_a_browser_can_open(tmp_path):
    """The image's VTRACK_HOST=0.0.0.0: the link was http://0.0.0.0:8000/docs."""
    port = free_port()
    service = subprocess.Popen(
        [sys.executable, "-m", "service.cli", "serve", "--host", "0.0.0.0", "--port", str(port)],
        stderr=subprocess.PIPE,
        text=True,
        env={**os.environ, "VTRACK_DATA_DIR": str(tmp_path / "data"),
             "VTRACK_ZENOH_LISTEN": f'["tcp/127.0.0.1:{free_port()}"]'},
    )  # fmt: skip
    try:
        lines = [service.stderr.readline() for _ in range(2)]
        assert f"serving on every address of this machine, port {port}" in lines[0]
        link = lines[1].split("open the API docs at ")[1].split()[0]
        assert link == f"http://localhost:{port}/docs"
        page = wait_for(lambda: try_get(link), timeout=60, what="the API docs")
        assert page.status_code == 200
    finally:
        service.terminate()
        service.wait(timeout=30)
        service.stderr.close()


@pytest.mark.parametrize(
    ("host", "token", "zenoh_host", "warned"),
    [
        ("0.0.0.0", None, "127.0.0.1", ["no VTRACK_API_TOKEN, and the API listens on every"]),
        ("0.0.0.0", "s3cret", "0.0.0.0", ["Zenoh listens on tcp/0.0.0.0:"]),
        ("127.0.0.1", None, "[::1]", []),
    ],
)
def test_serve_says_what_a_service_open_to_the_network_exposes(
    tmp_path, host, token, zenoh_host, warned
):
    # before: a service bound to every address without a token (the Docker image's) said
    # nothing, and nothing said that the token does not cover Zenoh
    port = free_port()
    env = {**os.environ, "VTRACK_DATA_DIR": str(tmp_path / "data"),
           "VTRACK_ZENOH_LISTEN": f'["tcp/{zenoh_host}:{free_port()}"]'}  # fmt: skip
    if token:
        env["VTRACK_API_TOKEN"] = token
    if zenoh_host == "0.0.0.0":  # refused without it (tests/streams/test_security.py)
        env["VTRACK_ZENOH_ALLOW_OPEN"] = "true"
    service = subprocess.Popen(
        [sys.executable, "-m", "service.cli", "serve", "--host", host, "--port", str(port)],
        stderr=subprocess.PIPE,
        text=True,
        env=env,
    )
    try:
        wait_for(lambda: try_get(f"http://127.0.0.1:{port}/readyz"), 60, "the service")
    finally:
        service.terminate()
        stderr = service.communicate(timeout=30)[1]
    warnings = [line for line in stderr.splitlines() if line.startswith("vtrack: warning: ")]
    assert len(warnings) == len(warned), stderr
    for line, start in zip(warnings, warned, strict=True):
        assert line.startswith(f"vtrack: warning: {start}")
    if token is None and warned:
        assert "upload, download and delete jobs and stream recordings" in warnings[0]
    if zenoh_host == "0.0.0.0":
        assert "(VTRACK_API_TOKEN does not cover Zenoh)" in warnings[0]


def test_an_output_behind_a_link_or_a_pipe_is_written_through_not_replaced(scene_video, tmp_path):
    path, truth = scene_video
    box = ",".join(str(int(v)) for v in truth[0])
    # a link: its file gets the rows, the link stays (was: the link replaced by a plain file)
    real, link = tmp_path / "real.csv", tmp_path / "link.csv"
    real.write_text("an earlier run\n")
    link.symlink_to(real)
    result = vtrack("track", path, "--box", box, "--out", link, "--quiet")
    assert result.returncode == 0, result.stderr
    assert link.is_symlink() and len(real.read_text().splitlines()) == 31
    # a pipe (as /dev/null, a device): written into (was: replaced by a plain file)
    pipe = tmp_path / "pipe"
    os.mkfifo(pipe)
    lines = []
    reader = threading.Thread(
        target=lambda: lines.extend(pipe.read_text().splitlines()), daemon=True
    )
    reader.start()
    result = vtrack("track", path, "--box", box, "--out", pipe, "--quiet")
    reader.join(timeout=60)
    assert result.returncode == 0, result.stderr
    assert len(lines) == 31 and lines[0] == "frame,x,y,w,h,peak,psr,occluded"
    assert pipe.is_fifo() and sorted(p.name for p in tmp_path.iterdir()) == [
        "link.csv",
        "pipe",
        "real.csv",
    ]


def test_a_folder_start_past_its_last_image_is_named_and_its_assumed_rate_told(shared_data):
    crossing = shared_data / "otb" / "Crossing"  # 120 images, no frame rate: 25 per second
    result = vtrack("track", crossing, "--start", "4.79")
    assert result.returncode == 2 and result.stdout == ""  # no CSV header before the error
    # was: "groundtruth_rect.txt has no box for frame 121"
    assert "vtrack: no frame is at or after --start 4.79 s: the last is at 4.76 s" in (
        result.stderr
    )
    assert "the image folder states no frame rate (no seqinfo.ini frameRate): --start and " in (
        result.stderr
    )
    result = vtrack("track", crossing, "--start", "4.7", "--fps", "25", "--quiet")
    assert result.returncode == 0 and result.stderr == ""
    assert [row.split(",")[0] for row in result.stdout.splitlines()] == ["frame", "119", "120"]


def test_a_colour_table_for_a_preset_without_colour_names_is_said_to_do_nothing(
    shared_data, scene_video
):
    table = shared_data / "colornames" / "w2c.mat"
    args = ["--box", "1,1,5,5", "--w2c", table, "--quiet", "--preset"]
    result = vtrack("track", scene_video[0], *args, "mosse_gray")
    assert result.returncode == 0, result.stderr
    assert result.stderr == (
        "vtrack: warning: --w2c: preset mosse_gray uses no Color Names (gray features); the "
        "table has no effect\n"
    )
    assert vtrack("track", scene_video[0], *args, "rcsk_cn").stderr == ""
