"""Filling short gaps in finished tracks, once the person has been seen again.

An online tracker reports a person only in the frames where it trusts its estimate: a brief
occlusion or a few missed detections leave a hole in the trajectory, although the same id comes
back. For a result read after the fact (a job's JSON and MOT files), the frames of such a hole
can be filled: the person's box and parts move linearly in time from the last frame before the
gap to the first frame after it. Motion over a second or less is close to straight at walking
speed, and unlike the tracker's own prediction (``report_missing``) the fill knows where the
person came out. Filled estimates are marked ``interpolated``.

:class:`GapFiller` works as frames come: it remembers each track's last estimate and the recent
frames' times, and when a track returns within ``max_gap`` seconds it hands back the estimates
of the frames in between. Its memory is bounded by ``max_gap``, whatever the video's length.
"""

from __future__ import annotations

from collections import deque
from collections.abc import Sequence

import numpy as np

from tracking.tracks import FrameTracks

__all__ = ["GapFiller", "interpolate_track"]


def interpolate_track(
    a: FrameTracks, b: FrameTracks, frames: Sequence[tuple[int, float]]
) -> list[FrameTracks]:
    """One track's estimates in ``frames`` (``(frame_index, timestamp)`` pairs between ``a``'s
    and ``b``'s), linear in time from ``a`` (one row) to ``b`` (one row of the same track): box,
    score, part centres and part boxes (a part without a box at either end has none). Occluded
    when either end is; a part is visible only where it is at both ends (a part covered at
    either end may be covered in between). Each is a one-row :class:`FrameTracks` marked
    ``interpolated``, in the order of ``frames``.

    Raises
    ------
    ValueError
        If ``a`` or ``b`` is not one row, or their part names differ.
    """
    if len(a) != 1 or len(b) != 1:
        raise ValueError(f"interpolate_track takes one row at each end, got {len(a)} and {len(b)}")
    if a.part_names != b.part_names:
        raise ValueError(f"the two ends have other parts: {a.part_names} and {b.part_names}")
    times = np.array([t for _, t in frames], dtype=np.float64)
    span = b.timestamp - a.timestamp
    if span > 0:
        w = (times - a.timestamp) / span
    else:  # frames sharing one timestamp: spread them evenly instead
        w = np.arange(1, len(times) + 1, dtype=np.float64) / (len(times) + 1)
    w = np.clip(w, 0.0, 1.0)
    boxes = a.boxes + w[:, None] * (b.boxes - a.boxes)  # (K, 4)
    scores = a.scores + w * (b.scores - a.scores)  # (K,)
    xy = a.part_xy + w[:, None, None] * (b.part_xy - a.part_xy)  # (K, P, 2)
    part_boxes = a.part_boxes + w[:, None, None] * (b.part_boxes - a.part_boxes)  # NaN stays
    visible = a.part_visible & b.part_visible  # (1, P)
    occluded = a.occluded | b.occluded
    return [
        FrameTracks(
            index,
            timestamp,
            track_ids=a.track_ids,
            boxes=boxes[k : k + 1],
            scores=scores[k : k + 1],
            occluded=occluded,
            interpolated=np.ones(1, dtype=bool),
            part_names=a.part_names,
            part_xy=xy[k : k + 1],
            part_boxes=part_boxes[k : k + 1],
            part_visible=visible,
            part_measured=np.zeros_like(visible),
        )
        for k, (index, timestamp) in enumerate(frames)
    ]


class GapFiller:
    """Hands back filled estimates for tracks that return within ``max_gap`` seconds.

    Parameters
    ----------
    max_gap:
        Longest time, in seconds, between the last frame a track was reported in and the frame
        it is reported in again for the frames between to be filled.
    """

    def __init__(self, max_gap: float) -> None:
        if not (np.isfinite(max_gap) and max_gap > 0):
            raise ValueError(f"max_gap must be a positive number of seconds, got {max_gap}")
        self.max_gap = float(max_gap)
        self._frames: deque[tuple[int, float]] = deque()  # (frame_index, timestamp), in order
        self._seen: dict[int, FrameTracks] = {}  # each track's last row
        self._part_names: tuple[str, ...] | None = None

    def push(self, frame: FrameTracks) -> list[FrameTracks]:
        """Take the next frame's tracks; return the earlier frames that gain filled estimates,
        in frame order, each holding only those estimates (the frame's other tracks were
        reported with it). A frame with other part names than the previous ones starts over:
        tracks seen before it are not joined to those after."""
        if frame.part_names != self._part_names:
            self._frames.clear()
            self._seen.clear()
            self._part_names = frame.part_names
        now = frame.timestamp
        filled: dict[tuple[int, float], list[FrameTracks]] = {}
        for row, track_id in enumerate(frame.track_ids.tolist()):
            track = frame[row]
            last = self._seen.get(track_id)
            self._seen[track_id] = track
            if last is None or now - last.timestamp > self.max_gap:
                continue
            between = [(i, t) for i, t in self._frames if i > last.frame_index]
            if not between:
                continue
            for key, estimate in zip(between, interpolate_track(last, track, between), strict=True):
                filled.setdefault(key, []).append(estimate)
        self._frames.append((frame.frame_index, now))
        # older frames and tracks can no longer start a gap short enough to fill
        while self._frames and now - self._frames[0][1] > self.max_gap:
            self._frames.popleft()
        for track_id in [k for k, s in self._seen.items() if now - s.timestamp > self.max_gap]:
            del self._seen[track_id]
        return [FrameTracks.merge(filled[key]) for key in sorted(filled)]
