"""Multi-person 2D body keypoints with an OpenPose-style network (Open Model Zoo's
``human-pose-estimation-0001``) on OpenVINO, decoded bottom-up with part affinity fields.

The network gives, at stride 8 of its input, 19 heatmaps (18 keypoints and the background) and 38
part affinity fields (PAFs): for each of 19 limbs a 2D vector field pointing from the limb's
first keypoint to its second along the limb. Decoding follows Cao et al., *Realtime Multi-Person
2D Pose Estimation using Part Affinity Fields*, CVPR 2017, as Open Model Zoo's demos implement it
(``demos/common/python/model_zoo/model_api/models/open_pose.py``,
``demos/common/cpp/models/src/openpose_decoder.cpp``), in vectorized numpy:

1. the heatmaps are enlarged 4 times (bicubic), so keypoints are placed at 2 input pixels, not 8
   (the PAFs are not: they are read between their pixels, bilinearly, where the reference
   enlarges them too and reads the nearest pixel);
2. :func:`find_peaks`: keypoint candidates are the local maxima of each heatmap above a threshold
   (non-maximum suppression, Cao et al. sec. 2.2);
3. :func:`group_people`: each candidate limb (every pair of candidates of its two keypoint types)
   is scored by the line integral of its PAF along the segment between them (eq. 10-11, sampled
   at 10 points); the pairs are matched greedily by score, one limb per keypoint (the bipartite
   matching of eq. 12-13 relaxed as in the paper), and limbs sharing keypoints are joined into
   skeletons, tree edge by tree edge from the neck;
4. :func:`decode_openpose` maps the keypoints back to frame pixels.

:meth:`PoseEstimator.estimate` feeds whole frames at their aspect, the shorter side kept in
576-1080 pixels like the CNN person detector: on PETS09-S2L1 the model placed a skeleton on 229
of 232 people at 576x768 but on 154 at its native 256x456 (``../shared/data/models/README.md``).
:meth:`PoseEstimator.estimate_crops` feeds a crop around each of a tracker's people instead,
each brought to one size (the person 128 px high): cheaper than the frame for a few people, and
small people are seen larger (docs/benchmarks.md, "Pose and re-identification").
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np

from tracking.detection.cnn.config import check_input_rule, input_scale_for, input_size_for
from tracking.detection.cnn.runtime import CnnModelError, Network, load_network
from tracking.types import is_int, validate_uint8_frame

__all__ = [
    "KEYPOINT_NAMES",
    "LIMBS",
    "PoseConfig",
    "PoseEstimator",
    "Poses",
    "decode_openpose",
    "find_peaks",
    "group_people",
]

KEYPOINT_NAMES = (
    "nose",
    "neck",
    "right_shoulder",
    "right_elbow",
    "right_wrist",
    "left_shoulder",
    "left_elbow",
    "left_wrist",
    "right_hip",
    "right_knee",
    "right_ankle",
    "left_hip",
    "left_knee",
    "left_ankle",
    "right_eye",
    "left_eye",
    "right_ear",
    "left_ear",
)
"""The network's 18 keypoints in its heatmap order (OpenPose's COCO order, with a neck; Open
Model Zoo's demo maps them to COCO's 17 by ``reorder_map``); heatmap 18 is the background."""

LIMBS = (
    # (first keypoint, second keypoint, PAF channel of x; y is the next channel), in the order
    # the skeletons are grown: the neck's limbs first, so that each later limb meets a skeleton.
    (1, 2, 12),
    (1, 5, 20),
    (2, 3, 14),
    (3, 4, 16),
    (5, 6, 22),
    (6, 7, 24),
    (1, 8, 0),
    (8, 9, 2),
    (9, 10, 4),
    (1, 11, 6),
    (11, 12, 8),
    (12, 13, 10),
    (1, 0, 28),
    (0, 14, 30),
    (14, 16, 34),
    (0, 15, 32),
    (15, 17, 36),
    (2, 16, 18),
    (5, 17, 26),
)
"""The 19 limbs (Open Model Zoo's ``BODY_PARTS_KPT_IDS`` and ``BODY_PARTS_PAF_IDS``); the last
two (shoulder-ear) are the redundant connections OpenPose adds for robustness."""

_SAMPLES = 10  # points of the PAF line integral (eq. 11), the reference's
_PAIRS_PER_PASS = 20_000  # candidate limbs scored at once: 20,000 x 10 samples, a few MB


@dataclass(frozen=True)
class Poses:
    """Skeletons found in one frame.

    Attributes
    ----------
    keypoints:
        ``(N, 18, 2)`` float64 ``x, y`` in frame pixels (0-based, pixel centres at integers), in
        :data:`KEYPOINT_NAMES` order; NaN where a keypoint was not found.
    scores:
        ``(N, 18)`` the heatmap's value at each keypoint (about ``[0, 1]``); 0 where missing.
    person_scores:
        ``(N,)`` each skeleton's score as in the reference: the sum of its keypoints' heatmap
        values and of its limbs' PAF scores (eq. 11), so more complete skeletons score higher.
    """

    keypoints: np.ndarray
    scores: np.ndarray
    person_scores: np.ndarray

    def __len__(self) -> int:
        return len(self.person_scores)

    @classmethod
    def empty(cls) -> Poses:
        """No skeleton."""
        k = len(KEYPOINT_NAMES)
        return cls(np.zeros((0, k, 2)), np.zeros((0, k)), np.zeros(0))

    def found(self) -> np.ndarray:
        """``(N, 18)`` bool: which keypoints each skeleton has."""
        return ~np.isnan(self.keypoints[..., 0])

    def boxes(self) -> np.ndarray:
        """``(N, 4)`` ``x, y, w, h``: the tight box of each skeleton's found keypoints (NaN for
        a skeleton with none). The keypoints are joints, not the body's outline: the box
        misses the top of the head, the feet and the arms' width, so it is smaller than a
        person box."""
        if len(self) == 0:
            return np.zeros((0, 4))
        found = self.found()
        points = self.keypoints
        with np.errstate(invalid="ignore"):
            low = np.where(found[..., None], points, np.inf).min(axis=1)
            high = np.where(found[..., None], points, -np.inf).max(axis=1)
        boxes = np.concatenate([low, high - low], axis=1)
        boxes[~found.any(axis=1)] = np.nan
        return boxes


def find_peaks(
    heatmaps: np.ndarray, threshold: float = 0.1, radius: int = 3, max_peaks: int = 100
) -> list[np.ndarray]:
    """Keypoint candidates: the local maxima of each heatmap (Cao et al. sec. 2.2, non-maximum
    suppression of the confidence maps).

    A pixel is a peak if it is above ``threshold`` and the largest in the ``(2 radius + 1)``
    square around it (a grey dilation of each map, OpenCV's, 10 times scipy's maximum filter
    here; Open Model Zoo's demo puts this max pooling, 7x7 at 4 times enlarged maps, into the
    network). Of equal maxima closer than the window (a plateau), the first in raster order
    stays.

    Parameters
    ----------
    heatmaps:
        ``(K, H, W)`` (or ``(1, K, H, W)``) one confidence map per keypoint type.

    Returns
    -------
    list of (P, 3) float64 arrays
        Per keypoint type, its peaks ``x, y, score`` in map pixels, the best first (at most
        ``max_peaks``).
    """
    maps = np.asarray(heatmaps, dtype=np.float32)
    if maps.ndim == 4 and maps.shape[0] == 1:
        maps = maps[0]
    if maps.ndim != 3:
        raise ValueError(f"heatmaps must be (K, H, W), got shape {np.shape(heatmaps)}")
    size = 2 * radius + 1
    kernel = np.ones((size, size), dtype=np.uint8)
    # dilation's border is -inf: a peak at the edge is compared with its inside neighbours only
    maps = np.ascontiguousarray(maps)
    largest = np.empty_like(maps)
    for m, out in zip(maps, largest, strict=True):
        cv2.dilate(m, kernel, dst=out)
    # the few pixels above the threshold first (a flat index: np.nonzero over the whole stack
    # of maps took half the decoding's time), then which of them are their window's maximum
    flat, flat_largest = maps.reshape(-1), largest.reshape(-1)
    candidates = np.flatnonzero(flat > threshold)
    candidates = candidates[flat[candidates] == flat_largest[candidates]]
    kinds, ys, xs = np.unravel_index(candidates, maps.shape)
    values = flat[candidates]
    # A maximum has no larger value in its window, only equal ones (a plateau; two peaks of a
    # map within a window of each other are equal): each that has an earlier peak (raster
    # order) in its window goes. Only maps with two peaks of one value can hold such a pair;
    # there, each peak's window's earliest peak is a min filter of the peaks' raster indices.
    by_value = np.lexsort((values, kinds))
    tie = (np.diff(kinds[by_value]) == 0) & (np.diff(values[by_value]) == 0)
    keep = np.ones(len(values), dtype=bool)
    if tie.any():
        width = maps.shape[2]
        raster = (ys * width + xs).astype(np.float32)  # exact below 2**24 pixels
        index = np.full(maps.shape, np.inf, dtype=np.float32)
        index[kinds, ys, xs] = raster
        plateaus = np.unique(kinds[by_value[1:][tie]])
        earliest = index.copy()
        for kind in plateaus:  # the few maps with a plateau; outside a map: +inf
            cv2.erode(index[kind], kernel, dst=earliest[kind])
        keep = earliest[kinds, ys, xs] == raster
    kinds, xs, ys, values = kinds[keep], xs[keep], ys[keep], values[keep]
    # map by map, the best first (a stable sort: equal scores in raster order), at most
    # max_peaks of each
    order = np.lexsort((-values, kinds))
    kinds = kinds[order]
    counts = np.bincount(kinds, minlength=len(maps))
    rank = np.arange(len(kinds)) - np.repeat(np.cumsum(counts) - counts, counts)
    kept = order[rank < max_peaks]
    found = np.column_stack([xs[kept], ys[kept], values[kept]]).astype(np.float64)
    return np.split(found, np.cumsum(np.minimum(counts, max_peaks))[:-1])


def limb_scores(
    starts: np.ndarray, ends: np.ndarray, paf: np.ndarray, min_paf_score: float = 0.05
) -> tuple[np.ndarray, np.ndarray]:
    """The PAF score of every candidate limb from ``starts`` ``(n, 2)`` to ``ends`` ``(m, 2)``.

    Cao et al. eq. 10-11: the line integral of the field ``paf`` ``(2, H, W)`` along the
    segment, projected on its direction, sampled at 10 evenly spaced points (the field read
    bilinearly between its pixels: the reference reads the nearest pixel of 4 times enlarged
    fields, which costs a bicubic enlargement of 38 maps). As in the reference, the mean is
    over the samples that agree with the direction (projection > ``min_paf_score``), and the
    fraction of those is returned beside it; the paper's prior against limbs longer than half
    the map's height is added (``min(H / (2 length) - 1, 0)``, Open Model Zoo's C++ decoder
    and the original code).

    Returns
    -------
    scores, agreeing:
        ``(n, m)`` each, the mean agreeing projection (plus the length prior) and the fraction
        of agreeing samples.
    """
    firsts, seconds = _every_pair(starts, ends)
    channels = np.zeros(len(firsts), np.intp)
    scores, agreeing = _pair_scores(firsts, seconds, paf, channels, min_paf_score)
    return scores.reshape(len(starts), len(ends)), agreeing.reshape(len(starts), len(ends))


def _every_pair(starts: np.ndarray, ends: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Every start with every end, start by start: ``(n m, 2)`` each."""
    return np.repeat(starts, len(ends), axis=0), np.tile(ends, (len(starts), 1))


