"""Greyscale video (infrared and monochrome cameras) is tracked, and the job says what its
colour cues cannot do there; real videos through ``service.analysis.analyze``."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from api_schemas.jobs import JobOptions
from service.analysis import analyze
from tests.service.test_cli import vtrack

PEOPLE_GREY = "the video is greyscale (an infrared or monochrome camera?): every person's"
ONE_BOX = {"x": 312, "y": 99, "w": 19, "h": 47}


@pytest.fixture(scope="module")
def grey_video(pets_cut, tmp_path_factory):
    """The PETS clip as a monochrome camera records it: MJPG written with one channel."""
    capture = cv2.VideoCapture(str(pets_cut))
    path = tmp_path_factory.mktemp("grey") / "ir.avi"
    writer = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*"MJPG"), 10.0, (480, 360), False)
    while (read := capture.read())[0]:
        writer.write(cv2.cvtColor(read[1], cv2.COLOR_BGR2GRAY))
    writer.release()
    capture.release()
    return path


def test_people_in_greyscale_video_are_tracked_with_a_word_on_their_colours(grey_video, tmp_path):
    # before: tracked without a word, identities then rest on less than the docs promise
    result = analyze(grey_video, JobOptions(formats=["json"]), tmp_path / "out")
    assert result.frames_processed == 24
    assert [w for w in result.warnings if w.startswith("the video is greyscale")] == [
        PEOPLE_GREY + " clothing colours are the same grey, so they do not help keep people "
        "apart or recognise those who come back; identities rest on motion and appearance alone"
    ]


def test_a_colour_preset_on_greyscale_video_is_named(grey_video, tmp_path):
    options = JobOptions(mode="single_target", first_box=ONE_BOX, preset="rcsk_cn")
    result = analyze(grey_video, options, tmp_path / "cn")
    assert (
        "the video is greyscale: the colour features (cn) of preset rcsk_cn see no colour in "
        "it; a grey preset (rcsk_gray) follows the same intensities without them" in result.warnings
    )
    grey = JobOptions(mode="single_target", first_box=ONE_BOX, preset="rcsk_gray")
    assert not any("greyscale" in w for w in analyze(grey_video, grey, tmp_path / "g").warnings)


def test_colour_video_gets_no_such_word(pets_cut, tmp_path):
    result = analyze(pets_cut, JobOptions(formats=["json"]), tmp_path / "out")
    assert not any("greyscale" in warning for warning in result.warnings)


def test_vtrack_track_says_the_same_of_greyscale_video(grey_video, tmp_path):
    # before: `vtrack track` followed the box with Color Names on grey frames without a word
    box = "{x},{y},{w},{h}".format(**ONE_BOX)
    tracked = vtrack("track", grey_video, "--box", box, "--end", 1, "--quiet")
    assert tracked.returncode == 0, tracked.stderr
    assert (
        "vtrack: warning: the video is greyscale: the colour features (cn) of preset "
        "strcf_hog_cn see no colour in it" in tracked.stderr
    )
    grey = vtrack("track", grey_video, "--box", box, "--end", 1, "--quiet", "--preset", "rcsk_gray")
    assert grey.returncode == 0 and "greyscale" not in grey.stderr, grey.stderr


def test_vtrack_track_refuses_frames_too_small_to_track(tmp_path):
    # before: tracked a box in 16x8 frames that uploads and streams refuse
    path = tmp_path / "tiny.avi"
    writer = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*"MJPG"), 10.0, (16, 8))
    for value in range(0, 250, 25):
        writer.write(np.full((8, 16, 3), value, np.uint8))
    writer.release()
    tracked = vtrack("track", path, "--box", "2,2,4,4")
    assert tracked.returncode == 2
    assert tracked.stderr.strip() == (
        "vtrack: a frame size of 16x8 is too small to track: width and height must be at least "
        "32 pixels"
    )
    assert tracked.stdout == ""
