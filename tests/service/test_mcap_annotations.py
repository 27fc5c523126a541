"""The MCAP's image annotations: what Foxglove draws over each frame."""

from __future__ import annotations

import pytest

from api_schemas.tracks import BoxModel, FrameTracksMessage, TrackState
from service.outputs.mcap_out import LABEL_SIZE, annotations


def _labels(*tops: float) -> list[dict]:
    tracks = [
        TrackState(
            track_id=i, box=BoxModel(x=10.0, y=top, w=20.0, h=60.0), score=0.5, occluded=False
        )
        for i, top in enumerate(tops)
    ]
    message = FrameTracksMessage(frame_index=0, timestamp=0.0, tracks=tracks)
    return annotations(message, 0)["texts"]


def test_id_labels_sit_above_their_box():
    (label,) = _labels(100.0)
    # Foxglove anchors a text at its bottom left: the label ends just above the box.
    assert label["position"] == {"x": 10.0, "y": 98.0}
    assert label["font_size"] == LABEL_SIZE


@pytest.mark.parametrize("top", [0.0, 5.0, LABEL_SIZE + 1.0])
def test_id_labels_of_boxes_at_the_top_edge_stay_in_the_image(top):
    # Before, a box starting less than a label's height from the top put its label above the
    # image (bottom edge at y 0 or just below), where Foxglove shows nothing of it.
    (label,) = _labels(top)
    bottom = label["position"]["y"]
    assert bottom - LABEL_SIZE >= 0  # the whole label is inside the image
    assert top < bottom <= top + 60.0  # and inside its box, near the top