def _limb_type_scores(
    peaks: list[np.ndarray], fields: np.ndarray, min_paf_score: float
) -> list[tuple[np.ndarray, np.ndarray]]:
    """:func:`limb_scores` of every limb type of :data:`LIMBS`, ``(n, m)`` scores and
    agreeing fractions each, in as few passes as :data:`_PAIRS_PER_PASS` allows (a pass per
    type cost most of a small crop's decoding; the bound keeps a crowd's memory small)."""
    sizes = [len(peaks[first]) * len(peaks[second]) for first, second, _ in LIMBS]
    out: list[tuple[np.ndarray, np.ndarray]] = []
    start = 0
    while start < len(LIMBS):
        stop = start + 1
        while stop < len(LIMBS) and sum(sizes[start : stop + 1]) <= _PAIRS_PER_PASS:
            stop += 1
        limbs = LIMBS[start:stop]
        pairs = [
            _every_pair(peaks[first][:, :2], peaks[second][:, :2]) for first, second, _ in limbs
        ]
        channels = np.repeat([channel for _, _, channel in limbs], sizes[start:stop])
        scores, agreeing = _pair_scores(
            np.concatenate([p[0] for p in pairs]).reshape(-1, 2),
            np.concatenate([p[1] for p in pairs]).reshape(-1, 2),
            fields,
            channels,
            min_paf_score,
        )
        ends = np.cumsum(sizes[start:stop])[:-1]
        for (first, second, _), s, a in zip(
            limbs, np.split(scores, ends), np.split(agreeing, ends), strict=True
        ):
            shape = (len(peaks[first]), len(peaks[second]))
            out.append((s.reshape(shape), a.reshape(shape)))
        start = stop
    return out


