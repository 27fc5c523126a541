"""Filling short gaps in tracks: linear in time, only gaps the limit allows, bounded memory."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from tracking.gap_filling import GapFiller, interpolate_track
from tracking.tracks import FrameTracks

PARTS = ("head", "left_leg")


def person(
    track_id: int, x: float, *, score: float = 0.8, occluded: bool = False, head: bool = True
) -> FrameTracks:
    """One person as a one-row frame (frame 0 at 0 s until :func:`at` places it): a head with
    a box, a leg without one."""
    return FrameTracks(
        0,
        0.0,
        track_ids=[track_id],
        boxes=[[x, 0.0, 20.0, 100.0]],
        scores=[score],
        occluded=[occluded],
        interpolated=[False],
        part_names=PARTS,
        part_xy=[[[x + 5, 10.0], [x + 3, 80.0]]],
        part_boxes=[[[x + 2, 5, 6, 10], [np.nan] * 4]],
        part_visible=[[head, True]],
        part_measured=[[False, False]],
    )


def at(index: int, timestamp: float, people: list[FrameTracks]) -> FrameTracks:
    """The people in frame ``index`` at ``timestamp``."""
    if not people:
        return FrameTracks.empty(index, timestamp, PARTS)
    placed = [dataclasses.replace(p, frame_index=index, timestamp=timestamp) for p in people]
    return FrameTracks.merge(placed)


def run(filler: GapFiller, frames: list[tuple[float, list[FrameTracks]]]) -> list[FrameTracks]:
    """Push frames (timestamp, people) numbered 0, 1...; every filled frame, in push order."""
    filled = []
    for index, (timestamp, people) in enumerate(frames):
        filled += filler.push(at(index, timestamp, people))
    return filled


def test_a_short_gap_is_filled_linearly_in_time_and_marked():
    frames = [(0.0, [person(1, 0)]), (0.1, []), (0.2, []), (0.3, [person(1, 30, score=0.5)])]
    filled = run(GapFiller(0.5), frames)
    assert [f.frame_index for f in filled] == [1, 2]
    assert [f.timestamp for f in filled] == [0.1, 0.2]
    for frame, x in zip(filled, (10.0, 20.0), strict=True):
        (track,) = frame  # the object view of the row
        assert track.track_id == 1 and track.interpolated and not track.occluded
        assert track.box.x == pytest.approx(x) and track.box.h == pytest.approx(100.0)
        head, leg = track.parts
        assert (head.name, head.x, head.box.x) == (
            "head",
            pytest.approx(x + 5),
            pytest.approx(x + 2),
        )
        assert (leg.name, leg.x, leg.box) == ("left_leg", pytest.approx(x + 3), None)
    assert [f.scores[0] for f in filled] == pytest.approx([0.7, 0.6])
    assert not np.any([f.part_measured for f in filled])  # filled in: nothing measured


def test_weights_follow_the_frame_times_not_their_count():
    # a recorder that dropped frames: 0.1 s, then 0.4 s, then 0.1 s apart
    frames = [(0.0, [person(1, 0)]), (0.1, []), (0.5, []), (0.6, [person(1, 60)])]
    filled = run(GapFiller(1.0), frames)
    assert [f.boxes[0, 0] for f in filled] == pytest.approx([10.0, 50.0])


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
    assert [(f.frame_index, sorted(f.track_ids.tolist())) for f in filled] == [
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
    assert frame.occluded.tolist() == [True]
    assert frame.part_visible.tolist() == [[False, True]]


def test_ends_with_other_parts_are_not_joined():
    legless = dataclasses.replace(
        at(2, 0.2, [person(1, 20)])[0],
        part_names=("head",),
        part_xy=np.zeros((1, 1, 2)),
        part_boxes=np.zeros((1, 1, 4)),
        part_visible=[[True]],
        part_measured=[[False]],
    )
    with pytest.raises(ValueError, match="other parts"):
        interpolate_track(at(0, 0.0, [person(1, 0)]), legless, [(1, 0.1)])
    # a pipeline whose parts change (none does) starts the filler over
    filler = GapFiller(0.5)
    assert run(filler, [(0.0, [person(1, 0)]), (0.1, [])]) == []
    assert filler.push(legless) == []


def test_frames_sharing_a_timestamp_are_spread_evenly():
    a, b = at(0, 1.0, [person(1, 0)]), at(3, 1.0, [person(1, 30)])
    (first, second) = interpolate_track(a, b, [(1, 1.0), (2, 1.0)])
    assert (first.boxes[0, 0], second.boxes[0, 0]) == (pytest.approx(10.0), pytest.approx(20.0))
    assert (first.frame_index, second.frame_index) == (1, 2)


def test_memory_stays_bounded_on_a_long_run():
    filler = GapFiller(0.5)
    rng = np.random.default_rng(0)
    for index in range(2000):
        # people come and go with new ids, and are missed now and then
        people = [person(index // 50 + k, float(index)) for k in range(3) if rng.random() > 0.2]
        filler.push(at(index, index * 0.04, people))
    assert len(filler._frames) <= 13  # 0.5 s at 25 fps
    assert len(filler._seen) <= 6


@pytest.mark.parametrize("max_gap", [0.0, -1.0, float("nan"), float("inf")])
def test_a_limit_that_is_not_a_positive_time_is_refused(max_gap):
    with pytest.raises(ValueError, match="max_gap"):
        GapFiller(max_gap)
