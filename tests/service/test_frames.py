"""Frame timestamps: a frame is stamped with its presentation time in the video, so the frames of
a variable-frame-rate video keep their real spacing in the results and in the motion model."""

from __future__ import annotations

import shutil
from itertools import islice
from pathlib import Path

import av
import numpy as np
import pytest

from api_schemas.jobs import JobOptions
from service import frames
from service.analysis import analyze
from service.frames import DEFAULT_FPS, FrameSourceError, open_frames
from service.outputs.json_out import read_trajectories
from tests.service.conftest import PETS_VIDEO, VFR_MS, mux_silence, write_stamped

pytestmark = pytest.mark.slow

# For the tests that check which frames are read and what is said of the container: one box
# followed by the fastest correlation tracker reads the same frames as the people tracker, in
# a fortieth of the time (40 frames: 0.1 s against 4.4 s).
FRAMES_ONLY = JobOptions(
    mode="single_target",
    first_box={"x": 200, "y": 150, "w": 40, "h": 80},
    preset="mosse_gray",
    formats=["json"],
)


def test_a_constant_rate_video_is_stamped_index_over_fps(shared_data):
    # The H.264 AVI puts its first frame at 0.2 s (B-frame delay); the first frame is time 0.
    source = open_frames(shared_data / PETS_VIDEO)
    stamps = [(f.index, f.timestamp) for f in islice(source.timed(), 30)]
    assert stamps == [(i, pytest.approx(i / 10)) for i in range(30)]
    stepped = [(f.index, f.timestamp) for f in islice(source.timed(4), 5)]
    assert stepped == [(i, pytest.approx(i / 10)) for i in range(0, 20, 4)]


def test_a_variable_rate_video_keeps_its_presentation_times(vfr_video):
    source = open_frames(vfr_video)
    assert [f.timestamp for f in source.timed()] == pytest.approx([ms / 1000 for ms in VFR_MS])
    # skipped frames are grabbed, and the kept ones still carry their own times
    assert [(f.index, f.timestamp) for f in source.timed(3)] == [
        (i, pytest.approx(VFR_MS[i] / 1000)) for i in range(0, len(VFR_MS), 3)
    ]


def test_the_json_result_carries_the_presentation_times(vfr_video, tmp_path):
    result = analyze(vfr_video, JobOptions(formats=["json"]), tmp_path / "out")
    trajectories = read_trajectories(result.files["json"])
    points = [p for t in trajectories.tracks for p in t.frames]
    assert points, "people are tracked in the PETS frames"
    for point in points:
        assert point.timestamp == pytest.approx(VFR_MS[point.frame_index] / 1000)


@pytest.fixture(scope="module")
def vfr_matroska(shared_data, tmp_path_factory):
    frames = list(islice(open_frames(shared_data / PETS_VIDEO), len(VFR_MS)))
    return write_stamped(frames, VFR_MS, tmp_path_factory.mktemp("mkv") / "dropped_frames.mkv")


def test_a_complete_variable_rate_matroska_is_not_called_truncated(vfr_matroska, tmp_path):
    # Matroska states no frame count: OpenCV's duration x rate (27 here) is no promise
    source = open_frames(vfr_matroska)
    assert not source.count_stated and source.frame_count > len(VFR_MS)
    result = analyze(vfr_matroska, FRAMES_ONLY, tmp_path / "out")
    assert result.warnings == []
    assert result.video.frames_read == len(VFR_MS)
    assert result.video.frames_announced == 0