def _pair_scores(
    starts: np.ndarray,
    ends: np.ndarray,
    pafs: np.ndarray,
    channels: np.ndarray,
    min_paf_score: float,
) -> tuple[np.ndarray, np.ndarray]:
    """:func:`limb_scores` of ``P`` segments ``starts`` to ``ends`` ``(P, 2)``, each along its own
    field: channels ``channels[p]`` and the next (x, y) of ``pafs`` ``(C, H, W)``. One pass for
    the candidate limbs of every limb type (:func:`group_people`): ``(P,)`` each."""
    height = pafs.shape[1]
    vectors = ends - starts  # (P, 2)
    lengths = np.linalg.norm(vectors, axis=-1)
    units = vectors / np.maximum(lengths, 1e-6)[..., None]  # a zero-length limb scores 0
    steps = np.linspace(0.0, 1.0, _SAMPLES)
    points = starts[:, None, :] + steps[None, :, None] * vectors[:, None, :]  # (P, samples, 2)
    field = _bilinear(pafs, points[..., 0], points[..., 1], channels[:, None])  # (2, P, samples)
    projection = field[0] * units[:, 0, None] + field[1] * units[:, 1, None]
    agree = projection > min_paf_score
    count = agree.sum(axis=-1)
    mean = np.where(agree, projection, 0.0).sum(axis=-1) / np.maximum(count, 1)
    prior = np.minimum(0.5 * height / np.maximum(lengths, 1e-6) - 1.0, 0.0)
    return mean + prior, count / _SAMPLES


