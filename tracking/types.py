"""Plain types shared by every tracker: boxes, per-frame outputs and the `Tracker` contract.

Frames are numpy arrays in RGB order, ``uint8``, shape ``(H, W, 3)``, or grayscale ``(H, W)``.
Boxes are axis-aligned, in pixels, with a 0-based top-left corner: ``(x, y, w, h)``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Protocol, TypeGuard

import numpy as np

__all__ = [
    "Box",
    "Tracker",
    "TrackerOutput",
    "as_box",
    "box_problem",
    "check_pixel_values",
    "checked_timestamp",
    "is_int",
    "validate_box",
    "validate_frame",
    "validate_uint8_frame",
]


@dataclass(frozen=True, slots=True)
class Box:
    """An axis-aligned box: top-left corner ``(x, y)`` and size ``(w, h)`` in pixels."""

    x: float
    y: float
    w: float
    h: float

    @property
    def center(self) -> tuple[float, float]:
        """Centre ``(cx, cy)`` in pixels."""
        return self.x + self.w / 2.0, self.y + self.h / 2.0

    @classmethod
    def from_center(cls, cx: float, cy: float, w: float, h: float) -> Box:
        return cls(cx - w / 2.0, cy - h / 2.0, w, h)

    def as_array(self) -> np.ndarray:
        """The box as a float64 array ``[x, y, w, h]``."""
        return np.array([self.x, self.y, self.w, self.h], dtype=np.float64)


@dataclass(frozen=True, slots=True)
class TrackerOutput:
    """What a tracker says about one frame.

    Attributes
    ----------
    box:
        Estimated target box.
    peak:
        Maximum of the correlation response: near 0 for no match, and on the frame the filter
        was learned from between about 0.3 and 1 depending on the preset (features, kernel,
        regularisation) and the target, so compare it between frames of one run, not between
        presets.
    psr:
        Peak-to-sidelobe ratio of the response: ``(peak - mean) / std`` of the response outside
        a small window around the peak (Bolme et al. 2010). Higher is more confident; a sudden
        drop signals occlusion or a lost target. Its scale depends on the feature grid.
    occluded:
        The tracker's failure signal fired (for presets that have one, see
        :attr:`~tracking.correlation.CorrelationConfig.apce_ratio`): the response does not look
        like the target's, so the target is hidden or lost and the tracker did not learn from
        this frame (the box is still the response's best guess).
    """

    box: Box
    peak: float
    psr: float
    occluded: bool = False


class Tracker(Protocol):
    """The contract every single-target tracker keeps.

    State lives on the instance; two instances never share anything, so one tracker per target
    or per camera is always safe. The type checker holds the implementations to it
    (``tests/protocol_conformance.py``).
    """

    def initialize(self, frame: np.ndarray, box: Box) -> None:
        """Learn the target's appearance from ``frame`` inside ``box``."""
        ...

    def update(self, frame: np.ndarray) -> TrackerOutput:
        """Find the target in the next ``frame``, learn from it and return its box."""
        ...

    def reset(self) -> None:
        """Forget the target; :meth:`initialize` must be called again before :meth:`update`."""
        ...


def is_int(value: object) -> TypeGuard[int | np.integer]:
    """Whether ``value`` is a Python or numpy integer; ``bool`` is not (``True`` is no count)."""
    return isinstance(value, int | np.integer) and not isinstance(value, bool)


def check_pixel_values(array: np.ndarray, name: str = "image") -> None:
    """Raise ValueError unless ``array`` has an integer or floating dtype (not bool) and only
    finite values: what the HOG kernels read unchecked."""
    if array.dtype == np.bool_ or not (
        np.issubdtype(array.dtype, np.integer) or np.issubdtype(array.dtype, np.floating)
    ):
        raise ValueError(f"{name} must have an integer or floating dtype, got {array.dtype}")
    # min and max propagate NaN and show infinities, without a boolean copy of the array
    if (
        array.size
        and np.issubdtype(array.dtype, np.floating)
        and not (np.isfinite(array.min()) and np.isfinite(array.max()))
    ):
        raise ValueError(f"{name} must contain only finite values (it has NaN or infinity)")


def validate_frame(frame: object) -> np.ndarray:
    """Check that ``frame`` is a non-empty image: ``(H, W)`` or ``(H, W, 3)``.

    Raises
    ------
    TypeError
        If ``frame`` is not a numpy array.
    ValueError
        If it has the wrong shape or is empty.
    """
    if not isinstance(frame, np.ndarray):
        raise TypeError(f"frame must be a numpy array, got {type(frame).__name__}")
    if frame.ndim not in (2, 3) or (frame.ndim == 3 and frame.shape[2] != 3):
        raise ValueError(f"frame must have shape (H, W) or (H, W, 3), got {frame.shape}")
    if frame.shape[0] < 2 or frame.shape[1] < 2:
        raise ValueError(f"frame is empty or too small: shape {frame.shape}")
    return frame


def validate_uint8_frame(frame: object, user: str) -> np.ndarray:
    """:func:`validate_frame`, and a uint8 frame (values 0-255), as ``user`` needs it.

    Raises
    ------
    TypeError
        For another dtype: 16-bit or 0..1 float frames are not guessed at.
    """
    frame = validate_frame(frame)
    if frame.dtype != np.uint8:
        raise TypeError(
            f"{user} needs a uint8 frame (values 0-255), got dtype {frame.dtype}: convert it first"
        )
    return frame


def as_box(value: object) -> Box:
    """``value`` as a :class:`Box` of plain floats: a Box, or four numbers ``(x, y, w, h)``.

    Raises
    ------
    TypeError
        For anything else.
    """
    values: tuple[Any, ...]
    if isinstance(value, Box):
        values = (value.x, value.y, value.w, value.h)
    else:
        try:
            values = tuple(value)  # type: ignore[arg-type]
        except TypeError:
            values = ()
    if len(values) != 4 or not all(isinstance(v, (int, float, np.number)) for v in values):
        raise TypeError(f"box must be a Box or four numbers (x, y, w, h), got {value!r}")
    return Box(*(float(v) for v in values))


MAX_BOX_FRAMES = 4
"""A box may reach past the frame (a target partly out of view), but no side may be more than
this many times the frame's: a larger one is a mistake, and its patches would not fit in memory."""


def box_problem(box: Box, frame_shape: tuple[int, ...]) -> str | None:
    """Why ``box`` cannot start a track in a frame of ``frame_shape``, in plain numbers
    (``"900,10,20,20 lies entirely outside the 480x360 frame"``); ``None`` when it can."""
    values = (box.x, box.y, box.w, box.h)
    text = ",".join(f"{v:g}" for v in values)
    if not all(np.isfinite(v) for v in values):
        return f"{text} is not four finite numbers"
    if box.w < 1 or box.h < 1:
        return f"{text}: width and height must be at least 1 pixel"
    height, width = frame_shape[:2]
    if box.x >= width or box.y >= height or box.x + box.w <= 0 or box.y + box.h <= 0:
        return f"{text} lies entirely outside the {width}x{height} frame"
    if box.w > MAX_BOX_FRAMES * width or box.h > MAX_BOX_FRAMES * height:
        return f"{text} is more than {MAX_BOX_FRAMES} times the size of the {width}x{height} frame"
    return None


def validate_box(box: Box, frame_shape: tuple[int, ...]) -> Box:
    """Check that ``box`` has a positive size and overlaps a frame of ``frame_shape``.

    Raises
    ------
    ValueError
        If the box has a non-positive or non-finite size or lies entirely outside the frame
        (:func:`box_problem` says which).
    """
    if problem := box_problem(box, frame_shape):
        raise ValueError(f"box {problem}")
    return box


def checked_timestamp(timestamp: object, previous: float | None) -> float:
    """``timestamp`` (seconds) as a float, checked against the previous frame's.

    Raises
    ------
    TypeError
        For something that is not a number (a string is not read as one).
    ValueError
        For a timestamp that is not finite or comes before ``previous``.
    """
    if isinstance(timestamp, bool) or not isinstance(timestamp, (int, float, np.number)):
        raise TypeError(f"timestamp must be a number of seconds, got {timestamp!r}")
    value = float(timestamp)
    if not math.isfinite(value):
        raise ValueError(f"timestamp must be a finite number of seconds, got {value}")
    if previous is not None and value < previous:
        raise ValueError(
            f"timestamp {value:.3f} s is before the previous frame's {previous:.3f} s; "
            "timestamps must not go backwards"
        )
    return value
