"""Counts of lines and zones from whole trajectories in MOTChallenge rows: the ground truth's,
or a tracker's result file, so that a tracker's counts can be held against the truth's with
the same counting code (:mod:`tracking.analytics`)."""

from __future__ import annotations

import numpy as np

from tracking.analytics import AnalyticsConfig, AnalyticsEngine, Counts, ground_points

__all__ = ["count_error", "count_rows"]


def count_rows(rows: np.ndarray, config: AnalyticsConfig, fps: float) -> Counts:
    """The counts of ``config``'s lines and zones over ``rows`` ``(N, >= 6)``: ``frame, id,
    x, y, w, h`` with 1-based frames and 0-based boxes (:func:`tracking.evaluation.mot.
    ground_truth_rows`), frame ``f`` at ``(f - 1) / fps`` seconds."""
    engine = AnalyticsEngine(config)
    rows = np.asarray(rows, dtype=np.float64)
    if not len(rows):
        return engine.counts
    frames = rows[:, 0].astype(np.int64)
    order = np.argsort(frames, kind="stable")
    rows, frames = rows[order], frames[order]
    starts = np.flatnonzero(np.r_[True, frames[1:] != frames[:-1]])
    for block in np.split(rows, starts[1:]):
        boxes = block[:, 2:6]
        engine.update((block[0, 0] - 1) / fps, block[:, 1], ground_points(boxes), boxes)
    return engine.counts


def count_error(counts: Counts, truth: Counts) -> tuple[int, int]:
    """``(sum of |count - true count|, sum of true counts)`` over every line's two directions
    and every zone's entries: their ratio is the relative counting error."""
    error = total = 0
    for name, true in truth.lines.items():
        ours = counts.lines.get(name, {"in": 0, "out": 0})
        for direction in ("in", "out"):
            error += abs(ours[direction] - true[direction])
            total += true[direction]
    for name, true in truth.zones.items():
        ours = counts.zones.get(name, {"entered": 0, "left": 0, "dwell": 0})
        error += abs(ours["entered"] - true["entered"])
        total += true["entered"]
    return error, total