def _bilinear(maps: np.ndarray, x: np.ndarray, y: np.ndarray, channels: np.ndarray) -> np.ndarray:
    """Two maps of ``maps`` ``(C, H, W)``, ``channels`` and the next (broadcast with ``x``),
    read at points ``x, y`` (clamped to the maps) by bilinear interpolation: ``(2, *x.shape)``."""
    height, width = maps.shape[1:]
    x = np.clip(x, 0.0, width - 1.0)
    y = np.clip(y, 0.0, height - 1.0)
    x0 = np.minimum(np.floor(x).astype(np.intp), width - 2) if width > 1 else np.zeros_like(x, int)
    y0 = (
        np.minimum(np.floor(y).astype(np.intp), height - 2) if height > 1 else np.zeros_like(y, int)
    )
    x1 = np.minimum(x0 + 1, width - 1)
    y1 = np.minimum(y0 + 1, height - 1)
    fx, fy = x - x0, y - y0
    pair = np.stack([channels, channels + 1])  # (2, ...)
    top = maps[pair, y0, x0] * (1 - fx) + maps[pair, y0, x1] * fx
    bottom = maps[pair, y1, x0] * (1 - fx) + maps[pair, y1, x1] * fx
    return top * (1 - fy) + bottom * fy


def group_people(
    peaks: list[np.ndarray],
    pafs: np.ndarray,
    *,
    min_paf_score: float = 0.05,
    min_agreeing: float = 0.8,
    min_keypoints: int = 3,
    min_mean_score: float = 0.2,
) -> Poses:
    """Skeletons from keypoint candidates and part affinity fields (Cao et al. sec. 2.4).

    For each limb of :data:`LIMBS` in turn, every pair of candidates of its two keypoint types
    is scored (:func:`limb_scores`, eq. 10-11); pairs with a positive score and more than
    ``min_agreeing`` of their samples along the field are limbs, chosen greedily best first,
    each candidate in one limb at most (the paper's relaxation of the matching, eq. 13). A limb
    extends the skeleton that holds one of its ends, starts a skeleton if neither is held, and
    merges the two skeletons holding its ends if they share no keypoint type (Open Model Zoo's
    ``update_poses``). Skeletons with fewer than ``min_keypoints`` keypoints, or a score per
    keypoint under ``min_mean_score`` (the C++ demo's ``minSubsetScore``), are dropped.

    Parameters
    ----------
    peaks:
        Per keypoint type (18), its candidates ``(P, 3)`` ``x, y, score`` (:func:`find_peaks`).
    pafs:
        ``(38, H, W)`` (or ``(1, 38, H, W)``) the fields, in the peaks' pixel grid.

    Returns
    -------
    Poses
        In the maps' pixels, the best scoring skeleton first.
    """
    fields = np.asarray(pafs, dtype=np.float32)
    if fields.ndim == 4 and fields.shape[0] == 1:
        fields = fields[0]
    kinds = len(KEYPOINT_NAMES)
    if len(peaks) < kinds or fields.ndim != 3 or fields.shape[0] < 2 * len(LIMBS):
        raise ValueError(
            f"need {kinds} peak lists and (38, H, W) fields, got {len(peaks)} lists and "
            f"fields of shape {np.shape(pafs)}"
        )
    # skeletons as rows: which candidate (index into its type's list, -1: none) per type
    members = np.zeros((0, kinds), dtype=np.intp)
    totals: list[float] = []
    limb_types = _limb_type_scores(peaks, fields, min_paf_score)
    for (first, second, _), (scores, agreeing) in zip(LIMBS, limb_types, strict=True):
        a, b = peaks[first], peaks[second]
        ia, ib = np.nonzero((scores > 0) & (agreeing > min_agreeing))
        if len(ia) == 0:
            continue
        order = np.argsort(-scores[ia, ib], kind="stable")
        used_a, used_b = set(), set()
        for i, j in zip(ia[order].tolist(), ib[order].tolist(), strict=True):
            if i in used_a or j in used_b:
                continue
            used_a.add(i)
            used_b.add(j)
            members, totals = _join(
                members, totals, first, i, second, j, a[i, 2], b[j, 2], float(scores[i, j])
            )
    if len(members) == 0:
        return Poses.empty()
    totals_array = np.asarray(totals)
    counts = (members >= 0).sum(axis=1)
    keep = (counts >= min_keypoints) & (totals_array / np.maximum(counts, 1) >= min_mean_score)
    members, totals_array = members[keep], totals_array[keep]
    order = np.argsort(-totals_array, kind="stable")
    members, totals_array = members[order], totals_array[order]
    keypoints = np.full((len(members), kinds, 2), np.nan)
    confidences = np.zeros((len(members), kinds))
    for kind in range(kinds):
        held = members[:, kind] >= 0
        chosen = peaks[kind][members[held, kind]]
        keypoints[held, kind] = chosen[:, :2]
        confidences[held, kind] = chosen[:, 2]
    return Poses(keypoints, confidences, totals_array)


