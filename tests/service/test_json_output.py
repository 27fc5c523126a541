"""The JSON result writer: frames in, trajectories out, in memory that does not grow with the
video."""

from __future__ import annotations

import json
import tracemalloc

import pytest

from api_schemas.tracks import (
    BoxModel,
    FrameTracksMessage,
    PartState,
    TrackState,
    Trajectories,
    VideoInfo,
)
from service.outputs.base import RunSummary, StreamInfo
from service.outputs.json_out import JsonWriter, read_trajectories

PARTS = ("head", "left_shoulder", "right_shoulder")


def _track(track_id: int, frame: int) -> TrackState:
    parts = [
        PartState(name=name, x=frame + k, y=2.5 * k, box=None, visible=k != 1)
        for k, name in enumerate(PARTS)
    ]
    box = BoxModel(x=frame + 0.25, y=track_id * 10.0, w=30.0, h=70.5)
    return TrackState(track_id=track_id, box=box, score=0.5, occluded=frame % 2 == 1, parts=parts)


def _run(path, frames: list[list[int]], skeleton: tuple[tuple[str, str], ...] = ()) -> JsonWriter:
    """A writer fed one message per frame with the given track ids, left open."""
    info = StreamInfo(640, 480, 25.0, 1, PARTS, "people", job_id="job1", skeleton=skeleton)
    writer = JsonWriter(path, info)
    for index, ids in enumerate(frames):
        tracks = [_track(i, index) for i in ids]
        writer.write(
            None, FrameTracksMessage(frame_index=index, timestamp=index / 25, tracks=tracks)
        )
    return writer


def _summary(frames: int) -> RunSummary:
    video = VideoInfo(
        width=640, height=480, fps=25.0, frames_announced=frames, frames_read=frames, frame_step=1
    )
    return RunSummary(video, frames)


def test_frames_are_grouped_into_trajectories_by_id(tmp_path):
    path = tmp_path / "trajectories.json"
    frames = [[7], [7, 2], [2, 7, 11], [11], [], [2]]
    _run(path, frames).close(_summary(len(frames)))

    document = read_trajectories(path)
    assert isinstance(document, Trajectories)
    assert (document.job_id, document.mode, document.part_names) == ("job1", "people", list(PARTS))
    assert document.frames_processed == 6 and document.video.frames_read == 6
    assert [t.track_id for t in document.tracks] == [2, 7, 11]
    expected = {2: [1, 2, 5], 7: [0, 1, 2], 11: [2, 3]}
    for trajectory in document.tracks:
        assert [p.frame_index for p in trajectory.frames] == expected[trajectory.track_id]
        for point in trajectory.frames:
            track = _track(trajectory.track_id, point.frame_index)
            assert point.timestamp == point.frame_index / 25
            assert (point.box, point.occluded, point.parts) == (
                track.box,
                track.occluded,
                track.parts,
            )
    assert [p.name for p in tmp_path.iterdir()] == ["trajectories.json"]  # no scratch left


def test_the_document_names_the_skeleton(tmp_path):
    path = tmp_path / "trajectories.json"
    skeleton = (("head", "left_shoulder"), ("head", "right_shoulder"))
    _run(path, [[1]], skeleton).close(_summary(1))
    assert json.loads(path.read_text())["skeleton"] == [list(edge) for edge in skeleton]
    assert read_trajectories(path).skeleton == list(skeleton)


def test_results_written_before_the_skeleton_still_load(tmp_path):
    path = tmp_path / "trajectories.json"
    _run(path, [[1]]).close(_summary(1))
    document = json.loads(path.read_text())
    assert document.pop("skeleton") == []  # nothing to draw
    assert Trajectories.model_validate(document).skeleton == []


def test_a_video_without_tracks_gives_an_empty_list(tmp_path):
    path = tmp_path / "trajectories.json"
    _run(path, [[], []]).close(_summary(2))
    assert read_trajectories(path).tracks == []


def test_an_aborted_writer_leaves_nothing(tmp_path):
    path = tmp_path / "trajectories.json"
    _run(path, [[1], [1]]).abort()
    assert list(tmp_path.iterdir()) == []


@pytest.mark.slow
def test_memory_does_not_grow_with_the_video(tmp_path):
    # 3000 frames of eight people: 24 000 points, as models about 200 MB; the writer keeps two
    # integers per point and copies the serialised points from its scratch file.
    path = tmp_path / "trajectories.json"
    writer = _run(path, [[f // 300 * 8 + k for k in range(8)] for f in range(3000)])
    tracemalloc.start()
    try:
        writer.close(_summary(3000))
        _, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    assert peak < 8 * 2**20, f"closing took {peak / 2**20:.1f} MB"
    assert sum(len(t.frames) for t in read_trajectories(path).tracks) == 24000
