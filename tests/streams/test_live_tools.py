"""``vtrack publish`` and ``vtrack subscribe`` as users run them (each in its own process),
against ``vtrack serve`` on loopback: what they say and how they end. No rate or delay is
measured (every wait is seconds long): not marked realtime, these run beside other tests.
"""

from __future__ import annotations

import re
import signal
import subprocess
import threading
import time

import pytest

from api_schemas.streams import StreamTracksEnded, StreamTracksMessage
from devtools.testing import free_port
from service.streams.keys import StreamKeys
from tests.conftest import REPO_ROOT, sigint_as_in_a_terminal
from tests.service.conftest import PETS_VIDEO, wait_for
from tests.streams.live import (
    PUBLIC_SCALE,
    VTRACK,
    OutputLines,
    camera_running,
    start_stream,
    status,
)

pytestmark = pytest.mark.slow


def connect(server) -> list[str]:
    return ["--connect", server.zenoh_listen[0]]


def test_subscribe_current_on_a_stream_without_tracks_says_what_the_tracker_answered(
    server, session
):
    camera = "quiet"
    with server.client() as client:
        start_stream(client, session, camera)
        asked = subprocess.run(
            [*VTRACK, "subscribe", "--camera", camera, "--current", *connect(server)],
            cwd=REPO_ROOT,
            capture_output=True,
            text=True,
            timeout=60,
        )
        assert asked.returncode == 1
        assert "vtrack subscribe: camera quiet has no tracks yet\n" in asked.stderr
        assert "no tracker answered" not in asked.stderr
        assert "nothing answers" not in asked.stderr
        assert asked.stdout == ""
        assert client.delete(f"/v1/streams/{camera}").status_code == 200


def test_subscribe_ends_quietly_when_its_reader_goes_away(
    server, session, pets_frames, public_detections
):
    # vtrack subscribe --camera door | head -2
    camera = "piped"
    keys = StreamKeys("vtrack", camera)
    with server.client() as client:
        start_stream(client, session, camera)
        subscriber = subprocess.Popen(
            [*VTRACK, "subscribe", "--camera", camera, *connect(server)],
            cwd=REPO_ROOT,
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            text=True,
        )
        stderr = OutputLines(subscriber)
        try:
            with camera_running(session, keys, pets_frames[:20], public_detections):
                lines = [subscriber.stdout.readline() for _ in range(2)]
                subscriber.stdout.close()  # head has its lines and exits
                returncode = subscriber.wait(timeout=30)
        finally:
            subscriber.kill()
            subscriber.wait()
        assert all(line.startswith("seq ") for line in lines), lines
        assert returncode == 0
        wait_for(lambda: stderr.has("following"), 5, "the whole stderr")
        said = "".join(stderr.lines)
        assert "Traceback" not in said and "BrokenPipeError" not in said, said
        assert client.delete(f"/v1/streams/{camera}").status_code == 200


def test_subscribe_json_with_an_output_file_prints_and_records(
    server, session, tmp_path, pets_frames, public_detections
):
    camera = "both"
    keys = StreamKeys("vtrack", camera)
    out = tmp_path / "tracks.jsonl"
    with server.client() as client:
        start_stream(client, session, camera)
        with camera_running(session, keys, pets_frames[:20], public_detections):
            subscribed = subprocess.run(
                [
                    *VTRACK,
                    "subscribe",
                    "--camera",
                    camera,
                    "--json",
                    "--output",
                    str(out),
                    "--count",
                    "3",
                    *connect(server),
                ],
                cwd=REPO_ROOT,
                capture_output=True,
                text=True,
                timeout=60,
            )
        assert subscribed.returncode == 0, subscribed.stderr
        printed = subscribed.stdout.splitlines()
        assert len(printed) == 3
        assert printed == out.read_text().splitlines()
        for line in printed:
            assert StreamTracksMessage.model_validate_json(line).camera == camera
        assert client.delete(f"/v1/streams/{camera}").status_code == 200


def test_subscribe_says_when_the_tracks_end(
    server, session, tmp_path, pets_frames, public_detections
):
    # A dashboard following the tracks learns that the people it shows are gone: in words,
    # and as JSON in the lines it prints and records.
    camera = "exit"
    keys = StreamKeys("vtrack", camera)
    out = tmp_path / "tracks.jsonl"
    command = [*VTRACK, "subscribe", "--camera", camera, *connect(server)]
    with server.client() as client:
        start_stream(client, session, camera)
        words, lines = (
            subprocess.Popen(
                args,
                cwd=REPO_ROOT,
                stdout=subprocess.PIPE,
                stderr=subprocess.PIPE,
                text=True,
                preexec_fn=sigint_as_in_a_terminal,
            )
            for args in (command, [*command, "--json", "--output", str(out)])
        )
        said = [OutputLines(tool) for tool in (words, lines)]
        shown = [OutputLines(tool, "stdout") for tool in (words, lines)]
        try:
            wait_for(lambda: all(s.has("following") for s in said), 30, "both to follow")
            with camera_running(session, keys, pets_frames[:20], public_detections):
                wait_for(lambda: status(client, camera)["tracks"], 60, "tracks")
            assert client.delete(f"/v1/streams/{camera}").status_code == 200
            wait_for(lambda: all(s.has("ended") for s in shown), 30, "the tracks to end")
        finally:
            for tool in (words, lines):
                tool.send_signal(signal.SIGINT)
                tool.wait(timeout=30)
    summary, documents = ([line.rstrip("\n") for line in s.lines] for s in shown)
    end = StreamTracksEnded.model_validate_json(documents[-1])
    assert end.reason == f"tracking of camera {camera} stopped on this instance"
    last = StreamTracksMessage.model_validate_json(documents[-2])
    assert (end.sequence, end.track_ids) == (last.sequence, [t.track_id for t in last.tracks])
    assert out.read_text().splitlines() == documents
    ids = ", ".join(f"#{i}" for i in end.track_ids)
    assert summary[-1] == (
        f"tracks ended after seq {end.sequence} t={end.timestamp:.3f}: {end.reason}"
        + (f"; {ids} will not come again" if ids else "")
    )
    assert summary[-2].startswith(f"seq {end.sequence} ")