def _join(
    members: np.ndarray,
    totals: list[float],
    first: int,
    i: int,
    second: int,
    j: int,
    score_i: float,
    score_j: float,
    limb: float,
) -> tuple[np.ndarray, list[float]]:
    """Add the limb (candidate ``i`` of type ``first``, ``j`` of type ``second``) to the
    skeletons: Open Model Zoo's ``update_poses``."""
    holds_i = np.flatnonzero(members[:, first] == i)
    holds_j = np.flatnonzero(members[:, second] == j)
    if len(holds_i) == 0 and len(holds_j) == 0:
        row = np.full((1, members.shape[1]), -1, dtype=np.intp)
        row[0, first], row[0, second] = i, j
        return np.vstack([members, row]), [*totals, score_i + score_j + limb]
    if len(holds_i) and len(holds_j):
        p, q = int(holds_i[0]), int(holds_j[0])
        if p == q:  # both ends already in one skeleton (a redundant limb): it only adds score
            totals[p] += limb
        elif not ((members[p] >= 0) & (members[q] >= 0)).any():
            # two pieces of one person (e.g. head and legs met through the neck's limbs late)
            members[p] = np.where(members[q] >= 0, members[q], members[p])
            totals[p] += totals[q] + limb
            members = np.delete(members, q, axis=0)
            del totals[q]
        return members, totals
    # one end held: the other joins its skeleton, unless that skeleton has another candidate
    # of the type already (the reference overwrote it; keeping the first keeps the better one,
    # found through a better-scored limb)
    p, kind, candidate, score = (
        (int(holds_i[0]), second, j, score_j)
        if len(holds_i)
        else (int(holds_j[0]), first, i, score_i)
    )
    if members[p, kind] < 0:
        members[p, kind] = candidate
        totals[p] += score + limb
    return members, totals


