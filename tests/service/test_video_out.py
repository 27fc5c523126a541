"""Annotated MP4: H.264 that browsers play from the first bytes, each frame at its presentation
time, and the tracks drawn where the JSON result puts them."""

from __future__ import annotations

import struct
from dataclasses import replace
from fractions import Fraction
from itertools import islice
from pathlib import Path

import av
import cv2
import numpy as np
import pytest
from mcap.reader import make_reader

from api_schemas.jobs import JobOptions
from api_schemas.tracks import BoxModel, FrameTracksMessage, PartState, TrackState, VideoInfo
from service.analysis import analyze
from service.frames import TimedFrame, open_frames
from service.outputs import h264
from service.outputs.base import RunSummary, StreamInfo
from service.outputs.h264 import h264_unavailable
from service.outputs.json_out import read_trajectories
from service.outputs.palette import track_colour
from service.outputs.video_out import H264Encoder, Mp4vEncoder, TrackDrawer, VideoWriter
from tests.service.conftest import PETS_VIDEO, VFR_MS

pytestmark = pytest.mark.slow


def top_level_boxes(data: bytes) -> list[str]:
    """The types of an MP4 file's top-level boxes, in file order (ISO 14496-12)."""
    types, offset = [], 0
    while offset + 8 <= len(data):
        size, kind = struct.unpack(">I4s", data[offset : offset + 8])
        if size == 1:  # 64-bit size follows the type
            size = struct.unpack(">Q", data[offset + 8 : offset + 16])[0]
        types.append(kind.decode("ascii"))
        if size < 8:
            break
        offset += size
    return types


def decoded(path: Path) -> list[tuple[float, np.ndarray]]:
    """(presentation time in seconds, RGB image) of every frame."""
    with av.open(str(path)) as container:
        return [
            (float(f.pts * f.time_base), f.to_ndarray(format="rgb24"))
            for f in container.decode(video=0)
        ]


@pytest.fixture(scope="module")
def annotated(vfr_video, tmp_path_factory):
    return analyze(
        vfr_video, JobOptions(formats=["json", "mp4"]), tmp_path_factory.mktemp("annotated")
    )


def test_this_install_writes_h264():
    # PyAV is a dependency and its wheels carry x264: the mp4v fallback is for custom builds.
    assert h264_unavailable() is None


def test_the_annotated_video_is_h264_with_its_index_first(annotated):
    path = annotated.files["mp4"]
    boxes = top_level_boxes(path.read_bytes())
    # the index (moov) before the frames (mdat): a browser starts playing before the download ends
    assert boxes[0] == "ftyp" and boxes.index("moov") < boxes.index("mdat"), boxes
    with av.open(str(path)) as container:
        codec = container.streams.video[0].codec_context
        assert (codec.name, codec.pix_fmt, codec.width, codec.height) == (
            "h264",
            "yuv420p",
            480,
            360,
        )


def test_frames_keep_their_presentation_times(annotated):
    # the source dropped frames (gaps of 0.5 s and 1.2 s): a constant-rate video would play
    # them 0.1 s apart and drift 1.5 s from the JSON's timestamps
    times = [t for t, _ in decoded(annotated.files["mp4"])]
    assert times == pytest.approx([ms / 1000 for ms in VFR_MS], abs=1e-3)


def test_tracks_are_drawn_where_the_json_puts_them(annotated, vfr_video):
    sources = list(open_frames(vfr_video))
    frames = [image for _, image in decoded(annotated.files["mp4"])]
    points: dict[int, list] = {}
    for track in read_trajectories(annotated.files["json"]).tracks:
        for point in track.frames:
            points.setdefault(point.frame_index, []).append(point.box)
    assert points, "people are tracked in the PETS frames"
    edges, beside = [], []
    for index, boxes in points.items():
        change = np.abs(frames[index].astype(int) - sources[index].astype(int)).sum(axis=2)
        for box in boxes:
            x0, y0 = round(box.x), round(box.y)
            x1, y1 = round(box.x + box.w), round(box.y + box.h)
            if x0 < 5 or y0 < 0 or x1 > 474 or y1 >= 360:
                continue
            edges.extend([change[y0:y1, x0].mean(), change[y0:y1, x1].mean()])
            beside.extend([change[y0:y1, x0 - 5].mean(), change[y0:y1, x1 + 5].mean()])
    assert edges
    # a box's sides are painted in its colour; 5 px beside them is the frame, up to compression
    # (inside are the part dots)
    assert np.median(edges) > 4 * np.median(beside), (np.median(edges), np.median(beside))


