"""The MOT text a job writes: the benchmarks' formatter, rows in frame, id order even when gap
filling hands in earlier frames late, no id twice in a frame; and the very bytes the MOT
benchmark writes for the same tracks."""

from __future__ import annotations

import json
from pathlib import Path
from types import SimpleNamespace

import pytest

from api_schemas.tracks import BoxModel, FrameTracksMessage, TrackState, VideoInfo
from service.outputs.base import RunSummary, StreamInfo
from service.outputs.mot_out import MotWriter
from tests.conftest import benchmark_module
from tests.service.test_analyze_cli import vtrack
from tracking.evaluation.mot import read_sequence_info

INFO = StreamInfo(width=64, height=48, fps=10.0, frame_step=1, part_names=(), mode="people")
VIDEO = VideoInfo(width=64, height=48, fps=10.0, frames_announced=4, frames_read=4, frame_step=1)
SUMMARY = RunSummary(video=VIDEO, frames_processed=4)


def message(frame_index: int, *ids: int, score: float = 0.123456) -> FrameTracksMessage:
    tracks = [
        TrackState(
            track_id=i,
            box=BoxModel(x=float(i), y=2.0, w=10.0, h=20.0),
            score=score,
            occluded=False,
            interpolated=True,
        )
        for i in ids
    ]
    return FrameTracksMessage(frame_index=frame_index, timestamp=frame_index / 10, tracks=tracks)


def test_late_filled_rows_are_merged_into_frame_and_id_order(tmp_path):
    writer = MotWriter(tmp_path / "tracks_mot.txt", INFO)
    writer.write(None, message(0, 5, 2))
    writer.write(None, message(1, 2))
    writer.write(None, message(2))  # nobody in view
    writer.write_filled(message(1, 7))  # track 7 came back in frame 3: frames 1 and 2 filled
    writer.write_filled(message(2, 7))
    writer.write(None, message(3, 7, 2))
    writer.write_filled(message(0, 3))  # another gap, closed later, reaching further back
    writer.close(SUMMARY)
    assert writer.path.read_text().splitlines() == [
        "1,2,3.00,3.00,10.00,20.00,0.12346,-1,-1,-1",
        "1,3,4.00,3.00,10.00,20.00,0.12346,-1,-1,-1",
        "1,5,6.00,3.00,10.00,20.00,0.12346,-1,-1,-1",
        "2,2,3.00,3.00,10.00,20.00,0.12346,-1,-1,-1",
        "2,7,8.00,3.00,10.00,20.00,0.12346,-1,-1,-1",
        "3,7,8.00,3.00,10.00,20.00,0.12346,-1,-1,-1",
        "4,2,3.00,3.00,10.00,20.00,0.12346,-1,-1,-1",
        "4,7,8.00,3.00,10.00,20.00,0.12346,-1,-1,-1",
    ]
    assert sorted(p.name for p in tmp_path.iterdir()) == ["tracks_mot.txt"]


def test_an_id_twice_in_a_frame_is_refused(tmp_path):
    writer = MotWriter(tmp_path / "tracks_mot.txt", INFO)
    with pytest.raises(ValueError, match="track id 4 appears more than once in frame 1"):
        writer.write(None, message(0, 4, 4))
    writer.write(None, message(0, 4))
    writer.write(None, message(1, 1))
    writer.write_filled(message(0, 4))  # frame 0 has track 4 already
    with pytest.raises(ValueError, match="track id 4 appears more than once in frame 1"):
        writer.close(SUMMARY)
    writer.abort()  # what the job does when a writer fails
    assert sorted(p.name for p in tmp_path.iterdir()) == ["tracks_mot.txt"]


@pytest.mark.slow
def test_a_jobs_mot_file_is_byte_for_byte_the_benchmarks(shared_data, tmp_path):
    """PETS09-S2L1's first 8 s on its public detections, gaps up to 1 s filled: the file a job
    writes (`vtrack analyze`, the service's pipeline and writers) against the file the MOT
    benchmark writes from its own loop over the same tracker (benchmarks/mot.py)."""
    sequence = shared_data / "mot" / "PETS09-S2L1"
    out = tmp_path / "job"
    result = vtrack(
        "analyze", sequence, "--out-dir", out, "--format", "json,mot",
        "--detections", sequence / "det" / "det.txt", "--end", "8", "--fill-gaps", "1",
    )  # fmt: skip
    assert result.returncode == 0, result.stderr
    document = json.loads((out / "trajectories.json").read_text())
    frames = document["frames_processed"]
    assert frames == 56  # 8 s at 7 fps
    # gap filling handed in earlier frames late: the writer had to put them in place
    assert any(p["interpolated"] for t in document["tracks"] for p in t["frames"])

    with benchmark_module("mot") as mot:
        (ours,) = mot.build_ours(["ours"], Path("none.mat"), fill_gaps=1.0).values()
        info = read_sequence_info(sequence)
        detections = mot.public_detections(info)
        rows, _, _ = mot.track_ours(ours, info, frames, _Progress(), False, detections)
        runs = {"ours": {info.name: SimpleNamespace(rows=rows)}}
        mot.write_results(SimpleNamespace(runs=runs), tmp_path / "benchmark")
    job = (out / "tracks_mot.txt").read_bytes()
    assert job.count(b"\n") > 150  # three to five people in each of the 56 frames
    assert job == (tmp_path / "benchmark" / "ours" / "PETS09-S2L1.txt").read_bytes()


class _Progress:
    """What ``track_ours`` reports its frames to (a tqdm bar in the benchmark)."""

    def update(self, frames: int) -> None:
        pass
