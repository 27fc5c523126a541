"""The CNN person detectors on OpenVINO: decoders on known outputs, every model of
``../shared/data/models`` on real PETS09-S2L1 and TUD-Stadtmitte frames, regions of interest in
batches, greyscale and 4K frames, and model files that are not models."""

from __future__ import annotations

import shutil
from pathlib import Path

import cv2
import numpy as np
import pytest

from tracking.datasets.mot import MotSequence
from tracking.detection import make_detector
from tracking.detection.cnn import CnnConfig, CnnDetector, CnnModelError
from tracking.detection.cnn.decoders import decode_ssd, decode_yolox, yolox_grid
from tracking.detection.nms import box_iou
from tracking.types import Box

DETECTORS = {
    "person-detection-0202": "person-detection-0202/FP16/person-detection-0202.xml",
    "person-detection-0200": "person-detection-0200/FP16/person-detection-0200.xml",
    "person-detection-retail-0013": "person-detection-retail-0013/FP16/"
    "person-detection-retail-0013.xml",
    "yolox-nano": "yolox-nano/yolox_nano.onnx",
}
# Frames with 19 ground-truth people each way, over the sequences' course (0-based).
FRAMES = {"PETS09-S2L1": (0, 100, 200, 400), "TUD-Stadtmitte": (0, 60, 120)}


@pytest.fixture(scope="module")
def models(shared_data: Path) -> Path:
    return shared_data / "models"


@pytest.fixture(scope="module", params=sorted(DETECTORS))
def detector(request, models: Path) -> CnnDetector:
    return CnnDetector.from_file(models / DETECTORS[request.param], CnnConfig(threads=1))


@pytest.fixture(scope="module")
def default_cnn(models: Path) -> CnnDetector:
    return CnnDetector.from_file(models / DETECTORS["person-detection-0202"], CnnConfig(threads=1))


def _found(boxes: np.ndarray, people: np.ndarray) -> np.ndarray:
    """Which ground-truth people a box overlaps with IoU >= 0.5."""
    if len(boxes) == 0:
        return np.zeros(len(people), dtype=bool)
    return box_iou(people, boxes).max(axis=1) >= 0.5


# -- decoders --------------------------------------------------------------------------------


def test_ssd_rows_end_at_the_first_negative_image_id():
    rows = np.array(
        [
            [0, 1, 0.9, 0.1, 0.2, 0.3, 0.6],
            [1, 1, 0.8, 0.5, 0.5, 0.7, 0.9],
            [0, 2, 0.7, 0.0, 0.0, 0.1, 0.1],  # another class
            [-1, 0, 0, 0, 0, 0, 0],  # the end: padding follows
            [0, 1, 0.99, 0.4, 0.4, 0.5, 0.5],
        ]
    ).reshape(1, 1, -1, 7)
    (corners0, conf0), (_, conf1) = decode_ssd(rows, batch=2)
    assert np.allclose(conf0, [0.9, 0.7]) and np.allclose(conf1, [0.8])
    assert np.allclose(corners0[0], [0.1, 0.2, 0.3, 0.6])
    (only, conf), _ = decode_ssd(rows, batch=2, label=1)
    assert np.allclose(conf, [0.9]) and only.shape == (1, 4)


def test_yolox_head_decodes_cells_strides_and_scores():
    size = (64, 32)  # width, height: 8x4 + 4x2 + 2x1 cells
    grid, strides = yolox_grid(size)
    assert grid.shape == (42, 2) and strides[:32].ravel().tolist() == [8.0] * 32
    head = np.zeros((1, 42, 5 + 3))
    # cell (column 3, row 1) of stride 8: index 1 * 8 + 3
    head[0, 11] = [0.5, 0.25, np.log(2.0), np.log(4.0), 0.9, 0.5, 0.1, 0.0]
    # the first cell of stride 32 (index 32 + 8): the network's box of class 1
    head[0, 40] = [0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.8, 0.0]
    ((corners, confidence),) = decode_yolox(head, size, class_id=0)
    centre = ((3 + 0.5) * 8, (1 + 0.25) * 8)
    assert np.allclose(corners[11], [centre[0] - 8, centre[1] - 16, centre[0] + 8, centre[1] + 16])
    assert confidence[11] == pytest.approx(0.45) and confidence[40] == 0.0
    ((_, person_of_class_1),) = decode_yolox(head, size, class_id=1)
    assert person_of_class_1[40] == pytest.approx(0.8)
    with pytest.raises(ValueError, match="has 42 cells"):
        decode_yolox(head[:, :41], size)


# -- real models on real frames ------------------------------------------------------------


@pytest.mark.slow
@pytest.mark.parametrize("sequence", sorted(FRAMES))
def test_each_model_finds_the_people(detector, shared_data, sequence):
    """Recall at IoU 0.5 over 19 people of each sequence. The models' AP on these sequences is
    0.85-0.92 (``../shared/data/models/README.md``), so 0.8 leaves a weak model its misses on a
    few frames while a broken decoder, input order or scaling (which finds next to nobody, or
    boxes off by the input's scale) fails; and at most two boxes per person at the default
    threshold."""
    seq = MotSequence.open(shared_data / "mot" / sequence)
    found = people = boxes = 0
    for index in FRAMES[sequence]:
        detections = detector.detect(seq.read_frame(index))
        found += _found(detections.boxes, seq.gt[index]).sum()
        people += len(seq.gt[index])
        boxes += len(detections)
        assert np.all((detections.probabilities >= 0) & (detections.probabilities <= 1))
        assert np.all(np.diff(detections.scores) <= 0)  # best first, as suppression keeps them
    assert found / people >= 0.8, f"{detector.model_name}: {found} of {people} people"
    assert boxes <= 2 * people


