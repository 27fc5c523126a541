"""Behaviour of the single-target trackers: synthetic scenes, a real sequence, bad input."""

import dataclasses

import numpy as np
import pytest
from scipy import ndimage

from tracking.correlation import PRESETS, CorrelationConfig, CorrelationTracker, ScaleConfig
from tracking.datasets.otb import load_otb_sequence, read_frame
from tracking.evaluation.metrics import center_location_error, success_auc
from tracking.types import Box


def textured(rng, shape, sigma):
    """Smoothed colour noise stretched to 0..255."""
    noise = ndimage.gaussian_filter(rng.standard_normal(shape), (sigma, sigma, 0))
    noise -= noise.min()
    return (255 * noise / noise.max()).astype(np.uint8)


def moving_target_scene(frames=50, size=(48, 36), scale_per_frame=1.0, seed=0):
    """A colourful textured target moving diagonally over a textured background.

    Returns the frames and the true boxes. The target's texture is resampled when it grows, so
    its appearance is the same object at another size, as a camera would see it.
    """
    rng = np.random.default_rng(seed)
    height, width = 240, 320
    background = textured(rng, (height, width, 3), 3.0)
    target = textured(rng, (96, 72, 3), 2.0)
    target[..., 0] = np.clip(target[..., 0].astype(int) + 60, 0, 255)  # redder than the scene
    images, boxes = [], []
    for t in range(frames):
        w = size[0] * scale_per_frame**t
        h = size[1] * scale_per_frame**t
        x, y = 60 + 2.5 * t, 50 + 1.5 * t
        frame = background.copy()
        sprite = ndimage.zoom(target, (h / 96, w / 72, 1), order=1)
        sh, sw = sprite.shape[:2]
        frame[int(y) : int(y) + sh, int(x) : int(x) + sw] = sprite
        images.append(frame)
        boxes.append((int(x), int(y), sw, sh))
    return images, np.array(boxes, dtype=float)


def run(tracker, images, first_box):
    tracker.initialize(images[0], Box(*first_box))
    return np.array([first_box] + [tracker.update(f).box.as_array() for f in images[1:]])


@pytest.mark.parametrize(
    "preset",
    [
        "mosse_gray",  # eq. 2.4, linear, one filter per channel
        "csk_gray",  # eq. 2.10, Gaussian kernel, interpolated coefficients
        "rcsk_gray",  # eq. 2.21, the proposed learning
        "rcsk_cn",  # gray + Color Names, the thesis's proposed tracker
        "rcsk_cn_pca2",  # Algorithm 4.2: 11 dimensions adaptively reduced to 2
        "rcsk_opponent",  # a pixel-wise colour space
        "rcsk_hue",  # a histogram representation
        "hog_cn_scale",  # HOG + Color Names on cells, with scale adaptation
    ],
)
def test_tracker_follows_a_moving_textured_target(preset):
    images, truth = moving_target_scene()
    boxes = run(CorrelationTracker(PRESETS[preset]), images, truth[0])
    errors = center_location_error(boxes, truth)
    assert errors.max() < 6.0, f"{preset} drifted: max centre error {errors.max():.1f} px"


@pytest.mark.parametrize("kernel", ["linear", "polynomial", "gaussian"])
def test_every_kernel_tracks(kernel):
    images, truth = moving_target_scene(frames=30)
    tracker = CorrelationTracker(CorrelationConfig(kernel=kernel, feature="gray+cn"))
    errors = center_location_error(run(tracker, images, truth[0]), truth)
    assert errors.max() < 6.0


def test_scale_mode_follows_a_growing_target():
    images, truth = moving_target_scene(frames=40, size=(40, 30), scale_per_frame=1.015)
    fixed = run(CorrelationTracker(CorrelationConfig(feature="gray+cn")), images, truth[0])
    adaptive_config = CorrelationConfig(feature="gray+cn", scale=ScaleConfig())
    adaptive = run(CorrelationTracker(adaptive_config), images, truth[0])
    # The target grows by 1.015^39 = 1.79; the scale mode must follow most of that.
    assert adaptive[-1, 2] / truth[0, 2] == pytest.approx(truth[-1, 2] / truth[0, 2], rel=0.12)
    assert success_auc(adaptive, truth) > success_auc(fixed, truth) + 0.05


