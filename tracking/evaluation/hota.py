"""HOTA, the Higher Order Tracking Accuracy (Luiten et al., IJCV 2021), as TrackEval computes it.

The benchmark scores with TrackEval itself (in its own environment); this in-process version
lets tests score a run without it, and the benchmark checks that the two agree.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.optimize import linear_sum_assignment

from tracking.detection.nms import box_iou

ALPHAS = np.arange(0.05, 0.96, 0.05)
"""Localisation thresholds the scores are averaged over."""

_EPS = np.finfo(float).eps


@dataclass(frozen=True, slots=True)
class HotaScores:
    """HOTA and its parts, averaged over :data:`ALPHAS` (fractions in ``[0, 1]``)."""

    hota: float
    det_a: float
    ass_a: float
    loc_a: float

    def percent(self) -> dict[str, float]:
        """HOTA, DetA and AssA in percent to one decimal, as the benchmarks report them."""
        return {
            "hota": round(100 * self.hota, 1),
            "det_a": round(100 * self.det_a, 1),
            "ass_a": round(100 * self.ass_a, 1),
        }


def hota(ground_truth: np.ndarray, tracks: np.ndarray) -> HotaScores:
    """Score ``tracks`` against ``ground_truth``.

    Parameters
    ----------
    ground_truth, tracks:
        MOTChallenge rows ``(N, >= 6)``: ``frame, id, x, y, w, h, ...``. Ground-truth rows
        whose seventh column (MOTChallenge's "consider" flag) is 0 are left out, as TrackEval
        does for MOT15: a track that covers such a person counts as a false positive.

    Returns
    -------
    HotaScores
    """
    gt = np.asarray(ground_truth, dtype=np.float64).reshape(-1, max(np.shape(ground_truth)[-1], 6))
    if gt.shape[1] >= 7:
        gt = gt[gt[:, 6] != 0]
    tr = np.asarray(tracks, dtype=np.float64).reshape(-1, max(np.shape(tracks)[-1], 6))
    gt_ids, gt_index = np.unique(gt[:, 1].astype(np.int64), return_inverse=True)
    tr_ids, tr_index = np.unique(tr[:, 1].astype(np.int64), return_inverse=True)
    frames = np.union1d(gt[:, 0], tr[:, 0]).astype(np.int64)
    per_frame = []
    for f in frames:
        g, t = gt[:, 0] == f, tr[:, 0] == f
        per_frame.append((gt_index[g], tr_index[t], box_iou(gt[g, 2:6], tr[t, 2:6])))

    # Pass 1: how strongly each gt id and tracker id co-occur, over the whole sequence.
    potential = np.zeros((len(gt_ids), len(tr_ids)))
    gt_count = np.bincount(gt_index, minlength=len(gt_ids)).astype(np.float64)
    tr_count = np.bincount(tr_index, minlength=len(tr_ids)).astype(np.float64)
    for g_idx, t_idx, sim in per_frame:
        if sim.size == 0:
            continue
        denominator = sim.sum(0)[None, :] + sim.sum(1)[:, None] - sim
        potential[np.ix_(g_idx, t_idx)] += np.where(
            denominator > _EPS, sim / np.maximum(denominator, _EPS), 0.0
        )
    global_alignment = potential / np.maximum(
        gt_count[:, None] + tr_count[None, :] - potential, _EPS
    )

    # Pass 2: match per frame, maximising alignment times similarity; count per threshold.
    true_pos = np.zeros(len(ALPHAS))
    loc_sum = np.zeros(len(ALPHAS))
    matches = np.zeros((len(ALPHAS), len(gt_ids), len(tr_ids)))
    for g_idx, t_idx, sim in per_frame:
        if sim.size == 0:
            continue
        score = global_alignment[np.ix_(g_idx, t_idx)] * sim
        rows, cols = linear_sum_assignment(-score)
        for a, alpha in enumerate(ALPHAS):
            ok = sim[rows, cols] >= alpha - _EPS
            true_pos[a] += ok.sum()
            loc_sum[a] += sim[rows[ok], cols[ok]].sum()
            matches[a, g_idx[rows[ok]], t_idx[cols[ok]]] += 1
    false_neg = len(gt) - true_pos
    false_pos = len(tr) - true_pos
    det_a = true_pos / np.maximum(true_pos + false_neg + false_pos, 1)
    association = matches / np.maximum(
        gt_count[None, :, None] + tr_count[None, None, :] - matches, 1
    )
    ass_a = (matches * association).sum(axis=(1, 2)) / np.maximum(true_pos, 1)
    # TrackEval's convention: a threshold with no match has LocA 1 (1e-10 / 1e-10).
    loc_a = np.maximum(loc_sum, 1e-10) / np.maximum(true_pos, 1e-10)
    return HotaScores(
        hota=float(np.mean(np.sqrt(det_a * ass_a))),
        det_a=float(np.mean(det_a)),
        ass_a=float(np.mean(ass_a)),
        loc_a=float(np.mean(loc_a)),
    )
