"""HOTA on cases whose scores can be worked out by hand."""

import numpy as np
import pytest

from tracking.evaluation.hota import hota


def rows(frames, track_id, box=(10, 10, 20, 40)):
    return np.array([[f, track_id, *box] for f in frames], dtype=float)


def test_perfect_tracking_scores_one():
    gt = np.vstack([rows(range(1, 6), 1), rows(range(1, 6), 2, (50, 10, 20, 40))])
    scores = hota(gt, gt)
    assert scores.hota == pytest.approx(1.0) and scores.loc_a == pytest.approx(1.0)


def test_no_tracks_score_zero():
    assert hota(rows(range(1, 4), 1), np.zeros((0, 6))).hota == 0.0


def test_an_id_switch_halfway_halves_association():
    # Tracker ids A (frames 1-2) and B (3-4) on one person: each association is
    # 2 / (4 + 2 - 2) = 0.5, so AssA = 0.5, DetA = 1 and HOTA = sqrt(0.5).
    gt = rows(range(1, 5), 7)
    tracks = np.vstack([rows([1, 2], 100), rows([3, 4], 200)])
    scores = hota(gt, tracks)
    assert scores.det_a == pytest.approx(1.0)
    assert scores.ass_a == pytest.approx(0.5)
    assert scores.hota == pytest.approx(np.sqrt(0.5))


def test_missing_half_the_frames():
    # TP 2, FN 2: DetA 0.5; the one association 2 / (4 + 2 - 2) = 0.5: HOTA 0.5.
    scores = hota(rows(range(1, 5), 1), rows([1, 2], 5))
    assert scores.det_a == pytest.approx(0.5)
    assert scores.hota == pytest.approx(0.5)


def test_localisation_counts_only_above_each_threshold():
    # A box overlapping the truth with IoU 0.5 is a match for the thresholds 0.05 .. 0.5 only:
    # 10 of the 19, so DetA is 10/19; LocA is 0.5 at those 10 and, by TrackEval's convention,
    # 1 at the 9 thresholds without a match.
    gt = rows([1], 1, (0, 0, 20, 40))
    tracks = rows([1], 9, (0, 0, 20, 20))  # IoU = 400 / 800 = 0.5
    scores = hota(gt, tracks)
    assert scores.det_a == pytest.approx(10 / 19)
    assert scores.loc_a == pytest.approx((10 * 0.5 + 9 * 1.0) / 19)


def test_scores_in_percent_as_the_benchmarks_report_them():
    rows = np.array([[1, 1, 0, 0, 10, 20], [2, 1, 1, 0, 10, 20]], dtype=float)
    assert hota(rows, rows).percent() == {"hota": 100.0, "det_a": 100.0, "ass_a": 100.0}
    assert hota(rows, rows[:0]).percent() == {"hota": 0.0, "det_a": 0.0, "ass_a": 0.0}


def test_ground_truth_marked_not_to_consider_is_left_out_as_trackeval_does():
    # person 2 (consider flag 0) is not ground truth: missing it costs nothing, and covering it
    # is a false positive (TP 4, FP 4: DetA 0.5, AssA 1); it used to count as found
    gt = np.vstack([rows(range(1, 5), 1), rows(range(1, 5), 2, (50, 10, 20, 40))])
    flags = np.array([1] * 4 + [0] * 4, dtype=float)[:, None]
    marked = np.hstack([gt, flags])
    assert hota(marked, gt[:4]).hota == pytest.approx(1.0)
    scores = hota(marked, gt)
    assert scores.det_a == pytest.approx(0.5) and scores.ass_a == pytest.approx(1.0)
    assert hota(np.hstack([gt, np.ones_like(flags)]), gt).hota == pytest.approx(1.0)
