"""Person re-identification embeddings (:mod:`tracking.detection.reid`) with Open Model Zoo's
person-reidentification-retail networks on real PETS09-S2L1 frames."""

from __future__ import annotations

import dataclasses
from collections import OrderedDict
from pathlib import Path

import numpy as np
import pytest

from tracking.datasets.mot import MotSequence, mot_to_image_boxes, read_mot_rows
from tracking.detection.cnn import CnnModelError
from tracking.detection.reid import ReidConfig, ReidEmbedder, cosine_similarity

DEFAULT_MODEL = "0287"  # the middle one: 0277 is stronger and slower, 0288 weaker and faster


def _model_path(shared_data: Path, number: str) -> Path:
    name = f"person-reidentification-retail-{number}"
    return shared_data / "models" / name / "FP16" / f"{name}.xml"


@pytest.fixture(scope="module")
def embedder(shared_data: Path) -> ReidEmbedder:
    return ReidEmbedder.from_file(_model_path(shared_data, DEFAULT_MODEL), ReidConfig(threads=2))


@pytest.fixture(scope="module")
def fast_embedder(shared_data: Path) -> ReidEmbedder:
    return ReidEmbedder.from_file(_model_path(shared_data, "0288"), ReidConfig(threads=2))


def _people(sequence: MotSequence, index: int) -> tuple[np.ndarray, np.ndarray]:
    """Ids and 0-based boxes of the ground truth of frame ``index`` (0-based). MotSequence.gt
    has the boxes only, so the ids are read from gt.txt (frame, id, x, y, w, h, ... 1-based)."""
    rows = read_mot_rows(sequence.path / "gt" / "gt.txt")
    rows = rows[rows[:, 0] == index + 1]
    return rows[:, 1].astype(int), mot_to_image_boxes(rows[:, 2:6])


def _boxes_of(wanted: np.ndarray, ids: np.ndarray, boxes: np.ndarray) -> np.ndarray:
    row = {int(person): k for k, person in enumerate(ids)}
    return boxes[[row[int(person)] for person in wanted]]


def test_the_same_person_is_the_closest_twenty_frames_later(shared_data, embedder):
    sequence = MotSequence.open(shared_data / "mot" / "PETS09-S2L1")
    first, later = 50, 70  # 0-based; the same 6 people are in both (72-114 px tall)
    ids_a, boxes_a = _people(sequence, first)
    ids_b, boxes_b = _people(sequence, later)
    common = np.intersect1d(ids_a, ids_b)[:6]
    assert len(common) == 6
    a = embedder.embed(sequence.read_frame(first), _boxes_of(common, ids_a, boxes_a))
    b = embedder.embed(sequence.read_frame(later), _boxes_of(common, ids_b, boxes_b))
    similarity = cosine_similarity(a, b)  # row i, column j: person common[i] then common[j]
    assert np.isfinite(similarity).all()
    matched = int((similarity.argmax(axis=1) == np.arange(6)).sum())
    # At least 5 of 6: 0287 ranks the right person first for 92.9 % of Market-1501's queries
    # (among 750 people, not 6), and it matched all 168 people of every 25th frame pair of
    # PETS09-S2L1 20 frames apart (0277: 166, 0288: 165); one miss is allowed for two people
    # dressed alike in the crowd, or occluding each other in one of the two frames. Chance
    # would give 1 of 6.
    assert matched >= 5, similarity
    # and on average a person is nearer to themselves than to the others
    same = np.diag(similarity).mean()
    other = similarity[~np.eye(6, dtype=bool)].mean()
    assert same > other + 0.1, (same, other)


def test_embeddings_are_unit_rows_and_nan_where_there_is_no_person_to_see(shared_data, embedder):
    sequence = MotSequence.open(shared_data / "mot" / "PETS09-S2L1")
    frame = sequence.read_frame(0)
    _, boxes = _people(sequence, 0)
    width = frame.shape[1]
    odd = np.array(
        [
            [width + 10.0, 20.0, 30.0, 80.0],  # outside the frame
            [100.0, 100.0, 3.0, 3.0],  # 3 px
            [-40.0, -40.0, 30.0, 30.0],  # above and left of the frame
            [np.nan, 10.0, 30.0, 80.0],  # not finite
        ]
    )
    out = embedder.embed(frame, np.concatenate([boxes, odd]))
    assert out.shape == (len(boxes) + 4, embedder.embedding_size)
    assert out.dtype == np.float32
    assert embedder.embedding_size == 256
    np.testing.assert_allclose(np.linalg.norm(out[: len(boxes)], axis=1), 1.0, atol=1e-5)
    assert np.isnan(out[len(boxes) :]).all()
    # a box partly outside is embedded from its part inside
    partly = embedder.embed(frame, np.array([[boxes[0, 0], -30.0, boxes[0, 2], boxes[0, 3] + 30]]))
    assert np.isfinite(partly).all()
    # greyscale: the grey repeated into three channels, the same person still alike
    grey = frame.mean(axis=2).astype(np.uint8)
    grey_out = embedder.embed(grey, boxes)
    np.testing.assert_allclose(np.linalg.norm(grey_out, axis=1), 1.0, atol=1e-5)
    assert (cosine_similarity(grey_out, out[: len(boxes)]).argmax(axis=1) == np.arange(3)).all()
    # no boxes
    assert embedder.embed(frame, np.zeros((0, 4))).shape == (0, 256)
    assert embedder.embed(frame, []).shape == (0, 256)
    with pytest.raises(ValueError, match="boxes"):
        embedder.embed(frame, np.zeros((2, 3)))
    with pytest.raises(TypeError, match="uint8"):
        embedder.embed(frame.astype(np.float32), boxes)


