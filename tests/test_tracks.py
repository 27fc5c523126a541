"""A frame's tracks as columns: checked shapes, rows selected like supervision's Detections, and
the object view for callers who iterate."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from tracking.tracks import FrameTracks, PartEstimate, TrackEstimate
from tracking.types import Box


def two_people() -> FrameTracks:
    return FrameTracks(
        4,
        0.4,
        track_ids=[3, 8],
        boxes=[[10, 20, 30, 60], [100, 20, 32, 64]],
        scores=[0.9, 0.5],
        occluded=[False, True],
        interpolated=[False, False],
        part_names=("head", "left_foot"),
        part_xy=[[[25, 25], [20, 78]], [[116, 26], [110, 82]]],
        part_boxes=[[[20, 20, 10, 10], [np.nan] * 4], [[111, 21, 10, 10], [105, 77, 10, 10]]],
        part_visible=[[True, True], [True, False]],
        part_measured=[[True, False], [False, False]],
    )


def test_columns_get_their_dtypes_and_rows_come_out_as_estimates():
    tracks = two_people()
    assert len(tracks) == 2
    assert tracks.track_ids.dtype == np.int64 and tracks.boxes.dtype == np.float64
    assert tracks.occluded.dtype == bool and tracks.part_visible.dtype == bool
    first, second = tracks
    assert first == TrackEstimate(
        3,
        Box(10, 20, 30, 60),
        0.9,
        False,
        (
            PartEstimate("head", 25, 25, Box(20, 20, 10, 10), True, True),
            PartEstimate("left_foot", 20, 78, None, True, False),  # NaN: no box
        ),
    )
    assert second.occluded and not second.parts[1].visible
    assert [type(v) for v in (first.track_id, first.score, first.occluded)] == [int, float, bool]


def test_rows_are_selected_by_index_mask_or_slice():
    tracks = two_people()
    assert tracks[1].track_ids.tolist() == [8]
    assert tracks[tracks.scores > 0.6].track_ids.tolist() == [3]
    assert tracks[np.array([1, 0])].track_ids.tolist() == [8, 3]
    assert len(tracks[:0]) == 0 and tracks[:0].part_xy.shape == (0, 2, 2)
    picked = tracks[[1]]
    assert (picked.frame_index, picked.timestamp, picked.part_names) == (4, 0.4, tracks.part_names)
    merged = FrameTracks.merge([tracks[1], tracks[0]])
    assert merged.track_ids.tolist() == [8, 3] and merged.part_boxes.shape == (2, 2, 4)


def test_an_empty_frame_has_every_column_with_no_rows():
    empty = FrameTracks.empty(7, 0.7, ("head",))
    assert len(empty) == 0 and list(empty) == []
    assert empty.boxes.shape == (0, 4) and empty.part_boxes.shape == (0, 1, 4)


def test_columns_of_the_wrong_shape_are_refused():
    tracks = two_people()
    with pytest.raises(ValueError, match=r"boxes must have shape \(2, 4\), got \(2, 3\)"):
        dataclasses.replace(tracks, boxes=np.zeros((2, 3)))
    with pytest.raises(ValueError, match=r"part_xy must have shape \(2, 1, 2\)"):
        dataclasses.replace(tracks, part_names=("head",))
    with pytest.raises(ValueError, match=r"track_ids must have shape \(N,\)"):
        dataclasses.replace(tracks, track_ids=[[3, 8]])
    with pytest.raises(ValueError, match="cannot merge the tracks of frame 5"):
        FrameTracks.merge([tracks, dataclasses.replace(tracks, frame_index=5)])