@pytest.mark.parametrize("size", [(6, 5), (8, 6), (12, 9), (16, 12)])
def test_the_default_preset_follows_small_targets(size):
    # On 4-pixel cells a 12 x 9 px target's padded patch was a grid of 8 x 6 cells, too few to
    # tell the target from its surroundings: it was lost within frames (max error 112 px)
    images, truth = moving_target_scene(frames=40, size=size)
    boxes = run(CorrelationTracker(PRESETS["hog_cn_scale"]), images, truth[0])
    errors = center_location_error(boxes, truth)
    assert errors.max() < 3.0, f"{size}: max centre error {errors.max():.1f} px"


@pytest.mark.parametrize("size", [(1, 1), (2, 2), (4, 4), (3, 8)])
def test_a_target_under_six_pixels_keeps_its_size(size):
    # The scale filter's floor of 6 px per side was a floor above 1 for them: a 1 px target
    # became 5 px on the first update of an unchanged frame, a 3 x 8 one 6 x 16.
    images, truth = moving_target_scene(frames=1, size=size)
    tracker = CorrelationTracker(PRESETS["hog_cn_scale"])
    tracker.initialize(images[0], Box(*truth[0]))
    for _ in range(5):
        box = tracker.update(images[0]).box
    assert (box.w, box.h) == pytest.approx(size, rel=0.05)


@pytest.mark.parametrize(
    ("box", "grid"),
    [
        (Box(100, 80, 12, 9), (16, 21)),  # short side 22.5 px -> 64 px: 16 cells
        (Box(100, 80, 17, 50), (34, 12)),  # enlarged only to the area cap (6400 px), not 64 px
        (Box(50, 40, 40, 40), (20, 20)),  # 100 x 100 px: shrunk to the cap, as before
    ],
)
def test_small_patches_are_enlarged_up_to_the_area_cap(box, grid):
    image = np.zeros((240, 320, 3), np.uint8)
    tracker = CorrelationTracker(PRESETS["hog_cn_scale"])  # 4 px cells, 2.5 x padding
    tracker.initialize(image, box)
    response = tracker.respond(image)
    assert response.response.shape == grid
    rows, cols = grid
    assert rows * cols * 16 <= 6400 * 1.05  # the cap holds (up to rounding to whole cells)


def test_reset_forgets_the_target():
    images, truth = moving_target_scene(frames=3)
    tracker = CorrelationTracker()
    tracker.initialize(images[0], Box(*truth[0]))
    tracker.reset()
    with pytest.raises(RuntimeError, match="initialize"):
        tracker.update(images[1])
    # each method names itself (before: respond() and learn() said "before update()")
    with pytest.raises(RuntimeError, match=r"initialize\(\) must be called before respond\(\)"):
        tracker.respond(images[1])


def test_a_preset_may_be_given_by_name():
    assert CorrelationTracker("rcsk_cn").config == PRESETS["rcsk_cn"]
    # before: AttributeError: 'str' object has no attribute 'feature'
    with pytest.raises(ValueError, match="unknown preset 'rcsk'; presets: mosse_gray, csk_gray"):
        CorrelationTracker("rcsk")
    with pytest.raises(TypeError, match="config must be a CorrelationConfig or a preset's name"):
        CorrelationTracker(3)


def test_a_preset_names_the_features_that_read_colour():
    assert PRESETS["hog_cn_scale"].colour_features == ("cn",)
    assert PRESETS["rcsk_opp_angle"].colour_features == ("opp_angle",)
    assert PRESETS["rcsk_gray"].colour_features == ()
    assert CorrelationConfig(feature="hog+gray").colour_features == ()


@pytest.mark.slow
def test_rcsk_with_color_names_stays_on_a_real_target(shared_data):
    """Skating1 (400 frames, a skater under changing stage light): with the w2c table the
    thesis's RCSK + Color Names tracker keeps the skater over the first 150 frames."""
    sequence = load_otb_sequence(shared_data / "otb" / "Skating1")
    config = dataclasses.replace(
        PRESETS["rcsk_cn"], color_names_path=str(shared_data / "colornames" / "w2c.mat")
    )
    tracker = CorrelationTracker(config)
    frames = [read_frame(p) for p in sequence.frame_paths[:150]]
    boxes = run(tracker, frames, sequence.ground_truth[0])
    errors = center_location_error(boxes, sequence.ground_truth[:150])
    assert np.median(errors) < 10.0
    assert np.mean(errors <= 20.0) > 0.9


# -- bad input -------------------------------------------------------------------------------

FRAME = np.zeros((120, 160, 3), np.uint8)