def test_a_cut_matroska_is_called_truncated_by_its_duration(shared_data, tmp_path):
    frames = list(islice(open_frames(shared_data / PETS_VIDEO), 40))
    data = write_stamped(frames, range(0, 4000, 100), tmp_path / "whole.mkv").read_bytes()
    cut = tmp_path / "cut.mkv"
    cut.write_bytes(data[: len(data) * 7 // 10])  # the header, with the duration, stays
    result = analyze(cut, FRAMES_ONLY, tmp_path / "out")
    assert 0 < result.video.frames_read < len(frames)
    assert any("of the 4.00 s its container announces" in w for w in result.warnings)


def test_a_matroska_starting_late_is_measured_from_its_first_frame(shared_data, tmp_path):
    # a segment of a longer recording, or a file cut with -copyts: its times start at 100 s,
    # and FFmpeg's Matroska writer states the track's end (104 s), not its length.
    # Before: "the video ended after 3.90 s of the 104.00 s its container announces", and
    # 1040 frames expected
    frames = list(islice(open_frames(shared_data / PETS_VIDEO), 40))
    late = write_stamped(frames, range(100_000, 104_000, 100), tmp_path / "late.mkv")
    source = open_frames(late)
    assert source.length == pytest.approx(4.0) and source.frame_count == 40
    result = analyze(late, FRAMES_ONLY, tmp_path / "out")
    assert result.warnings == [] and result.video.frames_read == 40


def test_a_list_of_other_files_is_not_taken_for_a_video(shared_data, tmp_path):
    # an ffconcat list named like a video: FFmpeg would read the files it names (in the
    # service, other clients' uploads beside it) as if they were this one
    shutil.copyfile(shared_data / PETS_VIDEO, tmp_path / "someone_elses.avi")
    listing = tmp_path / "clip.mp4"
    listing.write_text("ffconcat version 1.0\n" + "file someone_elses.avi\n" * 3)
    with pytest.raises(FrameSourceError) as refused:
        open_frames(listing)
    assert refused.value.reason == (
        "it is an FFmpeg concat file, which names other files or addresses to read: send the "
        "video itself"
    )


def test_frames_over_the_pixel_limit_are_refused_before_decoding(shared_data, monkeypatch):
    # a few kilobytes of H.264 can state 16000x16000 frames: gigabytes once decoded
    monkeypatch.setattr(frames, "MAX_PIXELS", 480 * 360 - 1)
    with pytest.raises(FrameSourceError, match="its frames of 480x360 pixels are more than"):
        open_frames(shared_data / PETS_VIDEO)


def test_frames_skipped_at_the_end_are_counted_as_read(vfr_video, tmp_path):
    # 12 frames with step 5: frames 0, 5 and 10 are tracked, 11 is read and skipped
    result = analyze(
        vfr_video,
        JobOptions(formats=["json"], frame_step=5, detector={"name": "default"}),
        tmp_path / "out",
    )
    assert result.frames_processed == 3
    assert result.video.frames_read == len(VFR_MS)
    assert result.warnings == []


@pytest.mark.parametrize(
    ("name", "fps", "count"), [("PETS09-S2L1", 7, 795), ("TUD-Stadtmitte", 25, 179)]
)
def test_a_motchallenge_folder_plays_at_its_frame_rate(shared_data, name, fps, count):
    sequence = shared_data / "mot" / name
    for path in (sequence, sequence / "img1"):
        source = open_frames(path)
        assert (source.fps, source.frame_count) == (fps, count)
        stamps = [f.timestamp for f in islice(source.timed(2), 3)]
        assert stamps == pytest.approx([0, 2 / fps, 4 / fps])


def _with_audio(video: Path, seconds: float, path: Path) -> Path:
    """``video``'s frames (stream-copied) beside an AAC track of ``seconds`` of silence."""
    with av.open(str(video)) as source, av.open(str(path), "w") as out:
        stream = out.add_stream_from_template(source.streams.video[0])
        mux_silence(out, seconds)
        for packet in source.demux(source.streams.video[0]):
            if packet.dts is not None:
                packet.stream = stream
                out.mux(packet)
    return path


@pytest.mark.parametrize("suffix", [".mkv", ".mp4"])
def test_sound_that_runs_on_after_the_pictures_is_no_truncation(shared_data, tmp_path, suffix):
    # before (Matroska): "the video ended after 3.90 s of the 4.50 s its container announces
    # (truncated or damaged file)": the container's duration spans the audio too
    frames = list(islice(open_frames(shared_data / PETS_VIDEO), 40))
    silent = write_stamped(frames, range(0, 4000, 100), tmp_path / f"silent{suffix}")
    video = _with_audio(silent, 4.5, tmp_path / f"recording{suffix}")
    source = open_frames(video)
    assert source.duration == pytest.approx(4.0, abs=0.11)
    assert source.frame_count == 40  # for Matroska an estimate, now from the video's duration
    result = analyze(video, FRAMES_ONLY, tmp_path / "out")
    assert (result.video.frames_read, result.warnings) == (40, [])


def test_a_millisecond_time_base_is_not_taken_for_the_frame_rate(shared_data, tmp_path):
    # WebM from browsers (MediaRecorder) states 1000 frames per second: it was reported as the
    # video's rate, and 40 frames were announced as 3900 (progress stuck near 1%)
    frames = list(islice(open_frames(shared_data / PETS_VIDEO), 40))
    path = write_stamped(frames, range(0, 4000, 100), tmp_path / "browser.mkv", rate=1000)
    source = open_frames(path)
    # no rate, so the count that Matroska does not state is estimated at the default rate
    assert source.fps is None and source.frame_count == round(3.9 * DEFAULT_FPS)
    stamps = [f.timestamp for f in source.timed()]
    assert stamps == pytest.approx([i / 10 for i in range(40)])
    result = analyze(path, FRAMES_ONLY, tmp_path / "out")
    assert result.warnings == [  # before: "declares no frame rate", of a video stating 1000
        "the video states no usable frame rate; frames without a presentation time of their "
        "own are stamped 25 per second"
    ]


@pytest.mark.parametrize(("muxer", "codec"), [("h264", "libx264"), ("m4v", "mpeg4")])
def test_a_raw_elementary_stream_plays_at_its_header_rate(shared_data, tmp_path, muxer, codec):
    # DVRs export raw .h264: no container, no timestamps, the rate only in the codec's headers.
    # Before, it was reported and stamped at FFmpeg's default 25 frames per second.
    path = tmp_path / f"export.{muxer}"
    with av.open(str(path), "w", format=muxer) as container:
        stream = container.add_stream(codec, rate=5)
        stream.width, stream.height, stream.pix_fmt = 480, 360, "yuv420p"
        for index, image in enumerate(islice(open_frames(shared_data / PETS_VIDEO), 12)):
            frame = av.VideoFrame.from_ndarray(image, format="rgb24")
            frame.pts = index
            container.mux(stream.encode(frame))
        container.mux(stream.encode())
    source = open_frames(path)
    assert source.fps == 5
    assert [f.timestamp for f in source.timed()] == pytest.approx([i / 5 for i in range(12)])
    result = analyze(path, FRAMES_ONLY, tmp_path / "out")
    assert (result.video.fps, result.video.frames_read, result.warnings) == (5, 12, [])


@pytest.mark.parametrize("suffix", [".mp4", ".ts"])
def test_a_clip_cut_without_its_keyframe_says_its_start_is_missing(shared_data, tmp_path, suffix):
    # Keyframes every 10 frames; the clip keeps the stream from its 6th frame, so its first 5
    # frames reference a keyframe it lacks. Before, the warning blamed the end: "the video
    # ended after 15 of the 20 frames its container announces (truncated or damaged file)".
    whole = tmp_path / "whole.mp4"
    with av.open(str(whole), "w") as container:
        stream = container.add_stream("libx264", rate=10, options={"g": "10", "bf": "0"})
        stream.width, stream.height, stream.pix_fmt = 480, 360, "yuv420p"
        for image in islice(open_frames(shared_data / PETS_VIDEO), 25):
            container.mux(stream.encode(av.VideoFrame.from_ndarray(image, format="rgb24")))
        container.mux(stream.encode())
    clip = tmp_path / f"clip{suffix}"
    with av.open(str(whole)) as source, av.open(str(clip), "w") as out:
        stream = out.add_stream_from_template(source.streams.video[0])
        packets = [p for p in source.demux(source.streams.video[0]) if p.size][5:]
        start = packets[0].pts
        for packet in packets:
            packet.pts -= start
            packet.dts -= start
            packet.stream = stream
            out.mux(packet)
    source = open_frames(clip)
    assert (source.lead_frames, source.lead_seconds) == (5, pytest.approx(0.5))
    result = analyze(clip, FRAMES_ONLY, tmp_path / "out")
    assert result.video.frames_read == 15
    assert result.warnings == [
        "the first 5 frames (0.50 s) could not be decoded: the video starts without a keyframe, "
        "as a clip cut from a longer recording does; tracking starts at its first keyframe, and "
        "frame numbers and times count from there"
    ]


def test_a_clip_shorter_than_a_confirmation_says_so(shared_data, tmp_path):
    # before: a one-frame clip of five people succeeded with no track and no word why
    frames = list(islice(open_frames(shared_data / PETS_VIDEO), 1))
    clip = write_stamped(frames, [0], tmp_path / "one_frame.mp4")
    embedded = {"name": "default"}  # no CNN model here: 'auto' would add its warning
    result = analyze(clip, JobOptions(formats=["json"], detector=embedded), tmp_path / "out")
    assert read_trajectories(result.files["json"]).tracks == []
    assert result.warnings == [
        "only 1 frame was tracked, and a person is reported once seen in 3 "
        "(tracker.confirm_hits): for a clip this short, set tracker.confirm_hits to 1"
    ]
    options = JobOptions(formats=["json"], tracker={"confirm_hits": 1}, detector=embedded)
    result = analyze(clip, options, tmp_path / "again")
    assert read_trajectories(result.files["json"]).tracks and result.warnings == []


def _copy_frames(sequence: Path, numbers, folder: Path, name: str = "{:06d}.jpg") -> Path:
    folder.mkdir(parents=True)
    for number in numbers:
        (folder / name.format(number)).write_bytes(
            (sequence / "img1" / f"{number:06d}.jpg").read_bytes()
        )
    return folder


def test_unpadded_image_names_play_in_their_numbers_order(shared_data, tmp_path):
    sequence = shared_data / "mot" / "TUD-Stadtmitte"
    folder = _copy_frames(sequence, range(1, 13), tmp_path / "frames", "img{}.jpg")
    reference = list(islice(open_frames(sequence), 12))
    # text order played img1, img10, img11, img12, img2, ...
    assert all((a == b).all() for a, b in zip(open_frames(folder), reference, strict=True))


def test_missing_images_leave_their_frames_out_and_the_others_keep_their_numbers(
    shared_data, tmp_path
):
    sequence = shared_data / "mot" / "TUD-Stadtmitte"
    copy = tmp_path / "TUD-gap"
    _copy_frames(sequence, [n for n in range(1, 21) if n not in (10, 11)], copy / "img1")
    (copy / "seqinfo.ini").write_text((sequence / "seqinfo.ini").read_text())
    source = open_frames(copy)
    frames = list(source.timed())
    # frame 12 is frame 12 (index 11), as in det.txt and gt.txt, not the tenth image's 10
    assert [f.index for f in frames] == [n - 1 for n in range(1, 21) if n not in (10, 11)]
    assert frames[9].timestamp == pytest.approx(11 / 25)
    assert source.frame_count == 20
    result = analyze(source, FRAMES_ONLY, tmp_path / "out")
    assert result.video.frames_read == 20 and result.frames_processed == 18
    assert list(source.notes) == result.warnings[: len(source.notes)]  # told with the results
    assert source.notes == (
        f"{copy / 'img1'} has no image for 2 of its frames (10-11, counted from 1): they are "
        "left out, and the other frames keep their files' numbers",
        f"{copy / 'seqinfo.ini'} states seqLength 179, but the images of {copy / 'img1'} end at "
        "frame 20: the frames there were tracked",
    )


def test_a_motchallenge_sequence_cut_from_later_keeps_its_frame_numbers(shared_data, tmp_path):
    sequence = shared_data / "mot" / "TUD-Stadtmitte"
    copy = tmp_path / "TUD-late"
    _copy_frames(sequence, range(41, 46), copy / "img1")
    (copy / "seqinfo.ini").write_text(
        (sequence / "seqinfo.ini").read_text().replace("frameRate=25", "frameRate=abc")
    )
    source = open_frames(copy)
    assert [f.index for f in source.timed()] == [40, 41, 42, 43, 44]  # 000041.jpg is frame 41
    assert source.fps is None
    assert f"{copy / 'seqinfo.ini'}: frameRate 'abc' is not a number of frames per second" in (
        source.notes
    )
    # a folder without seqinfo.ini counts its images (names may be times in milliseconds)
    plain = _copy_frames(sequence, range(41, 50, 2), tmp_path / "plain")
    assert [f.index for f in open_frames(plain).timed()] == [0, 1, 2, 3, 4]
    assert open_frames(plain).notes == ()


def test_a_video_stored_turned_is_read_upright(shared_data, tmp_path):
    # A phone held upright stores its pictures turned, with a display matrix that turns them
    # back; the frames come out as a player shows them, upright, for the detectors to see
    # people standing (OpenCV applies the matrix: CAP_PROP_ORIENTATION_AUTO).
    frames = list(islice(open_frames(shared_data / PETS_VIDEO), 10))
    path = tmp_path / "phone.mp4"
    with av.open(str(path), "w") as container:
        stream = container.add_stream("mpeg4", rate=10)
        stream.width, stream.height, stream.pix_fmt = 360, 480, "yuv420p"
        stream.set_display_rotation(-90)
        for image in frames:
            stored = np.ascontiguousarray(np.rot90(image))
            container.mux(stream.encode(av.VideoFrame.from_ndarray(stored, format="rgb24")))
        container.mux(stream.encode())
    source = open_frames(path)
    assert (source.width, source.height) == (480, 360)
    read = list(source)
    assert len(read) == len(frames)
    for original, image in zip(frames, read, strict=True):
        assert image.shape == original.shape
        assert np.abs(image.astype(int) - original).mean() < 6  # mpeg4's loss only
