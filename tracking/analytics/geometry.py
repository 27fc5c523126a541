"""Plane geometry of zones and lines, vectorised over the people of a frame.

Image coordinates in pixels, ``x`` to the right and ``y`` down. A zone is a simple polygon
``(K, 2)``; a line is a directed segment from its first point to its second. Every function
takes all points of a frame at once, ``(N, 2)``, and loops over nothing but numpy's axes.
"""

from __future__ import annotations

import numpy as np

__all__ = [
    "polygon_area",
    "polygon_problem",
    "segments_cross",
    "side_distance",
    "signed_distance_to_polygon",
]


def polygon_area(polygon: np.ndarray) -> float:
    """The area of a simple polygon ``(K, 2)`` (shoelace formula), positive either winding."""
    x, y = polygon[:, 0], polygon[:, 1]
    return 0.5 * abs(float(np.dot(x, np.roll(y, -1)) - np.dot(y, np.roll(x, -1))))


def _cross(o: np.ndarray, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """The z component of ``(a - o) x (b - o)``, broadcast over leading axes."""
    return (a[..., 0] - o[..., 0]) * (b[..., 1] - o[..., 1]) - (a[..., 1] - o[..., 1]) * (
        b[..., 0] - o[..., 0]
    )


def segments_cross(
    p: np.ndarray, q: np.ndarray, a: np.ndarray, b: np.ndarray, strict: bool = True
) -> np.ndarray:
    """Whether segments ``p -> q`` cross segment ``a -> b``, broadcast over leading axes.

    Two segments cross when the end points of each lie on opposite sides of the other
    (orientation test). ``strict``: touching end points do not count.
    """
    d1, d2 = _cross(a, b, p), _cross(a, b, q)
    d3, d4 = _cross(p, q, a), _cross(p, q, b)
    if strict:
        return (d1 * d2 < 0) & (d3 * d4 < 0)
    return (d1 * d2 <= 0) & (d3 * d4 <= 0)


def polygon_problem(polygon: np.ndarray) -> str | None:
    """Why ``polygon`` ``(K, 2)`` cannot be a zone, or None: fewer than 3 points, no area, or
    edges that cross each other (a bow tie has no inside a person can be said to be in)."""
    if polygon.ndim != 2 or polygon.shape[1] != 2 or len(polygon) < 3:
        return "a zone needs at least 3 points [x, y]"
    if not np.isfinite(polygon).all():
        return "a zone's points must be finite numbers"
    start, end = polygon, np.roll(polygon, -1, axis=0)
    k = len(polygon)
    # every pair of edges that share no corner (neighbours always touch at theirs)
    i, j = np.triu_indices(k, 2)
    apart = ~((i == 0) & (j == k - 1))
    i, j = i[apart], j[apart]
    crossing = segments_cross(start[i], end[i], start[j], end[j], strict=False)
    if crossing.any():
        first = int(np.argmax(crossing))
        return f"the zone's edges {i[first] + 1} and {j[first] + 1} cross: draw it so none do"
    if polygon_area(polygon) <= 1e-9:
        return "the zone has no area: its points lie on one line"
    return None


def signed_distance_to_polygon(points: np.ndarray, polygon: np.ndarray) -> np.ndarray:
    """Distance in pixels from each point ``(N, 2)`` to the boundary of ``polygon`` ``(K, 2)``:
    positive inside, negative outside, ``(N,)``.

    Inside by the even-odd rule (a ray to the right crosses the boundary an odd number of
    times); the distance is the nearest of the point-to-segment distances.
    """
    points = np.asarray(points, dtype=np.float64).reshape(-1, 2)
    a = polygon[None, :, :]  # (1, K, 2): edge starts
    b = np.roll(polygon, -1, axis=0)[None, :, :]  # edge ends
    p = points[:, None, :]  # (N, 1, 2)
    edge = b - a
    length2 = np.maximum((edge**2).sum(axis=-1), 1e-12)
    t = np.clip(((p - a) * edge).sum(axis=-1) / length2, 0.0, 1.0)  # (N, K)
    nearest = a + t[..., None] * edge
    distance = np.sqrt(((p - nearest) ** 2).sum(axis=-1)).min(axis=1)
    # even-odd rule: edges that straddle the point's row, crossed to the point's right
    ay, by = a[..., 1], b[..., 1]
    py, px = p[..., 1], p[..., 0]
    straddles = (ay > py) != (by > py)
    with np.errstate(divide="ignore", invalid="ignore"):
        x_at = a[..., 0] + (py - ay) * edge[..., 0] / (by - ay)
    inside = (straddles & (px < x_at)).sum(axis=1) % 2 == 1
    return np.where(inside, distance, -distance)


def side_distance(points: np.ndarray, start: np.ndarray, end: np.ndarray) -> np.ndarray:
    """Signed distance in pixels of each point ``(N, 2)`` from the infinite line through
    ``start -> end``: positive to the right of the direction of travel as seen on the image
    (``y`` down, so clockwise), negative to its left, ``(N,)``.

    ``d = ((end - start) x (p - start)) / |end - start|``.
    """
    points = np.asarray(points, dtype=np.float64).reshape(-1, 2)
    direction = end - start
    return _cross(start, end, points) / float(np.hypot(*direction))
