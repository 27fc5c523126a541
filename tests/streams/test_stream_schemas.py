"""The stream schemas (api_schemas.streams): camera names, unknown fields, the tracks
message."""

from __future__ import annotations

import pytest
import zenoh
from pydantic import ValidationError

from api_schemas.streams import (
    StreamSpec,
    StreamTracksMessage,
)
from api_schemas.tracks import FrameTracksMessage
from service.streams.keys import StreamKeys


@pytest.mark.parametrize(
    "camera", ["", "a/b", "cam*", "cam#1", "$cam", "cam?", "gate 1", " gate", "-gate", "x" * 65]
)
def test_stream_spec_rejects_bad_camera_names(camera):
    with pytest.raises(ValidationError):
        StreamSpec(camera=camera)


@pytest.mark.parametrize("camera", ["gate-1", "cam_2.north", "g", "A9", "x" * 64])
def test_stream_spec_accepts_camera_names(camera):
    spec = StreamSpec(camera=camera)
    assert spec.camera == camera
    zenoh.KeyExpr(StreamKeys("vtrack", camera).frames)


def test_stream_spec_rejects_unknown_fields():
    with pytest.raises(ValidationError, match="extra"):
        StreamSpec.model_validate({"camera": "gate", "fps": 10})


def test_stream_tracks_message_round_trip():
    assert issubclass(StreamTracksMessage, FrameTracksMessage)
    message = StreamTracksMessage.model_validate(
        {
            "frame_index": 3,
            "timestamp": 1700000000.5,
            "tracks": [
                {
                    "track_id": 2,
                    "box": {"x": 1.5, "y": 2.0, "w": 30.0, "h": 60.0},
                    "score": 0.75,
                    "occluded": False,
                }
            ],
            "camera": "gate",
            "sequence": 17,
            "latency": 0.012,
            "frames_skipped": 1,
            "detections": "upstream",
        }
    )
    again = StreamTracksMessage.model_validate_json(message.model_dump_json())
    assert again == message
    assert again.tracks[0].box.w == 30.0
    with pytest.raises(ValidationError):
        StreamTracksMessage.model_validate({**message.model_dump(), "unknown": 1})
