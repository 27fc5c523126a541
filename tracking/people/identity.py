"""Colour signatures of people: the identity cue that tells one person from another.

A person's RCSK model (Part I) is built to localise, not to recognise: after a gap its response
at the same person is barely higher than at another (medians 0.23 against 0.18 on PETS09-S2L1).
Clothing colour is far more telling. The signature is a joint hue-saturation-value histogram of
the torso and of the legs, each from the central part of the box (the box's sides are mostly
background); two signatures compare by their Bhattacharyya coefficient. On the ground truth of
PETS09-S2L1 and TUD-Stadtmitte, the same person 1-6 s apart scores a median 0.80 and 0.84,
two different people 0.39 and 0.50 (areas under the ROC curve 0.94 and 0.83).
"""

from __future__ import annotations

import cv2
import numpy as np

# (top, bottom) of the torso and the legs, in box heights from the top; the central share of
# the box width that is sampled.
_REGIONS = ((0.2, 0.5), (0.5, 0.85))
_CENTRAL_WIDTH = 0.6
_BINS = (8, 4, 4)  # hue, saturation, value
SIGNATURE_SIZE = len(_REGIONS) * int(np.prod(_BINS))


def colour_signatures(image: np.ndarray, boxes: np.ndarray) -> np.ndarray:
    """``(K, SIGNATURE_SIZE)`` signatures of the people in ``boxes`` ``(K, 4)`` (x, y, w, h) of an
    RGB ``image``; each region's histogram sums to 1, a region outside the image is all zeros."""
    boxes = np.asarray(boxes, dtype=np.float64).reshape(-1, 4)
    out = np.zeros((len(boxes), len(_REGIONS), int(np.prod(_BINS))), dtype=np.float32)
    if len(boxes) == 0:
        return out.reshape(0, SIGNATURE_SIZE)
    height, width = image.shape[:2]
    hsv = cv2.cvtColor(np.ascontiguousarray(image), cv2.COLOR_RGB2HSV)
    for k, (x, y, w, h) in enumerate(boxes):
        cx = x + w / 2
        x0, x1 = (
            int(max(cx - _CENTRAL_WIDTH * w / 2, 0)),
            int(min(cx + _CENTRAL_WIDTH * w / 2, width)),
        )
        for r, (top, bottom) in enumerate(_REGIONS):
            y0, y1 = int(max(y + top * h, 0)), int(min(y + bottom * h, height))
            if x1 <= x0 or y1 <= y0:
                continue
            hist = cv2.calcHist(
                [hsv[y0:y1, x0:x1]], [0, 1, 2], None, list(_BINS), [0, 180, 0, 256, 0, 256]
            ).ravel()
            out[k, r] = hist / hist.sum()
    return out.reshape(len(boxes), SIGNATURE_SIZE)


def signature_similarity(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Bhattacharyya coefficients between signatures ``a`` ``(M, S)`` and ``b`` ``(K, S)``,
    averaged over the body regions: ``(M, K)`` in [0, 1], 1 for identical colours."""
    a = np.sqrt(np.asarray(a, dtype=np.float64).reshape(-1, SIGNATURE_SIZE))
    b = np.sqrt(np.asarray(b, dtype=np.float64).reshape(-1, SIGNATURE_SIZE))
    return (a @ b.T) / len(_REGIONS)