@dataclass(frozen=True, slots=True)
class PoseConfig:
    """Options of :class:`PoseEstimator`.

    Attributes
    ----------
    input_size:
        ``(width, height)`` the frame is resized to; ``None`` (default): the frame's aspect,
        its shorter side kept in ``input_heights`` (as :class:`~tracking.detection.cnn.
        config.CnnConfig` does: small people need the larger input).
    input_heights, max_upscale, stride:
        The shorter side's range (a frame inside is fed at its size), the largest enlargement,
        and the multiple the input's sides are rounded to (the network's output stride is 8;
        32 as for the detectors).
    upsample:
        The maps are enlarged by this factor before peaks are found (the reference's 4).
    peak_threshold:
        Heatmap value a keypoint candidate must exceed (the reference's 0.1).
    max_peaks:
        Candidates kept per keypoint type (the reference's 100).
    min_paf_score, min_agreeing:
        A sample of a limb's line integral agrees if its projection exceeds ``min_paf_score``
        (0.05); a limb needs more than ``min_agreeing`` (0.8) of its 10 samples agreeing.
    min_keypoints, min_mean_score:
        A skeleton needs this many keypoints (3) and this score per keypoint (0.2).
    crop_size:
        ``(width, height)`` each person's crop is brought to by
        :meth:`PoseEstimator.estimate_crops` (a multiple of 8; the person about 2/3 of its
        height, as tall as in the network's native 256-px input); ``None`` disables crops.
    crop_margin:
        The crop around a box: ``crop_margin`` of its height above and below it, centred on it
        at ``crop_size``'s aspect.
    max_batch:
        Crops per inference request: two requests run at once, each of ``ceil(crops / 2)``
        up to this (``Network.infer_batches``).
    threads:
        Inference threads; 0: OpenVINO's choice.
    """

    input_size: tuple[int, int] | None = None
    input_heights: tuple[float, float] = (576.0, 1080.0)
    max_upscale: float = 2.0
    stride: int = 32
    upsample: int = 4
    peak_threshold: float = 0.1
    max_peaks: int = 100
    min_paf_score: float = 0.05
    min_agreeing: float = 0.8
    min_keypoints: int = 3
    min_mean_score: float = 0.2
    crop_size: tuple[int, int] | None = (96, 192)
    crop_margin: float = 0.25
    max_batch: int = 4
    threads: int = 0

    def __post_init__(self) -> None:
        check_input_rule(self.input_size, self.input_heights, self.max_upscale)
        if self.crop_size is not None and (
            len(self.crop_size) != 2
            or not all(is_int(side) and side >= 8 and side % 8 == 0 for side in self.crop_size)
        ):
            raise ValueError(f"crop_size must be two multiples of 8, got {self.crop_size}")
        if not (math.isfinite(self.crop_margin) and self.crop_margin >= 0):
            raise ValueError(f"crop_margin must be finite and >= 0, got {self.crop_margin}")
        for name in ("stride", "upsample", "max_peaks", "min_keypoints", "max_batch"):
            if not is_int(getattr(self, name)) or getattr(self, name) < 1:
                raise ValueError(f"{name} must be a positive int, got {getattr(self, name)}")
        if self.stride % 8:
            raise ValueError(f"stride must be a multiple of 8 (the network's), got {self.stride}")
        for name in ("peak_threshold", "min_paf_score", "min_agreeing", "min_mean_score"):
            if not math.isfinite(getattr(self, name)):
                raise ValueError(f"{name} must be finite, got {getattr(self, name)}")
        if not is_int(self.threads) or self.threads < 0:
            raise ValueError(f"threads must be an int >= 0, got {self.threads}")

    def input_for(self, frame_shape: tuple[int, ...]) -> tuple[int, int]:
        """``(width, height)`` of the network input for a frame of shape ``(H, W, ...)``:
        576-1080 px frames at their size (rounded to ``stride``), smaller ones enlarged (at
        most ``max_upscale``), larger ones shrunk."""
        if self.input_size is not None:
            return self.input_size
        scale = input_scale_for(frame_shape, self.input_heights, self.max_upscale)
        return input_size_for(frame_shape, scale, self.stride)


def decode_openpose(
    heatmaps: np.ndarray,
    pafs: np.ndarray,
    scale: float | tuple[float, float],
    stride: float = 8,
    config: PoseConfig | None = None,
) -> Poses:
    """Skeletons in frame pixels from the network's outputs.

    Parameters
    ----------
    heatmaps, pafs:
        ``(19, h, w)`` and ``(38, h, w)`` (or with a batch axis of 1), at ``stride`` input
        pixels per map pixel.
    scale:
        Input pixels per frame pixel, ``(x, y)`` or one for both (the resize of the frame).
    config:
        The decoding options (``upsample``, thresholds); the defaults if None.

    The heatmaps are enlarged ``upsample`` times (bicubic, as the reference) and their peaks
    found (:func:`find_peaks`); enlargement puts pixel ``u`` at map cell ``(u + 0.5) /
    upsample - 0.5``, where the peaks are grouped with the PAFs (:func:`group_people`). Map cell
    ``f`` is input pixel ``stride f + stride / 2 - 0.5`` (OpenPose's label grid: cell ``i`` at
    stride 8 is trained on pixel ``8 i + 3.5``), and that is frame pixel ``(input + 0.5) /
    scale - 0.5``.
    """
    config = PoseConfig() if config is None else config
    heat = np.asarray(heatmaps, dtype=np.float32)
    fields = np.asarray(pafs, dtype=np.float32)
    heat = heat[0] if heat.ndim == 4 else heat
    fields = fields[0] if fields.ndim == 4 else fields
    kinds = len(KEYPOINT_NAMES)
    if heat.ndim != 3 or heat.shape[0] < kinds or fields.shape[1:] != heat.shape[1:]:
        raise ValueError(
            f"heatmaps (19, h, w) and pafs (38, h, w), got {heat.shape}, {fields.shape}"
        )
    poses = _group(_peaks_in_cells(heat[:kinds], config), fields, config)
    sx, sy = scale if isinstance(scale, tuple) else (scale, scale)
    return _cells_to_frame(poses, stride, (sx, sy), (0.0, 0.0))


