"""Live streams: what starts the tracks over and what must not. Track ids go on across a service
restart and a worker's death; a publisher that starts counting again starts new tracks; a bad
frame is dropped without ending the tracks. ``vtrack serve`` in a subprocess, the cameras and
consumers real Zenoh sessions in this process, all on loopback.
"""

from __future__ import annotations

import os
import signal
import time

import cv2
import numpy as np
import pytest
import zenoh

from service.streams.keys import StreamKeys
from service.streams.payloads import encode_jpeg, frame_attachment
from service.streams.session import ZenohOptions
from service.streams.tools import member_session, publish_frames, reach_tracker
from tests.service.conftest import Server, wait_for
from tests.streams.live import (
    PUBLIC_SCALE,
    Follower,
    all_taken,
    put_frame,
    start_stream,
    status,
)
from tracking.detection import MotDetections

pytestmark = [pytest.mark.slow, pytest.mark.realtime]


def publish_run(
    session: zenoh.Session,
    keys: StreamKeys,
    frames: list[np.ndarray],
    public: MotDetections,
    first_frame: int,
    first_sequence: int = 0,
) -> None:
    """``frames`` (PETS frames from ``first_frame`` on) at 10 fps with their public detections
    as an upstream detector's (certain people, cheap tracking), every frame delivered."""
    publish_frames(
        session,
        keys,
        iter(frames),
        10.0,
        detections=lambda index: public.for_frame(first_frame + index),
        detections_scale=PUBLIC_SCALE,
        first_sequence=first_sequence,
        wait_for_subscriber=10,
        block=True,
    )


def ids_of(messages) -> set[int]:
    return {t.track_id for m in messages for t in m.tracks}


def ids_of_a_run(
    server: Server,
    camera: str,
    frames: list[np.ndarray],
    first: int,
    public: MotDetections,
    worker_starts: int,
) -> set[int]:
    """The track ids of ``frames`` (PETS frames from ``first`` on) published to the stream's
    worker number ``worker_starts``, by a session of its own (the service may have restarted
    since the last one)."""
    keys = StreamKeys("vtrack", camera)
    session = member_session(ZenohOptions(listen=server.zenoh_listen))
    try:
        with server.client() as client:
            before = wait_for(
                lambda: (
                    (s := status(client, camera))["worker_starts"] == worker_starts
                    and s["state"] == "waiting"
                    and s["counters"]
                ),
                60,
                f"worker {worker_starts} of {camera} to listen",
            )
            assert reach_tracker(session, keys, timeout=30)
            follower = Follower(session, keys)
            publish_run(session, keys, frames, public, first)
            # the counters go on across workers of one service
            taken = all_taken(client, camera, before["frames_in"] + len(frames))
            wait_for(
                lambda: (
                    len(follower.received())
                    == taken["frames_processed"] - before["frames_processed"]
                ),
                10,
                "the tracks messages",
            )
            follower.close()
            return ids_of(follower.received())
    finally:
        session.close()


def test_track_ids_go_on_after_the_service_restarts_and_after_a_worker_dies(
    tmp_path, pets_frames, public_detections
):
    # The tester's walkthrough: ids #10-#18 published, kill -TERM the service, start it again:
    # the stream comes back by itself and its ids must not start at #1 again.
    camera = "gate"
    server = Server(tmp_path / "data", workers=1).start()
    try:
        with server.client() as client:
            assert client.post("/v1/streams", json={"camera": camera}).status_code == 201
        first = ids_of_a_run(server, camera, pets_frames[:15], 0, public_detections, 1)
        # A consumer still following when the service stops is told that the tracks ended.
        keys = StreamKeys("vtrack", camera)
        watching = member_session(ZenohOptions(listen=server.zenoh_listen))
        try:
            assert reach_tracker(watching, keys, timeout=30)
            follower = Follower(watching, keys)
            server.stop()  # SIGTERM
            (end,) = wait_for(follower.endings, 10, "the message that the tracks ended")
        finally:
            watching.close()
        assert end.reason == f"tracking of camera {camera} stopped on this instance"
        assert set(end.track_ids) <= first
        server.start()
        restarted = ids_of_a_run(server, camera, pets_frames[15:30], 15, public_detections, 1)
        with server.client() as client:
            os.kill(status(client, camera)["worker_pid"], signal.SIGKILL)
        revived = ids_of_a_run(server, camera, pets_frames[30:45], 30, public_detections, 2)
        with server.client() as client:  # before: 15, the new worker's own
            assert status(client, camera)["counters"]["frames_in"] == 30
    finally:
        server.stop()
    assert first and restarted and revived, "people are tracked in every run"
    # Each run's ids are above every id of the run before it.
    assert min(restarted) > max(first), (first, restarted)
    assert min(revived) > max(restarted), (restarted, revived)