def _twenty_boxes(sequence: MotSequence) -> tuple[np.ndarray, np.ndarray]:
    frame = sequence.read_frame(50)
    _, boxes = _people(sequence, 50)
    shifts = np.array([[dx, dy, 0.0, 0.0] for dx in (-3, 0, 3, 6) for dy in (-2, 2)])
    many = np.concatenate([boxes + shift for shift in shifts])[:20]
    assert len(many) == 20
    return frame, many


@pytest.mark.parametrize("count", [20, 7, 5, 1])
def test_a_batch_beyond_max_batch_equals_one_box_at_a_time(shared_data, fast_embedder, count):
    """Several rounds of requests (20), a padded last request (7, 5), one crop."""
    sequence = MotSequence.open(shared_data / "mot" / "PETS09-S2L1")
    frame, boxes = _twenty_boxes(sequence)
    boxes = boxes[:count]
    assert fast_embedder.config.max_batch < 20  # several inferences
    together = fast_embedder.embed(frame, boxes)
    alone = np.concatenate([fast_embedder.embed(frame, box[None]) for box in boxes])
    agreement = np.einsum("kd,kd->k", together, alone)
    assert agreement.min() > 1 - 1e-3, agreement


def test_a_model_of_fixed_shape_is_fed_one_crop_at_a_time(shared_data, fast_embedder):
    sequence = MotSequence.open(shared_data / "mot" / "PETS09-S2L1")
    frame, boxes = _twenty_boxes(sequence)
    fixed = ReidEmbedder(dataclasses.replace(fast_embedder.network, reshapeable=False))
    agreement = np.einsum("kd,kd->k", fixed.embed(frame, boxes), fast_embedder.embed(frame, boxes))
    assert agreement.min() > 1 - 1e-3, agreement


def test_other_networks_and_broken_files_are_refused(shared_data, tmp_path):
    detector = shared_data / "models/person-detection-0200/FP16/person-detection-0200.xml"
    with pytest.raises(CnnModelError, match="re-identification"):
        ReidEmbedder.from_file(detector)
    pose = (
        shared_data / "models/human-pose-estimation-0001/FP16-INT8/human-pose-estimation-0001.xml"
    )
    with pytest.raises(CnnModelError, match="re-identification"):
        ReidEmbedder.from_file(pose)
    garbage = tmp_path / "garbage.xml"
    garbage.write_text("<net name='x'><layers><layer id='0'")
    garbage.with_suffix(".bin").write_bytes(b"\0" * 16)
    with pytest.raises(CnnModelError):
        ReidEmbedder.from_file(garbage)
    with pytest.raises(CnnModelError):
        ReidEmbedder.from_file(tmp_path / "missing.xml")


def test_cosine_similarity_is_nan_for_rows_without_an_embedding():
    a = np.array([[1.0, 0.0], [np.nan, np.nan], [0.6, 0.8]], dtype=np.float32)
    b = np.array([[0.0, 1.0], [1.0, 0.0]], dtype=np.float32)
    similarity = cosine_similarity(a, b)
    assert similarity.shape == (3, 2)
    np.testing.assert_allclose(similarity[[0, 2]], [[0.0, 1.0], [0.8, 0.6]], atol=1e-6)
    assert np.isnan(similarity[1]).all()
    both = cosine_similarity(a, a)
    assert np.isnan(both[1]).all() and np.isnan(both[:, 1]).all()
    assert cosine_similarity(np.zeros((0, 2)), b).shape == (0, 2)
    with pytest.raises(ValueError):
        cosine_similarity(a, np.zeros((2, 3)))


@pytest.mark.parametrize(
    "options", [{"max_batch": 0}, {"threads": -1}, {"min_box_side": 0.5}, {"max_batch": 2.0}]
)
def test_config_refuses_nonsense(options):
    with pytest.raises(ValueError):
        ReidConfig(**options)


def test_after_prepare_no_number_of_people_compiles_anything(shared_data, fast_embedder):
    """A live stream compiles every batch of crops up front: embedding 1 to 9 people then
    finds every shape compiled (each compile would have cost a tenth of a second or more)."""
    network = dataclasses.replace(fast_embedder.network, _compiled=OrderedDict())
    embedder = ReidEmbedder(network, fast_embedder.config)
    embedder.prepare()
    prepared = list(network._compiled)
    assert len(prepared) == embedder.config.max_batch
    frame, boxes = _twenty_boxes(MotSequence.open(shared_data / "mot" / "PETS09-S2L1"))
    for count in range(1, 10):
        embedder.embed(frame, boxes[:count])
    assert sorted(network._compiled) == sorted(prepared)


def test_no_input_is_refused_plainly(fast_embedder):
    with pytest.raises(ValueError, match="at least one input"):
        fast_embedder.network.infer_batches(np.zeros((0, 3, 256, 128), np.float32), 4)