def test_publish_interrupted_tells_how_many_frames_it_sent(server, session, shared_data):
    camera = "ctrlc"
    detections = shared_data / "mot" / "PETS09-S2L1" / "det" / "det.txt"
    with server.client() as client:
        start_stream(client, session, camera)
        publisher = subprocess.Popen(
            [
                *VTRACK,
                "publish",
                str(shared_data / PETS_VIDEO),
                "--camera",
                camera,
                "--fps",
                "10",
                "--detections",
                str(detections),
                "--detections-scale",
                str(PUBLIC_SCALE),
                *connect(server),
            ],
            cwd=REPO_ROOT,
            stderr=subprocess.PIPE,
            text=True,
            preexec_fn=sigint_as_in_a_terminal,
        )
        stderr = OutputLines(publisher)
        try:
            wait_for(
                lambda: status(client, camera)["counters"]["frames_in"] >= 10,
                60,
                "frames from vtrack publish",
            )
            publisher.send_signal(signal.SIGINT)  # Ctrl-C
            returncode = publisher.wait(timeout=30)
        finally:
            publisher.kill()
            publisher.wait()
        assert returncode == 0
        wait_for(lambda: stderr.has("frames sent"), 5, "the count")
        said = "".join(stderr.lines)
        sent = int(re.search(r"(\d+) frames sent", said).group(1))
        assert "nothing answers" not in said
        assert sent >= 10, said
        # Every frame it counted reached the service, and no other.
        wait_for(
            lambda: status(client, camera)["counters"]["frames_in"] == sent,
            30,
            f"the service to count {sent} frames",
        )
        assert client.delete(f"/v1/streams/{camera}").status_code == 200


@pytest.mark.parametrize("command", ["publish", "subscribe"])
def test_a_tool_pointed_where_nothing_answers_says_so(shared_data, command):
    # A mistyped endpoint: Zenoh opens the session anyway and keeps trying in the background,
    # so without a word the camera looked like one nobody subscribed to.
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    arguments = {
        "publish": ["publish", str(shared_data / PETS_VIDEO), "--limit", "2", "--wait", "0"],
        "subscribe": ["subscribe", "--current"],
    }[command]
    ran = subprocess.run(
        [*VTRACK, *arguments, "--camera", "door", "--connect", endpoint],
        cwd=REPO_ROOT,
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert f"vtrack {command}: nothing answers at {endpoint} (is vtrack serve running" in (
        ran.stderr
    ), ran.stderr
    assert "Traceback" not in ran.stderr


def test_subscribe_stopped_while_messages_pour_in_ends_cleanly(server, session, tmp_path):
    # before: Ctrl-C closed the --output file while Zenoh's callbacks still wrote to it, and
    # each printed "callback error" and a ValueError traceback (I/O on a closed file). Here,
    # as with a reader that lags, the callbacks wait on a full stdout when Ctrl-C comes.
    keys = StreamKeys("vtrack", "flood")
    out = tmp_path / "flood.jsonl"
    stop = threading.Event()

    def flood() -> None:
        publisher = session.declare_publisher(keys.tracks)
        sequence = 0
        while not stop.is_set():
            message = StreamTracksMessage(
                frame_index=sequence,
                timestamp=float(sequence),
                tracks=[],
                camera="flood",
                sequence=sequence,
                latency=0.0,
                frames_skipped=0,
                detections="service",
            )
            publisher.put(message.model_dump_json())
            sequence += 1
        publisher.undeclare()

    command = [*VTRACK, "subscribe", "--camera", "flood", "--json", "--output", str(out)]
    tool = subprocess.Popen(
        [*command, *connect(server)],
        cwd=REPO_ROOT,
        stdout=subprocess.PIPE,  # not read until Ctrl-C: it fills up
        stderr=subprocess.PIPE,
        text=True,
        preexec_fn=sigint_as_in_a_terminal,
    )
    said = OutputLines(tool)
    thread = threading.Thread(target=flood, daemon=True)
    try:
        wait_for(lambda: said.has("following"), 30, "the subscriber to follow")
        thread.start()
        wait_for(lambda: out.exists() and out.stat().st_size > 30_000, 30, "messages")
        # a pause, not a condition: the flood goes on while the tool's stdout pipe, unread,
        # fills up (by now), which is the case tested
        time.sleep(1.0)
        tool.send_signal(signal.SIGINT)
        threading.Thread(target=tool.stdout.read, daemon=True).start()  # the reader catches up
        assert tool.wait(timeout=30) == 0
    finally:
        stop.set()
        thread.join(10)
        if tool.poll() is None:
            tool.kill()
    assert not [line for line in said.lines if "Traceback" in line or "error" in line]
    lines = out.read_text().splitlines()
    assert all(StreamTracksMessage.model_validate_json(line) for line in lines)
