"""Filling short gaps in tracks: linear in time, only gaps the limit allows, bounded memory."""

from __future__ import annotations

import numpy as np
import pytest

from tracking.gap_filling import GapFiller, interpolate_track
from tracking.tracks import FrameTracks, PartEstimate, TrackEstimate
from tracking.types import Box


def person(track_id: int, x: float, *, score: float = 0.8, occluded: bool = False, head=True):
    parts = (
        PartEstimate("head", x + 5, 10.0, Box(x + 2, 5, 6, 10), visible=head),
        PartEstimate("left_leg", x + 3, 80.0, None, visible=True),
    )
    return TrackEstimate(track_id, Box(x, 0.0, 20.0, 100.0), score, occluded, parts)


def run(filler: GapFiller, frames: list[tuple[float, list[TrackEstimate]]]) -> list[FrameTracks]:
    """Push frames (timestamp, tracks) numbered 0, 1...; every filled frame, in push order."""
    filled = []
    for index, (timestamp, tracks) in enumerate(frames):
        filled += filler.push(FrameTracks(index, timestamp, tuple(tracks)))
    return filled


def test_a_short_gap_is_filled_linearly_in_time_and_marked():
    frames = [(0.0, [person(1, 0)]), (0.1, []), (0.2, []), (0.3, [person(1, 30, score=0.5)])]
    filled = run(GapFiller(0.5), frames)
    assert [f.frame_index for f in filled] == [1, 2]
    assert [f.timestamp for f in filled] == [0.1, 0.2]
    for frame, x in zip(filled, (10.0, 20.0), strict=True):
        (track,) = frame.tracks
        assert track.track_id == 1 and track.interpolated and not track.occluded
        assert track.box.x == pytest.approx(x) and track.box.h == pytest.approx(100.0)
        head, leg = track.parts
        assert (head.name, head.x, head.box.x) == (
            "head",
            pytest.approx(x + 5),
            pytest.approx(x + 2),
        )
        assert (leg.name, leg.x, leg.box) == ("left_leg", pytest.approx(x + 3), None)
    assert [f.tracks[0].score for f in filled] == pytest.approx([0.7, 0.6])


def test_weights_follow_the_frame_times_not_their_count():
    # a recorder that dropped frames: 0.1 s, then 0.4 s, then 0.1 s apart
    frames = [(0.0, [person(1, 0)]), (0.1, []), (0.5, []), (0.6, [person(1, 60)])]
    filled = run(GapFiller(1.0), frames)
    assert [f.tracks[0].box.x for f in filled] == pytest.approx([10.0, 50.0])


def test_gaps_longer_than_the_limit_and_unbroken_tracks_get_nothing():
    long_gap = [(0.0, [person(1, 0)]), (0.3, []), (0.61, [person(1, 30)])]
    assert run(GapFiller(0.6), long_gap) == []
    unbroken = [(t, [person(1, 10 * t)]) for t in (0.0, 0.1, 0.2)]
    assert run(GapFiller(0.6), unbroken) == []
    # a track that ended long ago and whose id is seen again is not joined either
    ended = [(0.0, [person(1, 0)]), *[(0.1 * k, []) for k in range(1, 20)], (2.0, [person(1, 5)])]
    assert run(GapFiller(0.6), ended) == []


def test_tracks_closing_gaps_together_share_the_filled_frames():
    frames = [
        (0.0, [person(1, 0), person(2, 100)]),
        (0.1, [person(2, 100)]),
        (0.2, []),
        (0.3, [person(1, 30), person(2, 100)]),
    ]
    filled = run(GapFiller(0.5), frames)
    assert [(f.frame_index, sorted(t.track_id for t in f.tracks)) for f in filled] == [
        (1, [1]),
        (2, [1, 2]),
    ]


def test_occlusion_and_covered_parts_at_either_end_carry_into_the_gap():
    frames = [
        (0.0, [person(1, 0, head=False)]),
        (0.1, []),
        (0.2, [person(1, 20, occluded=True)]),
    ]
    (frame,) = run(GapFiller(0.5), frames)
    (track,) = frame.tracks
    assert track.occluded
    assert [p.visible for p in track.parts] == [False, True]


def test_parts_only_one_end_has_are_left_out():
    a = person(1, 0)
    b = TrackEstimate(1, Box(20, 0, 20, 100), 0.9, False, a.parts[1:])
    (track,) = interpolate_track(a, 0.0, b, 0.2, [0.1])
    assert [p.name for p in track.parts] == ["left_leg"]


def test_frames_sharing_a_timestamp_are_spread_evenly():
    (first, second) = interpolate_track(person(1, 0), 1.0, person(1, 30), 1.0, [1.0, 1.0])
    assert (first.box.x, second.box.x) == (pytest.approx(10.0), pytest.approx(20.0))


def test_memory_stays_bounded_on_a_long_run():
    filler = GapFiller(0.5)
    rng = np.random.default_rng(0)
    for index in range(2000):
        # people come and go with new ids, and are missed now and then
        tracks = [person(index // 50 + k, float(index)) for k in range(3) if rng.random() > 0.2]
        filler.push(FrameTracks(index, index * 0.04, tuple(tracks)))
    assert len(filler._frames) <= 13  # 0.5 s at 25 fps
    assert len(filler._seen) <= 6


@pytest.mark.parametrize("max_gap", [0.0, -1.0, float("nan"), float("inf")])
def test_a_limit_that_is_not_a_positive_time_is_refused(max_gap):
    with pytest.raises(ValueError, match="max_gap"):
        GapFiller(max_gap)