@pytest.mark.slow
def test_regions_are_searched_in_one_batch_and_keep_their_people(default_cnn, pets):
    frame = pets.read_frame(100)
    people = pets.gt[100]
    regions = [
        (Box(x - 0.25 * h, y - 0.25 * h, w + 0.5 * h, 1.5 * h), (0.7 * h, 1.4 * h))
        for x, y, w, h in people
    ]
    found = default_cnn.detect_regions(frame, regions)
    assert len(found) == len(regions)
    hits = 0
    for (region, heights), detections, person in zip(regions, found, people, strict=True):
        centres = detections.boxes[:, :2] + detections.boxes[:, 2:] / 2
        assert np.all((centres[:, 0] >= region.x) & (centres[:, 0] <= region.x + region.w))
        assert np.all(
            (detections.boxes[:, 3] >= heights[0]) & (detections.boxes[:, 3] <= heights[1])
        )
        hits += int(_found(detections.boxes, person[None]).any())
    assert hits >= len(people) - 1
    # one region alone gives what it gives in the batch (the same crop and input)
    alone = default_cnn.detect_region(frame, *regions[0])
    assert np.allclose(alone.boxes, found[0].boxes, atol=1.0)
    # more regions than one inference takes, and a region outside the frame
    many = default_cnn.detect_regions(frame, regions * 4 + [(Box(-50, -50, 20, 20), None)])
    assert len(many) == 4 * len(regions) + 1 and len(many[-1]) == 0


@pytest.mark.slow
def test_greyscale_and_4k_frames(default_cnn, pets):
    frame = pets.read_frame(100)
    people = pets.gt[100]
    grey = cv2.cvtColor(frame, cv2.COLOR_RGB2GRAY)
    assert _found(default_cnn.detect(grey).boxes, people).sum() >= len(people) - 1
    # the same frame at 5x (3840x2880): searched at 1080 px high, boxes in the 4K frame's pixels
    big = cv2.resize(frame, None, fx=5, fy=5, interpolation=cv2.INTER_LINEAR)
    assert default_cnn.config.input_for(big.shape) == (1440, 1088)
    assert _found(default_cnn.detect(big).boxes, people * 5).sum() >= len(people) - 1


def test_input_follows_the_frame_within_bounds():
    config = CnnConfig()
    assert config.input_for((576, 768, 3)) == (768, 576)  # as it is
    assert config.input_for((360, 480, 3)) == (768, 576)  # enlarged 1.6x to 576 px high
    assert config.input_for((1280, 720, 3)) == (736, 1280)  # portrait: by its shorter side
    assert config.input_for((2160, 3840, 3)) == (1920, 1088)  # halved
    assert CnnConfig(upscale=2.0).input_for((100, 200, 3)) == (416, 192)
    assert CnnConfig(input_size=(512, 512)).input_for((576, 768, 3)) == (512, 512)


# -- files that are not models ------------------------------------------------------------


def test_bad_model_files_are_refused_with_a_reason(models, tmp_path):
    xml = models / DETECTORS["person-detection-0202"]
    with pytest.raises(CnnModelError, match="cannot read"):
        CnnDetector.from_file(tmp_path / "missing.xml")
    with pytest.raises(CnnModelError, match="not a CNN model file"):
        CnnDetector.from_file(models.parent / "mot" / "PETS09-S2L1" / "det" / "det.txt")
    alone = tmp_path / "alone" / xml.name
    alone.parent.mkdir()
    shutil.copy(xml, alone)
    with pytest.raises(CnnModelError, match="no weights file"):
        CnnDetector.from_file(alone)
    garbage = tmp_path / "garbage.xml"
    garbage.write_text("<net>not a network")
    garbage.with_suffix(".bin").write_bytes(b"\0" * 64)
    with pytest.raises(CnnModelError, match="not a model OpenVINO can read"):
        CnnDetector.from_file(garbage)
    truncated = tmp_path / "truncated" / xml.name
    truncated.parent.mkdir()
    shutil.copy(xml, truncated)
    weights = xml.with_suffix(".bin").read_bytes()
    truncated.with_suffix(".bin").write_bytes(weights[: len(weights) // 2])
    with pytest.raises(CnnModelError, match=r"truncated|cannot read|does not compile|can read"):
        CnnDetector.from_file(truncated)
    onnx = tmp_path / "broken.onnx"
    onnx.write_bytes((models / DETECTORS["yolox-nano"]).read_bytes()[:100_000])
    with pytest.raises(CnnModelError):
        CnnDetector.from_file(onnx)


def test_a_network_that_is_no_detector_is_refused(models):
    reid = (
        models / "person-reidentification-retail-0288/FP16/person-reidentification-retail-0288.xml"
    )
    with pytest.raises(CnnModelError, match="not an SSD detection output"):
        CnnDetector.from_file(reid)


def test_the_factory_builds_the_cnn(models):
    path = models / DETECTORS["person-detection-0200"]
    by_name = make_detector("cnn", model=path)
    by_path = make_detector(path, CnnConfig(threshold=0.5))
    assert isinstance(by_name, CnnDetector) and by_path.config.threshold == 0.5
    assert by_name.network is by_path.network  # read once per process
    with pytest.raises(ValueError, match="needs its network"):
        make_detector("cnn")
    with pytest.raises(ValueError, match="takes a CnnConfig"):
        make_detector(path, config=object())  # type: ignore[arg-type]
