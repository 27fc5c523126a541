"""Events from synthetic trajectories whose every event is known in advance."""

from __future__ import annotations

import numpy as np
import pytest

from tracking.analytics import (
    AnalyticsConfig,
    AnalyticsEngine,
    Line,
    Zone,
    ground_points,
    polygon_problem,
)
from tracking.analytics.geometry import side_distance, signed_distance_to_polygon

HEIGHT = 100.0  # every synthetic person is 100 px tall: a 10 px band around lines and zones

# a vertical line x = 200 from y = 0 down to y = 400: its left, looking down the image, is
# x > 200 (y points down), so walking from x > 200 to x < 200 crosses it 'in'
GATE = Line("gate", np.array([200.0, 0.0]), np.array([200.0, 400.0]))
# a square zone from (300, 100) to (500, 300), with a 2 s dwell
BENCH = Zone("bench", np.array([[300.0, 100], [500, 100], [500, 300], [300, 300]]), 2.0)


def run(
    path: list[tuple[float, float]], config: AnalyticsConfig, fps: float = 10.0, track_id: int = 7
):
    """Feed one person walking along ``path`` (ground points), one point per frame."""
    engine = AnalyticsEngine(config)
    events = []
    for frame, (x, y) in enumerate(path):
        box = np.array([[x - 20, y - HEIGHT, 40, HEIGHT]])
        events += engine.update(frame / fps, np.array([track_id]), np.array([[x, y]]), box)
    return engine, events


def summary(events) -> list[tuple]:
    return [(e.type, e.name, e.direction, round(e.timestamp, 3)) for e in events]


def test_a_person_crossing_a_line_both_ways_and_hovering_on_it():
    # right of the gate, across it to the left, hover on it (within the band), back across
    path = [(260.0, 200.0), (230, 200), (205, 200), (195, 200), (170, 200)]  # in at frame 4
    path += [(195, 200), (205, 200), (195, 200), (205, 200), (195, 200)]  # hovering: nothing
    path += [(230, 200), (260, 200)]  # out at frame 10
    engine, events = run(path, AnalyticsConfig(lines=(GATE,)))
    assert summary(events) == [
        ("line_crossed", "gate", "in", 0.4),
        ("line_crossed", "gate", "out", 1.0),
    ]
    assert engine.counts.lines == {"gate": {"in": 1, "out": 1}}


def test_the_direction_follows_the_line_drawn():
    reversed_gate = Line("gate", GATE.end, GATE.start)
    _, events = run([(260.0, 200.0), (140, 200)], AnalyticsConfig(lines=(reversed_gate,)))
    assert summary(events) == [("line_crossed", "gate", "out", 0.1)]


def test_passing_beyond_the_end_of_a_line_crosses_nothing():
    # the gate ends at y = 400: a person walking across x = 200 at y = 450 passes it by
    _, events = run([(260.0, 450.0), (140, 450)], AnalyticsConfig(lines=(GATE,)))
    assert events == []


def test_a_person_entering_dwelling_and_leaving_a_zone():
    outside, inside = (250.0, 200.0), (400.0, 200.0)
    path = [outside] * 3 + [inside] * 25 + [outside] * 2  # in at frame 3, out at frame 28
    engine, events = run(path, AnalyticsConfig(zones=(BENCH,)))
    assert summary(events) == [
        ("zone_entered", "bench", None, 0.3),
        ("dwell", "bench", None, 2.3),  # 2 s after entering
        ("zone_left", "bench", None, 2.8),
    ]
    assert events[1].dwell_seconds == pytest.approx(2.0)
    assert events[2].dwell_seconds == pytest.approx(2.5) and not events[2].lost
    assert engine.counts.zones == {"bench": {"entered": 1, "left": 1, "dwell": 1}}


def test_a_short_visit_makes_no_dwell_and_the_boundary_band_no_flicker():
    # on the zone's left edge x = 300, jittering by 5 px (inside the 10 px band): no event
    path = [(250.0, 200.0), (295, 200), (305, 200), (295, 200), (305, 200)]
    path += [(400, 200)] * 5 + [(250, 200)]  # 0.5 s inside, then out
    _, events = run(path, AnalyticsConfig(zones=(BENCH,)))
    assert summary(events) == [
        ("zone_entered", "bench", None, 0.5),
        ("zone_left", "bench", None, 1.0),
    ]


