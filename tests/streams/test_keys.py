"""The Zenoh key expressions of a camera's stream (service.streams.keys)."""

from __future__ import annotations

import zenoh

from service.streams.keys import StreamKeys


def test_stream_keys():
    keys = StreamKeys("vtrack", "gate")
    assert keys.frames == "vtrack/cameras/gate/frames"
    assert keys.detections == "vtrack/cameras/gate/detections"
    assert keys.tracks == "vtrack/cameras/gate/tracks"
    assert keys.current == "vtrack/cameras/gate/tracks/current"
    assert keys.ended == "vtrack/cameras/gate/tracks/ended"
    assert keys.events == "vtrack/cameras/gate/events"
    assert keys.trackers == "vtrack/trackers/gate/*"
    assert keys.tracker_token("host-1") == "vtrack/trackers/gate/host-1"
    assert keys.as_dict() == {
        "frames": keys.frames,
        "detections": keys.detections,
        "tracks": keys.tracks,
        "ended": keys.ended,
        "current": keys.current,
        "events": keys.events,
        "trackers": keys.trackers,
    }
    # Every key is a valid Zenoh key expression, and the token matches the trackers wildcard.
    for key in [*keys.as_dict().values(), keys.tracker_token("host-1")]:
        zenoh.KeyExpr(key)
    assert zenoh.KeyExpr(keys.trackers).intersects(zenoh.KeyExpr(keys.tracker_token("x")))
    assert not zenoh.KeyExpr(keys.tracks).intersects(zenoh.KeyExpr(keys.current))
