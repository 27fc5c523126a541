"""One colour per track id, the same in every output."""

from __future__ import annotations

# Tableau 10 (matplotlib's default cycle), 8-bit RGB: distinct and readable on video.
_COLOURS: tuple[tuple[int, int, int], ...] = (
    (31, 119, 180),
    (255, 127, 14),
    (44, 160, 44),
    (214, 39, 40),
    (148, 103, 189),
    (140, 86, 75),
    (227, 119, 194),
    (127, 127, 127),
    (188, 189, 34),
    (23, 190, 207),
)


def track_colour(track_id: int) -> tuple[int, int, int]:
    """RGB of a track id."""
    return _COLOURS[track_id % len(_COLOURS)]
