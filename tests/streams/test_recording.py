"""A camera's recordings (service.streams.recording): the uploads' MCAP writer in stream mode,
segments by stream time and by run of tracks, the newest kept."""

from __future__ import annotations

import json
import logging
from pathlib import Path

import numpy as np
from mcap.reader import make_reader

from api_schemas.jobs import JobOptions, OutputFormat
from api_schemas.streams import StreamSpec, StreamTracksMessage
from api_schemas.tracks import BoxModel, TrackState
from service.streams.recording import Recording

IMAGE = np.full((48, 64, 3), 90, np.uint8)
OPTIONS = JobOptions(formats=[OutputFormat.mcap], mcap_images="jpeg")


def _message(index: int, timestamp: float, track_id: int = 5) -> StreamTracksMessage:
    track = TrackState(
        track_id=track_id, box=BoxModel(x=4.0, y=6.0, w=10.0, h=30.0), score=0.5, occluded=False
    )
    return StreamTracksMessage(
        frame_index=index,
        timestamp=timestamp,
        tracks=[track],
        camera="gate",
        sequence=100 + index,
        latency=0.125,
        frames_skipped=0,
        detections="service",
    )


def _no_errors(reason: str, level: int) -> None:
    raise AssertionError(f"unexpected error ({logging.getLevelName(level)}): {reason}")


def _read(path: Path) -> tuple[dict, dict, list[dict], dict[str, str]]:
    """Channels (topic: schema name), message counts by topic, the /tracks messages and the
    vtrack metadata of a finished recording."""
    with path.open("rb") as file:
        reader = make_reader(file)
        summary = reader.get_summary()
        assert summary is not None
        channels = {c.topic: summary.schemas[c.schema_id].name for c in summary.channels.values()}
        counts: dict[str, int] = {}
        tracks = []
        for _, channel, message in reader.iter_messages():
            counts[channel.topic] = counts.get(channel.topic, 0) + 1
            if channel.topic == "/tracks":
                tracks.append(json.loads(message.data))
        (metadata,) = [dict(m.metadata) for m in reader.iter_metadata() if m.name == "vtrack"]
    return channels, counts, tracks, metadata


def test_a_recording_is_the_uploads_mcap_in_stream_mode(tmp_path):
    spec = StreamSpec(camera="gate", record=True, record_images="jpeg", record_segment=1.0)
    recording = Recording(spec, tmp_path, _no_errors)
    recording.new_run(("head",), (), OPTIONS)
    for index in range(3):
        recording.write(IMAGE, _message(index, 1_765_000_000.0 + 0.25 * index))
    recording.new_run(("head",), (), OPTIONS)  # the tracks start over: a new segment
    recording.write(IMAGE, _message(3, 1_765_000_001.0, track_id=6))
    recording.close()
    first, second = sorted(tmp_path.glob("*.mcap"))
    assert not list(tmp_path.glob("*.partial"))
    channels, counts, tracks, metadata = _read(first)
    assert channels == {
        "/camera/image": "foxglove.CompressedImage",
        "/camera/annotations": "foxglove.ImageAnnotations",
        "/tracks": "vtrack.StreamTracks",
    }
    assert counts == {"/camera/image": 3, "/camera/annotations": 3, "/tracks": 3}
    # what was published, sequence and latency included
    assert tracks[2] == json.loads(_message(2, 1_765_000_000.5).model_dump_json())
    # a camera announces nothing: every frame read was recorded, and no frame rate is made up
    assert metadata["frames_read"] == metadata["frames_processed"] == "3"
    assert (metadata["width"], metadata["height"], metadata["part_names"]) == ("64", "48", "head")
    assert "fps" not in metadata and "start" not in metadata and "end" not in metadata
    assert JobOptions.model_validate_json(metadata["options"]) == OPTIONS
    assert _read(second)[1]["/tracks"] == 1


def test_segments_end_by_stream_time_and_only_the_newest_are_kept(tmp_path):
    spec = StreamSpec(
        camera="gate", record=True, record_images="jpeg", record_segment=1.0, record_keep=2
    )
    recording = Recording(spec, tmp_path, _no_errors)
    recording.new_run((), (), OPTIONS)
    for index in range(7):  # 0.5 s apart: segments of two frames, the last of one
        recording.write(IMAGE, _message(index, 100.0 + 0.5 * index))
    recording.close()
    kept = sorted(tmp_path.glob("*.mcap"))
    assert [_read(path)[1]["/tracks"] for path in kept] == [2, 1]
    assert _read(kept[-1])[2][0]["sequence"] == 106


def test_a_stream_that_does_not_record_writes_nothing(tmp_path):
    recording = Recording(StreamSpec(camera="gate"), tmp_path, _no_errors)
    recording.new_run((), (), OPTIONS)
    recording.write(IMAGE, _message(0, 1.0))
    recording.close()
    assert list(tmp_path.iterdir()) == []
