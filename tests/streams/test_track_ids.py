"""The ids a stream publishes (service.streams.track_ids) and the messages built from them
(service.streams.payloads): never an id twice, across trackers and workers."""

from __future__ import annotations

import logging

import numpy as np

from service.streams.payloads import ended_message, tracks_message
from service.streams.store import StreamStore
from service.streams.track_ids import ID_BLOCK, TrackIds
from tracking.tracks import FrameTracks


def _frame(*ids: int, timestamp: float = 12.5) -> FrameTracks:
    """A frame whose tracks carry the tracker's ``ids``."""
    n = len(ids)
    return FrameTracks(
        3,
        timestamp,
        track_ids=np.array(ids, dtype=np.int64),
        boxes=np.tile([10.0, 20.0, 30.0, 60.0], (n, 1)),
        scores=np.full(n, 0.5),
        occluded=np.zeros(n, bool),
        interpolated=np.zeros(n, bool),
        part_names=(),
        part_xy=np.zeros((n, 0, 2)),
        part_boxes=np.zeros((n, 0, 4)),
        part_visible=np.zeros((n, 0), bool),
        part_measured=np.zeros((n, 0), bool),
    )


def _no_errors(reason: str, level: int) -> None:
    raise AssertionError(f"unexpected error ({logging.getLevelName(level)}): {reason}")


def test_ids_go_on_above_every_published_one_when_a_tracker_or_worker_starts_over(tmp_path):
    database = tmp_path / "jobs.db"
    ids = TrackIds("gate", database, _no_errors)
    try:
        assert ids.published(_frame(1, 2)).track_ids.tolist() == [1, 2]
        ids.start_over()  # a new tracker numbers from 1 again
        assert ids.published(_frame(1)).track_ids.tolist() == [3]
        assert ids.published(_frame()).track_ids.tolist() == []
        ids.start_over()
        assert ids.published(_frame(2, 1)).track_ids.tolist() == [5, 4]
    finally:
        ids.close()
    store = StreamStore(database)
    try:  # reserved before id 1 went out, a block beyond the highest id (2) at a time
        assert store.reserved_track_ids("gate") == 2 + ID_BLOCK
    finally:
        store.close()
    again = TrackIds("gate", database, _no_errors)  # the next worker of the stream
    try:
        assert again.published(_frame(1)).track_ids.tolist() == [2 + ID_BLOCK + 1]
    finally:
        again.close()


def test_without_a_database_ids_start_at_one_with_each_worker():
    ids = TrackIds("gate", None, _no_errors)
    assert ids.published(_frame(1, 7)).track_ids.tolist() == [1, 7]
    ids.start_over()
    assert ids.published(_frame(1)).track_ids.tolist() == [8]
    ids.close()


def test_the_tracks_message_and_its_ending_carry_the_frame_as_published():
    message = tracks_message(
        _frame(4, 9, timestamp=1_765_000_000.1234567),
        frame_index=41,
        camera="gate",
        sequence=7,
        latency=0.25,
        frames_skipped=2,
        detections="upstream",
    )
    assert message.frame_index == 41  # the worker's count, not the tracker's
    assert message.timestamp == 1_765_000_000.1234567  # as stamped, not rounded
    assert [t.track_id for t in message.tracks] == [4, 9]
    assert (message.camera, message.sequence, message.latency) == ("gate", 7, 0.25)
    assert (message.frames_skipped, message.detections) == (2, "upstream")
    assert message.tracks[0].box.w == 30.0 and message.tracks[0].score == 0.5
    ended = ended_message(message, "no frame for 5.0 s")
    assert ended.track_ids == [4, 9] and ended.sequence == 7 and ended.camera == "gate"
    assert ended.timestamp == message.timestamp and ended.reason == "no frame for 5.0 s"