def test_a_publisher_that_starts_again_starts_the_tracks_over(
    server, session, pets_frames, public_detections
):
    # vtrack publish stopped and started a second later: its sequence numbers start at 0
    # again, its timestamps (the clock) go on rising. The people it shows are the same people
    # a moment later, so a tracker that went on would keep their ids.
    camera = "again"
    keys = StreamKeys("vtrack", camera)
    with server.client() as client:
        start_stream(client, session, camera)
        follower = Follower(session, keys)
        publish_run(session, keys, pets_frames[:20], public_detections, 0)
        taken = all_taken(client, camera, 20)
        wait_for(
            lambda: len(follower.received()) == taken["frames_processed"],
            10,
            "the first run's tracks messages",
        )
        first_run = follower.received()
        publish_run(session, keys, pets_frames[20:40], public_detections, 20)
        final = all_taken(client, camera, 40)
        wait_for(
            lambda: len(follower.received()) == final["frames_processed"],
            10,
            "the second run's tracks messages",
        )
        follower.close()
        second_run = follower.received()[len(first_run) :]
        assert final["restarts"] == 1
        assert second_run[0].sequence < first_run[-1].sequence
        before, after = ids_of(first_run), ids_of(second_run)
        assert before and after
        assert min(after) > max(before), "a track of the new publisher kept an old id"
        # The new run's frames used their own detections, none left over from the old run.
        assert {m.detections for m in second_run[1:]} == {"upstream"}
        assert client.delete(f"/v1/streams/{camera}").status_code == 200


def test_a_bad_frame_is_dropped_and_the_tracks_go_on(
    server, session, pets_frames, public_detections
):
    camera = "glitch"
    keys = StreamKeys("vtrack", camera)
    with server.client() as client:
        start_stream(client, session, camera)
        follower = Follower(session, keys)
        publish_run(session, keys, pets_frames[:20], public_detections, 0)
        all_taken(client, camera, 20)
        # A 1x1 raw frame with a valid attachment: no camera's frame.
        tiny = frame_attachment(20, time.time(), width=1, height=1, format="rgb8")
        put_frame(session, keys, b"\x00\x00\x00", tiny, zenoh.Encoding.APPLICATION_OCTET_STREAM)
        wait_for(lambda: status(client, camera)["counters"]["malformed"] == 1, 30, "the 1x1 frame")
        # One frame of a plausible size between frames of the stream's size: not a change of
        # resolution, since the next frame has the old size again.
        small = cv2.resize(pets_frames[21], (240, 180), interpolation=cv2.INTER_AREA)
        put_frame(
            session,
            keys,
            encode_jpeg(small),
            frame_attachment(21, time.time()),
            zenoh.Encoding.IMAGE_JPEG,
        )
        # As the malformed-payload test: one at a time, so the slot does not skip it unseen. A
        # pause, not a condition: the worker holds the odd frame uncounted until the next one
        # says what it was, and waiting longer than a moment would end the tracks (no frame).
        time.sleep(0.2)
        publish_run(session, keys, pets_frames[22:40], public_detections, 22, first_sequence=22)
        final = all_taken(client, camera, 40)
        wait_for(
            lambda: len(follower.received()) == final["frames_processed"],
            10,
            "the tracks messages",
        )
        follower.close()
        assert final["malformed"] == 2 and final["restarts"] == 0, final
        errors = " | ".join(status(client, camera)["errors"])
        assert "frame 20: a frame size of 1x1 is too small to track" in errors
        assert "frame 21: 240x180 between frames of 480x360; dropped" in errors
        messages = follower.received()
        assert 20 not in {m.sequence for m in messages}
        assert 21 not in {m.sequence for m in messages}
        before = ids_of(m for m in messages if m.sequence < 20)
        after = ids_of(m for m in messages if m.sequence >= 22)
        assert before & after, "the people tracked before the bad frames lost their ids"
        assert client.delete(f"/v1/streams/{camera}").status_code == 200


