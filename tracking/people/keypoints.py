"""Body keypoints as part measurements (issue 76): a pose network's skeletons assigned to the
tracked people, each keypoint a measurement of the part of the same name (docs/architecture.md
§5: the per-part Kalman filters get real measurements instead of only the body model's
prediction)."""

from __future__ import annotations

import numpy as np

from tracking.people.association import assign
from tracking.people.body import BodyModel

# Keypoints of the torso (neck, shoulders, hips in the pose network's order), whose mean is
# where a skeleton is: arms and legs swing, the torso stays over the box's centre line.
_TORSO = ("neck", "right_shoulder", "left_shoulder", "right_hip", "left_hip")
# Where the torso's centre lies in a person's box, in heights from the box centre (shoulders at
# 0.818 and hips at 0.530 of the height from the floor: their mean is 0.174 above the centre).
_TORSO_DY = -0.174


def assign_skeletons(
    keypoints: np.ndarray,
    names: tuple[str, ...],
    boxes: np.ndarray,
    min_share: float,
) -> np.ndarray:
    """Which skeleton belongs to which person: ``(T,)`` skeleton index per box, -1 for none.

    A skeleton may go to a person when at least ``min_share`` of its keypoints lie in the
    person's box, widened to at least 0.6 heights (outstretched arms) and by a tenth of the
    height above and below; among those, the assignment maximises that share minus the
    distance, in heights, between the skeleton's torso and where the box puts a torso
    (optimal assignment, :func:`tracking.people.association.assign`), so that of two
    overlapping people each gets the skeleton whose torso is over its own centre line.

    Parameters
    ----------
    keypoints:
        ``(S, K, 2)`` skeletons, NaN where a keypoint is missing.
    names:
        The ``K`` keypoint names (to find the torso's).
    boxes:
        ``(T, 4)`` the people's boxes ``x, y, w, h``.
    min_share:
        Least share of a skeleton's keypoints inside the box.
    """
    boxes = np.asarray(boxes, dtype=np.float64).reshape(-1, 4)
    out = np.full(len(boxes), -1, dtype=np.int64)
    if len(keypoints) == 0 or len(boxes) == 0:
        return out
    height = boxes[:, 3]
    centre_x = boxes[:, 0] + boxes[:, 2] / 2
    half_width = np.maximum(boxes[:, 2], 0.6 * height) / 2
    x, y = keypoints[None, :, :, 0], keypoints[None, :, :, 1]  # (1, S, K)
    inside = np.abs(x - centre_x[:, None, None]) <= half_width[:, None, None]
    inside &= y >= (boxes[:, 1] - 0.1 * height)[:, None, None]
    inside &= y <= (boxes[:, 1] + 1.1 * height)[:, None, None]  # (T, S, K); NaN compares False
    found = ~np.isnan(keypoints[..., 0])  # (S, K)
    share = inside.sum(axis=2) / np.maximum(found.sum(axis=1), 1)  # (T, S)
    torso = [names.index(n) for n in _TORSO if n in names]
    torso_found = found[:, torso].any(axis=1)
    torso_centre = np.where(
        torso_found[:, None],
        _nanmean(keypoints[:, torso], found[:, torso]),
        _nanmean(keypoints, found),
    )  # (S, 2)
    expected = np.stack([centre_x, boxes[:, 1] + (0.5 + _TORSO_DY) * height], axis=1)
    distance = np.linalg.norm(torso_centre[None] - expected[:, None], axis=2) / height[:, None]
    score = np.where(share >= min_share, share - distance, -np.inf)
    for row, col in assign(score):
        out[row] = col
    return out


def skeletons_in_crops(
    crops: list[tuple[np.ndarray, np.ndarray]],
    names: tuple[str, ...],
    boxes: np.ndarray,
    min_share: float,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Each person's skeleton from the crop around its box: of the crop's skeletons (it may
    show neighbours too), the one :func:`assign_skeletons` gives the crop's box.

    Parameters
    ----------
    crops:
        Per box, the crop's skeletons ``(S_i, K, 2)`` in frame pixels and their ``(S_i, K)``
        heatmap values.
    names, boxes, min_share:
        As for :func:`assign_skeletons`; ``boxes`` ``(T, 4)``, one per crop.

    Returns
    -------
    keypoints, scores, skeleton_of
        ``(T, K, 2)`` (NaN rows for none), ``(T, K)``, and ``(T,)``: ``t`` where person ``t``
        has its skeleton in row ``t``, -1 where none.
    """
    boxes = np.asarray(boxes, dtype=np.float64).reshape(-1, 4)
    k = len(names)
    keypoints = np.full((len(boxes), k, 2), np.nan)
    scores = np.zeros((len(boxes), k))
    skeleton_of = np.full(len(boxes), -1, dtype=np.int64)
    for t, (points, values) in enumerate(crops):
        chosen = assign_skeletons(points, names, boxes[t : t + 1], min_share)[0]
        if chosen >= 0:
            keypoints[t], scores[t], skeleton_of[t] = points[chosen], values[chosen], t
    return keypoints, scores, skeleton_of


def _nanmean(points: np.ndarray, found: np.ndarray) -> np.ndarray:
    """``(S, 2)`` mean of each skeleton's found points ``(S, K, 2)`` (NaN for none)."""
    total = np.where(found[..., None], points, 0.0).sum(axis=1)
    count = found.sum(axis=1)[:, None]
    with np.errstate(invalid="ignore", divide="ignore"):
        return total / count


def keypoint_measurements(
    body: BodyModel,
    keypoint_names: tuple[str, ...],
    keypoints: np.ndarray,
    scores: np.ndarray,
    skeleton_of: np.ndarray,
    sigma: float,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Part measurements from the assigned skeletons.

    Parameters
    ----------
    body:
        The tracker's body model; a keypoint measures the part of its name (parts of other
        names get none).
    keypoint_names, keypoints, scores:
        The pose network's ``K`` keypoint names, ``(S, K, 2)`` positions (NaN: missing) and
        ``(S, K)`` heatmap values.
    skeleton_of:
        ``(T,)`` each person's skeleton (:func:`assign_skeletons`), -1 for none.
    sigma:
        Standard deviation, in heights, of a keypoint whose heatmap value is 1; a weaker
        keypoint's is ``sigma / value`` (the value floored at 0.1): the heatmap's peak is the
        network's confidence that the joint is there.

    Returns
    -------
    z, found, sigmas
        ``(T, P, 2)`` positions, ``(T, P)`` which parts were measured, ``(T, P)`` standard
        deviations in heights.
    """
    people, parts = len(skeleton_of), len(body)
    z = np.zeros((people, parts, 2))
    found = np.zeros((people, parts), dtype=bool)
    sigmas = np.full((people, parts), sigma)
    pairs = [(p, keypoint_names.index(n)) for p, n in enumerate(body.names) if n in keypoint_names]
    has = skeleton_of >= 0
    if not pairs or not has.any():
        return z, found, sigmas
    part_index, key_index = (np.array(v) for v in zip(*pairs, strict=True))
    rows = np.flatnonzero(has)
    points = keypoints[skeleton_of[rows]][:, key_index]  # (R, Q, 2)
    values = scores[skeleton_of[rows]][:, key_index]  # (R, Q)
    ok = ~np.isnan(points[..., 0])
    z[rows[:, None], part_index[None]] = np.nan_to_num(points)
    found[rows[:, None], part_index[None]] = ok
    sigmas[rows[:, None], part_index[None]] = sigma / np.clip(values, 0.1, 1.0)
    return z, found, sigmas