def _peaks_in_cells(heatmaps: np.ndarray, config: PoseConfig) -> list[np.ndarray]:
    """:func:`find_peaks` of the heatmaps enlarged ``config.upsample`` times, placed back in
    map cells: enlargement puts pixel ``u`` at cell ``(u + 0.5) / upsample - 0.5``."""
    up = config.upsample
    # the reference's window: 7x7 at 4 times enlarged maps (p = round(6/7 upsample))
    radius = max(1, round(6 / 7 * up))
    peaks = find_peaks(_enlarge(heatmaps, up), config.peak_threshold, radius, config.max_peaks)
    for found in peaks:
        found[:, :2] = (found[:, :2] + 0.5) / up - 0.5
    return peaks


def _group(peaks: list[np.ndarray], fields: np.ndarray, config: PoseConfig) -> Poses:
    """:func:`group_people` with ``config``'s thresholds."""
    return group_people(
        peaks,
        fields,
        min_paf_score=config.min_paf_score,
        min_agreeing=config.min_agreeing,
        min_keypoints=config.min_keypoints,
        min_mean_score=config.min_mean_score,
    )


def _cells_to_frame(
    poses: Poses, stride: float, scale: tuple[float, float], origin: tuple[float, float]
) -> Poses:
    """Skeletons from map cells to frame pixels: cell ``f`` is input pixel ``stride f +
    stride / 2 - 0.5``, which is frame pixel ``(input + 0.5) / scale - 0.5`` from ``origin``
    (the top-left corner of the part of the frame the input shows)."""
    keypoints = poses.keypoints.copy()
    for axis in (0, 1):
        keypoints[..., axis] = (
            (stride * keypoints[..., axis] + stride / 2) / scale[axis] - 0.5 + origin[axis]
        )
    return Poses(keypoints, poses.scores, poses.person_scores)


def _enlarge(maps: np.ndarray, factor: int) -> np.ndarray:
    """``(C, H, W)`` maps resized ``factor`` times, bicubic (map by map: OpenCV's many-channel
    resize is 4 times slower)."""
    if factor == 1:
        return maps
    height, width = maps.shape[1:]
    out = np.empty((len(maps), height * factor, width * factor), dtype=np.float32)
    for m, enlarged in zip(maps, out, strict=True):
        cv2.resize(m, enlarged.shape[::-1], dst=enlarged, interpolation=cv2.INTER_CUBIC)
    return out