def test_frames_the_upscale_would_enlarge_beyond_8k_are_refused_one_by_one(server, session):
    # before: a 1440p camera at detector.upscale 4 was tracked at 10240x5760, seconds per frame
    camera = "qhd"
    keys = StreamKeys("vtrack", camera)
    with server.client() as client:
        start_stream(client, session, camera, detector={"upscale": 4})
        image = np.full((1440, 2560, 3), 90, np.uint8)
        attachment = frame_attachment(0, time.time())
        put_frame(session, keys, encode_jpeg(image), attachment, zenoh.Encoding.IMAGE_JPEG)
        wait_for(lambda: status(client, camera)["counters"]["malformed"] == 1, 30, "the frame")
        assert status(client, camera)["errors"] == [
            "frame 0: detector.upscale 4 enlarges frames of 2560x1440 to 10240x5760, beyond the "
            "7680x4320 the detector takes: use at most 3, or leave it unset to let the detector "
            "choose"
        ]
        assert client.delete(f"/v1/streams/{camera}").status_code == 200


def test_timestamps_in_milliseconds_are_warned_of_once(server, session, pets_frames):
    # each frame of a 10 fps camera stamped in milliseconds (since the camera started: Unix
    # time in milliseconds is refused outright) looks 100 s after the one before: every track
    # would end at once, and the stream would track nobody without saying why
    camera = "millis"
    keys = StreamKeys("vtrack", camera)
    with server.client() as client:
        start_stream(client, session, camera)
        started = 3_600_000.0
        for index, frame in enumerate(pets_frames[:6]):
            attachment = frame_attachment(index, started + 100 * index)
            put_frame(session, keys, encode_jpeg(frame), attachment, zenoh.Encoding.IMAGE_JPEG)
            time.sleep(0.1)  # the camera's pace: the arrival times are what is tested
        final = all_taken(client, camera, 6)
        errors = status(client, camera)["errors"]
        assert len(errors) == 1, errors
        # "frames 0 and 1 are stamped 100 s apart but arrived 0.1.. s apart: ..."
        assert errors[0].startswith("frames ") and "00 s apart but arrived 0." in errors[0]
        assert "attachment timestamps are seconds (Unix time)" in errors[0]
        assert final["frames_processed"] >= 2
        assert client.delete(f"/v1/streams/{camera}").status_code == 200


def test_unix_time_in_milliseconds_is_refused_and_the_recording_stream_goes_on(
    server, session, pets_frames
):
    # 1.7e12 "seconds" were accepted, and a recording worker died on each such frame (the MCAP
    # log time in nanoseconds overflows 64 bits) until the stream gave up as failed
    camera = "unixmillis"
    keys = StreamKeys("vtrack", camera)
    with server.client() as client:
        start_stream(client, session, camera, record=True)
        now = time.time()
        for index, frame in enumerate(pets_frames[:3]):
            attachment = frame_attachment(index, (now + 0.1 * index) * 1000)
            put_frame(session, keys, encode_jpeg(frame), attachment, zenoh.Encoding.IMAGE_JPEG)
            time.sleep(0.1)  # the camera's pace, as its timestamps say
        wait_for(lambda: status(client, camera)["counters"]["malformed"] == 3, 30, "3 refusals")
        errors = status(client, camera)["errors"]
        assert errors == [
            f"bad frame attachment (timestamp {(now + 0.1 * index) * 1000:.4g} is more than "
            "1e+10 s after 1970: timestamps are seconds, not milliseconds)"
            for index in range(3)
        ]
        for index, frame in enumerate(pets_frames[3:6], start=3):
            attachment = frame_attachment(index, now + 0.1 * index)
            put_frame(session, keys, encode_jpeg(frame), attachment, zenoh.Encoding.IMAGE_JPEG)
            time.sleep(0.1)  # the camera's pace, as its timestamps say
        assert all_taken(client, camera, 6)["frames_processed"] >= 1
        final = status(client, camera)
        assert final["state"] == "running" and final["error"] is None, final
        assert client.delete(f"/v1/streams/{camera}").status_code == 200