def encode_pets(encoder_type, path: Path, shared_data: Path, size: tuple[int, int]) -> list:
    """The first 5 frames of the PETS video cropped to ``size`` (w, h), encoded 0.1 s apart;
    returns the BGR frames written."""
    width, height = size
    images = [
        np.ascontiguousarray(image[:height, :width, ::-1])
        for image in islice(open_frames(shared_data / PETS_VIDEO), 5)
    ]
    encoder = encoder_type(path, width, height, 10.0)
    for i, image in enumerate(images):
        encoder.write(image, i / 10)
    encoder.close()
    return images


def test_odd_sized_frames_are_padded_by_one_row_and_column(shared_data, tmp_path):
    path = tmp_path / "odd.mp4"
    images = encode_pets(H264Encoder, path, shared_data, (479, 359))
    frames = decoded(path)
    assert [t for t, _ in frames] == pytest.approx([0.0, 0.1, 0.2, 0.3, 0.4])
    for (_, image), source in zip(frames, images, strict=True):
        assert image.shape == (360, 480, 3)
        error = np.abs(image[:359, :479].astype(int) - source[:, :, ::-1].astype(int)).mean()
        assert error < 6, error  # the same picture, up to compression


def test_the_mp4v_fallback_writes_a_video_opencv_reads(shared_data, tmp_path):
    path = tmp_path / "fallback.mp4"
    encode_pets(Mp4vEncoder, path, shared_data, (480, 360))
    capture = cv2.VideoCapture(str(path))
    read = []
    while (frame := capture.read()[1]) is not None:
        read.append(frame)
    capture.release()
    assert len(read) == 5 and read[0].shape == (360, 480, 3)


def test_without_x264_the_results_fall_back_and_the_job_says_so(monkeypatch, vfr_video, tmp_path):
    # as on a PyAV built against an FFmpeg without x264
    monkeypatch.setattr(h264, "h264_unavailable", lambda: "PyAV's FFmpeg has no libx264 encoder")
    result = analyze(vfr_video, JobOptions(formats=["mcap", "mp4"]), tmp_path / "out")
    with av.open(str(result.files["mp4"])) as container:
        assert container.streams.video[0].codec_context.name == "mpeg4"
    with result.files["mcap"].open("rb") as handle:
        summary = make_reader(handle).get_summary()
    assert {s.name for s in summary.schemas.values()} >= {"foxglove.CompressedImage"}
    assert [w for w in result.warnings if "libx264" in w] == [
        "the annotated video is mp4v, which browsers do not play: PyAV's FFmpeg has no libx264 "
        "encoder",
        "the mcap holds JPEG images instead of H.264 video: PyAV's FFmpeg has no libx264 encoder",
    ]


