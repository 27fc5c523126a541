"""The MCAP's image annotations: what Foxglove draws over each frame."""

from __future__ import annotations

import json

import numpy as np
import pytest
from mcap.reader import make_reader

from api_schemas.tracks import BoxModel, FrameTracksMessage, PartState, TrackState, VideoInfo
from service.frames import TimedFrame
from service.outputs import foxglove
from service.outputs.base import RunSummary, StreamInfo
from service.outputs.mcap_out import (
    ANNOTATIONS_TOPIC,
    LABEL_SIZE,
    McapWriter,
    image_annotations,
)
from service.outputs.palette import track_colour


def _labels(*tops: float) -> list[dict]:
    tracks = [
        TrackState(
            track_id=i, box=BoxModel(x=10.0, y=top, w=20.0, h=60.0), score=0.5, occluded=False
        )
        for i, top in enumerate(tops)
    ]
    message = FrameTracksMessage(frame_index=0, timestamp=0.0, tracks=tracks)
    return image_annotations(message, 0)["texts"]


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


SKELETON = (("head", "neck"), ("neck", "left_shoulder"), ("neck", "right_shoulder"))


def _person(track_id: int = 3, hidden: tuple[str, ...] = ("left_shoulder",)) -> TrackState:
    """A person whose parts sit at known places, ``hidden`` ones not visible."""
    places = {"head": (50.0, 20.0), "neck": (50.0, 40.0), "left_shoulder": (35.0, 45.0)}
    places["right_shoulder"] = (65.0, 45.0)
    parts = [
        PartState(name=name, x=x, y=y, visible=name not in hidden, measured=True)
        for name, (x, y) in places.items()
    ]
    box = BoxModel(x=20.0, y=10.0, w=60.0, h=150.0)
    return TrackState(track_id=track_id, box=box, score=0.9, occluded=False, parts=parts)


def _lines(annotation: dict) -> list[dict]:
    return [p for p in annotation["points"] if p["type"] == foxglove.LINE_LIST]


def test_limbs_between_visible_parts_are_a_line_list_in_the_track_colour():
    message = FrameTracksMessage(frame_index=0, timestamp=0.0, tracks=[_person()])
    (lines,) = _lines(image_annotations(message, 0, SKELETON))
    # two points per drawn limb; the limb to the hidden left shoulder is left out
    assert lines["points"] == [
        {"x": 50.0, "y": 20.0},
        {"x": 50.0, "y": 40.0},
        {"x": 50.0, "y": 40.0},
        {"x": 65.0, "y": 45.0},
    ]
    assert lines["outline_color"] == foxglove.color(track_colour(3))
    assert lines["thickness"] > 0


def test_a_track_without_a_drawable_limb_has_no_line_list():
    hidden = _person(hidden=("neck",))  # every limb ends at the neck
    message = FrameTracksMessage(frame_index=0, timestamp=0.0, tracks=[hidden])
    assert _lines(image_annotations(message, 0, SKELETON)) == []
    message = FrameTracksMessage(frame_index=0, timestamp=0.0, tracks=[_person()])
    assert _lines(image_annotations(message, 0)) == []  # no skeleton: parts only
    assert [p["type"] for p in image_annotations(message, 0)["points"]] == [
        foxglove.LINE_LOOP,
        foxglove.POINTS,
    ]


def test_the_mcap_file_holds_the_limbs_and_names_the_skeleton(tmp_path):
    # The file a job writes and a stream records: both go through McapWriter.
    parts = ("head", "neck", "left_shoulder", "right_shoulder")
    info = StreamInfo(160, 120, 10.0, 1, parts, "people", mcap_images="jpeg", skeleton=SKELETON)
    writer = McapWriter(tmp_path / "tracks.mcap", info)
    image = np.zeros((120, 160, 3), np.uint8)
    for index, hidden in enumerate([("left_shoulder",), ("neck",)]):
        tracks = [_person(hidden=hidden)]
        message = FrameTracksMessage(frame_index=index, timestamp=index / 10, tracks=tracks)
        writer.write(TimedFrame(index, index / 10, image), message)
    video = VideoInfo(width=160, height=120, frames_announced=2, frames_read=2, frame_step=1)
    writer.close(RunSummary(video, 2))

    with (tmp_path / "tracks.mcap").open("rb") as handle:
        reader = make_reader(handle)
        documents = [
            json.loads(message.data)
            for _, _, message in reader.iter_messages(topics=[ANNOTATIONS_TOPIC])
        ]
        (record,) = [m for m in reader.iter_metadata() if m.name == "vtrack"]
    assert [len(lines["points"]) for d in documents for lines in _lines(d)] == [4]
    assert record.metadata["skeleton"] == "head-neck,neck-left_shoulder,neck-right_shoulder"
    assert record.metadata["part_names"] == ",".join(parts)