class PoseEstimator:
    """Body keypoints of every person in a frame (Open Model Zoo's human-pose-estimation-0001
    or another OpenPose network with 19 heatmaps and 38 PAFs).

    Not thread-safe to construct, safe to call from several threads (each call makes its own
    inference request).
    """

    def __init__(self, network: Network, config: PoseConfig | None = None) -> None:
        self.network = network
        self.config = PoseConfig() if config is None else config
        self._heatmap_output, self._paf_output = _output_indices(network)

    @classmethod
    def from_file(
        cls, path: str | os.PathLike[str], config: PoseConfig | None = None
    ) -> PoseEstimator:
        """The network at ``path`` (an OpenVINO IR ``.xml`` with its ``.bin``, or ONNX), read
        once per process (:func:`~tracking.detection.cnn.runtime.load_network`).

        Raises
        ------
        CnnModelError
            A file that is not a model, or a model without the heatmap and PAF outputs.
        """
        config = PoseConfig() if config is None else config
        return cls(load_network(Path(path), config.threads), config)

    @property
    def model_name(self) -> str:
        """The model's name (its file's stem)."""
        return self.network.name

    def estimate(self, frame: np.ndarray) -> Poses:
        """The skeletons in ``frame`` (RGB ``(H, W, 3)`` or greyscale ``(H, W)`` uint8), in its
        pixels."""
        image = validate_uint8_frame(frame, "the pose estimator")
        code = cv2.COLOR_GRAY2BGR if image.ndim == 2 else cv2.COLOR_RGB2BGR
        image = cv2.cvtColor(image, code)  # the network takes BGR, 0-255 (normalised inside)
        if self.network.reshapeable:
            size = self.config.input_for(image.shape)
        else:
            size = (self.network.input_shape[3], self.network.input_shape[2])
        shrink = size[0] < image.shape[1]
        blob = cv2.resize(image, size, interpolation=cv2.INTER_AREA if shrink else cv2.INTER_LINEAR)
        batch = np.ascontiguousarray(blob.transpose(2, 0, 1)[None], dtype=np.float32)
        outputs = self.network.infer_all(batch)
        heatmaps, pafs = outputs[self._heatmap_output], outputs[self._paf_output]
        stride = size[1] / heatmaps.shape[2]
        scale = (size[0] / image.shape[1], size[1] / image.shape[0])
        return decode_openpose(heatmaps, pafs, scale, stride, self.config)

    def prepare_crops(self) -> None:
        """Compile the network for every batch of crops now (``Network.prepare_batches``),
        not on the frames that first need each; nothing when crops are off."""
        if self.config.crop_size is not None and self.network.reshapeable:
            width, height = self.config.crop_size
            self.network.prepare_batches((3, height, width), self.config.max_batch)

    def crops_cheaper(self, frame_shape: tuple[int, ...], count: int) -> bool:
        """Whether ``count`` crops (:meth:`estimate_crops`) feed the network fewer pixels than
        the whole frame (:meth:`estimate`) would: the network's time follows its input's
        pixels, so a few people are cheaper in crops and a crowd in the frame."""
        crop = self.config.crop_size
        if crop is None or not self.network.reshapeable:
            return False
        width, height = self.config.input_for(frame_shape)
        return count * crop[0] * crop[1] < width * height

    def estimate_crops(self, frame: np.ndarray, boxes: np.ndarray) -> list[Poses]:
        """The skeletons in a crop around each box ``x, y, w, h`` of ``frame``, in frame pixels.

        Each crop spans its box's height and ``config.crop_margin`` of it above and below, at
        ``config.crop_size``'s aspect around the box's centre, and is resized to that size
        (outside the frame: black), so that a person of any size is seen about as tall as the
        network saw people in training; the crops go through the network in batches. The
        network is bottom-up, so a crop may hold skeletons of other people too: which one is
        the box's person is the caller's choice. A box that is not finite or not positive gets
        no skeleton.
        """
        if self.config.crop_size is None:
            raise ValueError("crops are disabled (PoseConfig.crop_size is None)")
        image = validate_uint8_frame(frame, "the pose estimator")
        code = cv2.COLOR_GRAY2BGR if image.ndim == 2 else cv2.COLOR_RGB2BGR
        image = cv2.cvtColor(image, code)
        boxes = np.asarray(boxes, dtype=np.float64).reshape(-1, 4)
        width, height = self.config.crop_size
        usable = np.isfinite(boxes).all(axis=1) & (boxes[:, 2] > 0) & (boxes[:, 3] > 0)
        # input pixels per frame pixel (1 for boxes without a crop), and the crop's top-left
        # corner in the frame
        tall = np.where(usable, boxes[:, 3], height / (1 + 2 * self.config.crop_margin))
        scale = height / (tall * (1 + 2 * self.config.crop_margin))
        left = boxes[:, 0] + boxes[:, 2] / 2 - width / 2 / scale
        top = boxes[:, 1] + boxes[:, 3] / 2 - height / 2 / scale
        rows = np.flatnonzero(usable)
        crops = np.empty((len(rows), 3, height, width), dtype=np.float32)
        for crop, i in zip(crops, rows, strict=True):
            # input pixel u shows frame pixel (u + 0.5) / scale - 0.5 + left (decode_openpose's
            # convention), so the forward map is u = scale (x - left + 0.5) - 0.5
            s = scale[i]
            warp = np.array(
                [[s, 0.0, s * (0.5 - left[i]) - 0.5], [0.0, s, s * (0.5 - top[i]) - 0.5]]
            )
            resized = cv2.warpAffine(image, warp, (width, height), flags=cv2.INTER_LINEAR)
            crop[...] = resized.transpose(2, 0, 1)
        out = [Poses.empty() for _ in boxes]
        if len(rows) == 0:
            return out
        outputs = self.network.infer_batches(crops, self.config.max_batch)
        heat = outputs[self._heatmap_output][:, : len(KEYPOINT_NAMES)]  # the background's aside
        fields = outputs[self._paf_output]
        stride = height / heat.shape[2]
        kinds = heat.shape[1]
        # every crop's candidates at once; the grouping is each crop's own
        peaks = _peaks_in_cells(heat.reshape(-1, *heat.shape[2:]), self.config)
        for tile, i in enumerate(rows):
            mine = peaks[tile * kinds : (tile + 1) * kinds]
            poses = _group(mine, fields[tile], self.config)
            out[i] = _cells_to_frame(poses, stride, (scale[i], scale[i]), (left[i], top[i]))
        return out


def _output_indices(network: Network) -> tuple[int, int]:
    """Which outputs are the heatmaps (``K + 1`` channels) and the PAFs (``2 x 19``)."""
    shapes = network.output_shapes
    channels = [shape[1] if len(shape) == 4 else -1 for shape in shapes]
    heat = [i for i, c in enumerate(channels) if c == len(KEYPOINT_NAMES) + 1]
    paf = [i for i, c in enumerate(channels) if c == 2 * len(LIMBS)]
    if len(shapes) != 2 or len(heat) != 1 or len(paf) != 1:
        raise CnnModelError(
            f"{network.path.name} is not an OpenPose network: it needs two outputs, 19 heatmaps "
            f"and 38 part affinity fields (N, C, H, W), got channels {channels}"
        )
    return heat[0], paf[0]