@pytest.mark.parametrize(
    ("frame", "box", "message"),
    [
        (np.zeros((0, 0, 3), np.uint8), Box(1, 1, 5, 5), "empty"),  # empty frame
        (np.zeros((10, 10, 4), np.uint8), Box(1, 1, 5, 5), r"\(H, W, 3\)"),  # RGBA
        ([[1, 2], [3, 4]], Box(0, 0, 1, 1), "numpy array"),  # not an array
        (FRAME, Box(10, 10, 0, 20), "at least 1 pixel"),  # zero width
        (FRAME, Box(500, 10, 20, 20), "outside"),  # box right of the frame
        (FRAME, Box(-50, -50, 20, 20), "outside"),  # box above-left of the frame
        (FRAME, Box(np.nan, 10, 20, 20), "finite"),  # NaN coordinate
        (np.zeros((120, 160), np.uint8), Box(10, 10, 20, 20), "needs an RGB frame"),  # cn on gray
        # a box overlapping the frame but absurdly large (was: a 116 TiB allocation)
        (FRAME, Box(-1e6, -1e6, 2e6, 2e6), "more than 4 times the size"),
    ],
)
def test_bad_input_raises_a_clear_error(frame, box, message):
    with pytest.raises((ValueError, TypeError), match=message):
        CorrelationTracker(PRESETS["rcsk_cn"]).initialize(frame, box)


def test_gray_features_accept_a_grayscale_frame():
    images, truth = moving_target_scene(frames=5)
    gray = [f.mean(axis=2).astype(np.uint8) for f in images]
    boxes = run(CorrelationTracker(PRESETS["rcsk_gray"]), gray, truth[0])
    assert center_location_error(boxes, truth).max() < 6.0


@pytest.mark.parametrize("preset", ["hog_cn_scale", "rcsk_gray"])
@pytest.mark.parametrize("dtype", [np.int64, np.bool_, np.float64, np.uint16])
def test_a_frame_that_is_not_uint8_is_refused(preset, dtype):
    # was: cv2.error from deep inside resize for hog_cn_scale
    with pytest.raises(TypeError, match="needs a uint8 frame"):
        CorrelationTracker(PRESETS[preset]).initialize(FRAME.astype(dtype), Box(10, 10, 20, 20))


def test_a_box_may_be_four_numbers_of_any_kind():
    for given in [(10, 10, 20, 20), np.array([10, 10, 20, 20]), [np.int64(10), 10, 20.0, 20]]:
        tracker = CorrelationTracker(PRESETS["rcsk_gray"])
        tracker.initialize(FRAME, given)  # was: AttributeError 'tuple' object has no 'x'
        assert type(tracker.update(FRAME).box.x) is float  # no numpy scalars leak out
    with pytest.raises(TypeError, match="four numbers"):
        CorrelationTracker(PRESETS["rcsk_gray"]).initialize(FRAME, "10,10,20,20")


def test_a_frame_of_another_size_mid_sequence_is_refused():
    # was: tracked on with the centre clamped into the smaller frame, the box jumping
    tracker = CorrelationTracker(PRESETS["hog_cn_scale"])
    tracker.initialize(FRAME, Box(40, 40, 20, 30))
    with pytest.raises(ValueError, match="initialize the tracker again"):
        tracker.update(FRAME[:60, :80])


def test_frame_of_another_shape_mid_sequence_still_tracks_or_raises_clearly():
    images, truth = moving_target_scene(frames=3)
    tracker = CorrelationTracker(PRESETS["rcsk_cn"])
    tracker.initialize(images[0], Box(*truth[0]))
    with pytest.raises(ValueError, match="needs an RGB frame"):
        tracker.update(images[1][..., 0])


@pytest.mark.parametrize(
    "fields",
    [
        {"learning_rate": 0.0},  # gamma outside (0, 1]
        {"learner": "kcf"},  # unknown learner
        {"kernel": "laplacian"},  # unknown kernel
        {"learner": "mosse", "compressed_dim": 2},  # reduction needs a kernel learner
        {"cell_size": 0},
        {"min_patch_side": -1},
    ],
)
def test_bad_configuration_is_refused(fields):
    with pytest.raises(ValueError):
        CorrelationConfig(**fields)


def test_unknown_feature_is_refused():
    with pytest.raises(ValueError, match="unknown feature"):
        CorrelationConfig(feature="gray+sift")  # by the configuration, before any tracker