def test_non_square_pixels_are_reported_and_kept_in_the_annotated_video(shared_data, tmp_path):
    # A recorder storing 4:3 pictures 360 px wide (pixels 4/3 as wide as tall). Before, the
    # result did not say so and the annotated MP4 played squeezed, with square pixels.
    path = tmp_path / "squeezed.mp4"
    with av.open(str(path), "w") as container:
        stream = container.add_stream("libx264", rate=10)
        stream.width, stream.height, stream.pix_fmt = 360, 360, "yuv420p"
        stream.codec_context.sample_aspect_ratio = Fraction(4, 3)
        for image in islice(open_frames(shared_data / PETS_VIDEO), 10):
            squeezed = cv2.resize(image, (360, 360), interpolation=cv2.INTER_AREA)
            container.mux(stream.encode(av.VideoFrame.from_ndarray(squeezed, format="rgb24")))
        container.mux(stream.encode())
    assert open_frames(path).pixel_aspect == pytest.approx(4 / 3)
    result = analyze(path, JobOptions(formats=["json", "mp4", "mcap"]), tmp_path / "out")
    video = read_trajectories(result.files["json"]).video
    assert (video.width, video.height, video.pixel_aspect_ratio) == (360, 360, pytest.approx(4 / 3))
    with av.open(str(result.files["mp4"])) as container:
        assert container.streams.video[0].sample_aspect_ratio == Fraction(4, 3)
    # An MCAP read on its own says so too (its images are in stored pixels).
    with result.files["mcap"].open("rb") as handle:
        (record,) = [m for m in make_reader(handle).iter_metadata() if m.name == "vtrack"]
    assert record.metadata["width"] == "360" and record.metadata["height"] == "360"
    assert float(record.metadata["pixel_aspect_ratio"]) == pytest.approx(4 / 3)
    assert float(record.metadata["fps"]) == 10.0


def test_square_pixels_stay_square(annotated):
    video = read_trajectories(annotated.files["json"]).video
    assert video.pixel_aspect_ratio == 1.0
    with av.open(str(annotated.files["mp4"])) as container:
        assert container.streams.video[0].sample_aspect_ratio in (None, 0, 1)


SKELETON = (("head", "neck"), ("neck", "left_shoulder"))


def _posed(track_id: int = 1) -> FrameTracksMessage:
    """A person with a visible head and neck 40 px apart and a hidden left shoulder."""
    parts = [
        PartState(name="head", x=60.0, y=20.0, visible=True, measured=True),
        PartState(name="neck", x=60.0, y=60.0, visible=True, measured=True),
        PartState(name="left_shoulder", x=20.0, y=60.0, visible=False),
    ]
    box = BoxModel(x=10.0, y=10.0, w=100.0, h=100.0)
    track = TrackState(track_id=track_id, box=box, score=0.9, occluded=False, parts=parts)
    return FrameTracksMessage(frame_index=0, timestamp=0.0, tracks=[track])


def test_limbs_are_drawn_between_visible_parts_in_the_track_colour():
    grey = np.full((120, 120, 3), 128, np.uint8)
    drawn = TrackDrawer(skeleton=SKELETON).draw(grey, _posed())
    bare = TrackDrawer().draw(grey, _posed())
    r, g, b = track_colour(1)
    # along the head-neck limb, away from the part dots: the track's colour (BGR), up to the
    # anti-aliasing of a 1 px line
    assert np.abs(drawn[30:51, 60].astype(int) - (b, g, r)).max() <= 16
    assert (bare[30:51, 60] == 128).all()
    # the limb to the hidden shoulder is left out
    assert (drawn[60, 30:51] == 128).all()


def test_the_annotated_video_shows_the_limbs(tmp_path):
    grey = np.full((120, 120, 3), 128, np.uint8)
    video = VideoInfo(width=120, height=120, frames_announced=3, frames_read=3, frame_step=1)
    frames = []
    for skeleton in (SKELETON, ()):
        info = StreamInfo(120, 120, 10.0, 1, ("head", "neck", "left_shoulder"), "people")
        writer = VideoWriter(tmp_path / f"{len(skeleton)}.mp4", replace(info, skeleton=skeleton))
        for index in range(3):
            writer.write(TimedFrame(index, index / 10, grey), _posed())
        writer.close(RunSummary(video, 3))
        frames.append(decoded(writer.path)[-1][1].astype(int))
    limb = np.abs(frames[0][30:51, 59:62] - frames[1][30:51, 59:62]).sum(axis=2).max(axis=1)
    assert (limb > 60).all(), limb  # each row of the limb changed, through compression
