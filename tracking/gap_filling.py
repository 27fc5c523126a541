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
from dataclasses import dataclass

import numpy as np

from tracking.tracks import FrameTracks, PartEstimate, TrackEstimate
from tracking.types import Box

__all__ = ["GapFiller", "interpolate_track"]


@dataclass(frozen=True, slots=True)
class _Seen:
    frame_index: int
    timestamp: float
    estimate: TrackEstimate


def _lerp_box(a: Box, b: Box, w: np.ndarray) -> np.ndarray:
    """``(len(w), 4)`` boxes from ``a`` (weight 0) to ``b`` (weight 1)."""
    start = a.as_array()
    return start + w[:, None] * (b.as_array() - start)


def _parts(a: TrackEstimate, b: TrackEstimate, w: np.ndarray) -> list[tuple[PartEstimate, ...]]:
    """Each weight's parts. Parts are matched by name; a part only one end has is left out
    (there is nothing to move it towards)."""
    ends = {p.name: p for p in b.parts}
    pairs = [(p, ends[p.name]) for p in a.parts if p.name in ends]
    if not pairs:
        return [()] * len(w)
    xy0 = np.array([[p.x, p.y] for p, _ in pairs])
    xy1 = np.array([[q.x, q.y] for _, q in pairs])
    xy = xy0[None] + w[:, None, None] * (xy1 - xy0)[None]
    boxes = [
        _lerp_box(p.box, q.box, w) if p.box is not None and q.box is not None else None
        for p, q in pairs
    ]
    return [
        tuple(
            PartEstimate(
                name=p.name,
                x=float(xy[k, j, 0]),
                y=float(xy[k, j, 1]),
                box=None if boxes[j] is None else Box(*map(float, boxes[j][k])),
                # a part covered at either end may be covered in between: say so
                visible=p.visible and q.visible,
            )
            for j, (p, q) in enumerate(pairs)
        )
        for k in range(len(w))
    ]


def interpolate_track(
    a: TrackEstimate, t_a: float, b: TrackEstimate, t_b: float, times: list[float]
) -> list[TrackEstimate]:
    """Estimates of one track at ``times`` (between ``t_a`` and ``t_b``), linear in time from
    ``a`` at ``t_a`` to ``b`` at ``t_b``: box, score and part positions. Occluded when either
    end is."""
    span = t_b - t_a
    if span > 0:
        w = (np.asarray(times, dtype=np.float64) - t_a) / span
    else:  # frames sharing one timestamp: spread them evenly instead
        w = np.arange(1, len(times) + 1, dtype=np.float64) / (len(times) + 1)
    w = np.clip(w, 0.0, 1.0)
    boxes = _lerp_box(a.box, b.box, w)
    scores = a.score + w * (b.score - a.score)
    parts = _parts(a, b, w)
    return [
        TrackEstimate(
            track_id=a.track_id,
            box=Box(*map(float, boxes[k])),
            score=float(scores[k]),
            occluded=a.occluded or b.occluded,
            parts=parts[k],
            interpolated=True,
        )
        for k in range(len(w))
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
        self._seen: dict[int, _Seen] = {}

    def push(self, frame: FrameTracks) -> list[FrameTracks]:
        """Take the next frame's tracks; return the earlier frames that gain filled estimates,
        in frame order, each holding only those estimates (the frame's other tracks were
        reported with it)."""
        now = frame.timestamp
        filled: dict[tuple[int, float], list[TrackEstimate]] = {}
        for track in frame.tracks:
            last = self._seen.get(track.track_id)
            self._seen[track.track_id] = _Seen(frame.frame_index, now, track)
            if last is None or now - last.timestamp > self.max_gap:
                continue
            between = [(i, t) for i, t in self._frames if i > last.frame_index]
            if not between:
                continue
            estimates = interpolate_track(
                last.estimate, last.timestamp, track, now, [t for _, t in between]
            )
            for key, estimate in zip(between, estimates, strict=True):
                filled.setdefault(key, []).append(estimate)
        self._frames.append((frame.frame_index, now))
        # older frames and tracks can no longer start a gap short enough to fill
        while self._frames and now - self._frames[0][1] > self.max_gap:
            self._frames.popleft()
        for track_id in [k for k, s in self._seen.items() if now - s.timestamp > self.max_gap]:
            del self._seen[track_id]
        return [FrameTracks(i, t, tuple(filled[i, t])) for i, t in sorted(filled)]