def test_a_person_no_longer_seen_leaves_the_zone_as_lost():
    config = AnalyticsConfig(zones=(BENCH,), forget_after=1.0)
    engine = AnalyticsEngine(config)
    point, box = np.array([[400.0, 200.0]]), np.array([[380.0, 100.0, 40.0, 100.0]])
    assert [e.type for e in engine.update(0.0, np.array([3]), point, box)] == ["zone_entered"]
    assert engine.update(0.5, np.array([], int), np.zeros((0, 2)), np.zeros((0, 4))) == []
    (left,) = engine.update(1.5, np.array([], int), np.zeros((0, 2)), np.zeros((0, 4)))
    assert (left.type, left.track_id, left.lost, left.dwell_seconds) == ("zone_left", 3, True, 0)


def test_people_are_followed_apart_and_counted_per_bucket():
    config = AnalyticsConfig(lines=(GATE,), bucket_seconds=1.0)
    engine = AnalyticsEngine(config)
    boxes = np.array([[0.0, 0.0, 40.0, HEIGHT]] * 2)
    # two people cross the gate opposite ways, in different seconds
    engine.update(0.0, np.array([1, 2]), np.array([[260.0, 100.0], [140.0, 300.0]]), boxes)
    first = engine.update(0.5, np.array([2, 1]), np.array([[140.0, 300.0], [140.0, 100.0]]), boxes)
    second = engine.update(1.5, np.array([1, 2]), np.array([[140.0, 100.0], [260.0, 300.0]]), boxes)
    assert [(e.track_id, e.direction) for e in first + second] == [(1, "in"), (2, "out")]
    assert engine.counts.lines == {"gate": {"in": 1, "out": 1}}
    assert {start: c.lines for start, c in engine.counts.buckets.items()} == {
        0.0: {"gate": {"in": 1, "out": 0}},
        1.0: {"gate": {"in": 0, "out": 1}},
    }


def test_ground_points_are_between_the_placed_ankles_else_the_box_bottom():
    boxes = np.array([[10.0, 20.0, 40.0, 100.0], [100.0, 0.0, 20.0, 50.0]])
    names = ("nose", "left_ankle", "right_ankle")
    xy = np.array([[[30, 30], [20, 118], [40, 122]], [[110, 5], [0, 0], [0, 0]]], dtype=float)
    placed = np.array([[True, True, True], [True, False, False]])
    points = ground_points(boxes, names, xy, placed)
    np.testing.assert_allclose(points, [[30.0, 120.0], [110.0, 50.0]])
    np.testing.assert_allclose(ground_points(boxes), [[30.0, 120.0], [110.0, 50.0]])


@pytest.mark.parametrize(
    ("polygon", "problem"),
    [
        ([[0, 0], [10, 0]], "at least 3 points"),  # a segment
        ([[0, 0], [10, 10], [20, 20]], "no area"),  # collinear
        ([[0, 0], [10, 10], [10, 0], [0, 10]], "edges 1 and 3 cross"),  # a bow tie
        ([[0, 0], [10, 0], [10, 10], [0, 10]], None),  # a square
        ([[0, 0], [10, 0], [5, 2], [10, 10], [0, 10]], None),  # concave
    ],
)
def test_polygon_problems(polygon, problem):
    found = polygon_problem(np.array(polygon, dtype=float))
    assert found is None if problem is None else problem in found


def test_distances_to_a_concave_polygon_and_a_line():
    # a U shape: the notch (5, 8) is outside, the arms inside
    u = np.array([[0, 0], [10, 0], [10, 10], [7, 10], [7, 4], [3, 4], [3, 10], [0, 10]], float)
    depth = signed_distance_to_polygon(np.array([[5, 8], [1.5, 8], [5, 2], [-2, 5]]), u)
    np.testing.assert_allclose(depth, [-2.0, 1.5, 2.0, -2.0])
    side = side_distance(np.array([[3, 5], [-3, 5]]), np.array([0.0, 0]), np.array([0.0, 10]))
    np.testing.assert_allclose(side, [-3.0, 3.0])  # looking down the image, +x is on the left
