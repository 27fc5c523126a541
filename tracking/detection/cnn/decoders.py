"""Decoding the two families of detector outputs into boxes and confidences (vectorized).

- **SSD** (Open Model Zoo ``person-detection-*``; Liu et al., "SSD: Single Shot MultiBox
  Detector", ECCV 2016): the network ends in a ``DetectionOutput`` layer that has already
  decoded the priors and suppressed overlaps; its output ``[1, 1, K, 7]`` holds rows
  ``image_id, label, confidence, x_min, y_min, x_max, y_max`` with corners normalised to the
  input, and ``image_id = -1`` ends the list.
- **YOLOX** (Ge et al., "YOLOX: Exceeding YOLO Series in 2021", an anchor-free head): the raw
  head ``[N, A, 5 + C]`` holds, for each grid cell of the strides 8, 16 and 32 in order,
  ``dx, dy, log w, log h`` in units of the stride, the objectness and the C class scores (both
  already through the sigmoid). The box centre is ``(cell + (dx, dy)) * stride`` and its size
  ``exp(log w, log h) * stride`` (the YOLOX demo's ``demo_postprocess``); the confidence of a
  class is objectness times class score. There is no suppression in the network.
"""

from __future__ import annotations

import numpy as np

__all__ = ["YOLOX_STRIDES", "decode_ssd", "decode_yolox"]

YOLOX_STRIDES = (8, 16, 32)


def decode_ssd(
    output: np.ndarray, batch: int, label: int | None = None
) -> list[tuple[np.ndarray, np.ndarray]]:
    """Per image of the batch: corners ``(K, 4)`` ``x0, y0, x1, y1`` normalised to the input,
    and confidences ``(K,)``.

    ``label``: keep only rows of this class (``None``: every row; the person detectors have one
    class, 0 in 0202 and 1 in retail-0013; retail-0013 pads its rows with zeros, which the
    confidence threshold drops).
    """
    rows = np.asarray(output, dtype=np.float64).reshape(-1, 7)
    image = rows[:, 0]
    # rows after the first image_id -1 are padding
    valid = np.cumprod(image >= 0).astype(bool)
    if label is not None:
        valid &= rows[:, 1] == label
    out = []
    for index in range(batch):
        chosen = rows[valid & (image == index)]
        out.append((chosen[:, 3:7], chosen[:, 2]))
    return out


def decode_yolox(
    output: np.ndarray, input_size: tuple[int, int], class_id: int = 0
) -> list[tuple[np.ndarray, np.ndarray]]:
    """Per image: corners ``(A, 4)`` in input pixels and confidences ``(A,)`` of class
    ``class_id`` for every grid cell of an input of ``input_size`` ``(width, height)``."""
    head = np.asarray(output, dtype=np.float64)
    if head.ndim != 3 or head.shape[2] < 6 + class_id:
        raise ValueError(f"a YOLOX head is (N, A, 5 + classes), got {head.shape}")
    grid, strides = yolox_grid(input_size)
    if head.shape[1] != grid.shape[0]:
        raise ValueError(
            f"a YOLOX head for a {input_size[0]}x{input_size[1]} input has {grid.shape[0]} "
            f"cells, got {head.shape[1]}"
        )
    centres = (head[..., 0:2] + grid) * strides
    half = np.exp(np.minimum(head[..., 2:4], 20.0)) * strides / 2  # exp bounded: garbage in
    corners = np.concatenate([centres - half, centres + half], axis=-1)
    confidence = head[..., 4] * head[..., 5 + class_id]
    return [(corners[i], confidence[i]) for i in range(head.shape[0])]


def yolox_grid(input_size: tuple[int, int]) -> tuple[np.ndarray, np.ndarray]:
    """Cell positions ``(A, 2)`` (column, row) and strides ``(A, 1)`` of YOLOX's three levels,
    row-major within each level, the levels in stride order."""
    width, height = input_size
    cells, strides = [], []
    for stride in YOLOX_STRIDES:
        rows, cols = height // stride, width // stride
        ys, xs = np.mgrid[0:rows, 0:cols]
        cells.append(np.column_stack([xs.ravel(), ys.ravel()]))
        strides.append(np.full((rows * cols, 1), float(stride)))
    return np.concatenate(cells).astype(np.float64), np.concatenate(strides)
