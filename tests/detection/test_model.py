"""Loading voc-release5 model files, and the errors for files that are not such models."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import scipy.io

from tests.test_matfiles import V73_FILE
from tracking.detection.dpm.model import ModelFileError, flip_filter, load_dpm_model


def test_inria_model_structure(inria_model):
    m = inria_model
    assert m.name == "inriaperson"
    assert (m.sbin, m.interval, m.max_size, m.extra_octave) == (8, 10, (15, 5), True)
    assert m.threshold == pytest.approx(-0.1259, abs=1e-4)
    assert len(m.components) == 2
    original, mirrored = m.components
    assert not original.mirrored and mirrored.mirrored
    assert original.root.weights.shape == (15, 5, 32)
    assert original.window == (15, 5)
    assert len(original.parts) == 8
    assert all(p.weights.shape == (6, 6, 32) and p.anchor[2] == 1 for p in original.parts)
    # mirrored component: flipped filters, mirrored anchors, b_x negated
    np.testing.assert_array_equal(mirrored.root.weights, flip_filter(original.root.weights))
    for a, b in zip(original.parts, mirrored.parts, strict=True):
        np.testing.assert_array_equal(b.weights, flip_filter(a.weights))
        assert b.anchor[0] == 2 * 5 - 6 - a.anchor[0] and b.anchor[1] == a.anchor[1]
        np.testing.assert_allclose(b.deformation, a.deformation * [1, -1, 1, 1])
    # the root does not move: deformation weights 1000
    np.testing.assert_array_equal(original.root.deformation, [1000, 0, 1000, 0])
    assert original.bias == pytest.approx(-0.66595 * 10, abs=1e-3)  # offset x features.bias
    assert original.bbox_regression.shape == (4, 19)


def test_voc2007_person_model_has_three_mirrored_components(voc_path):
    m = load_dpm_model(voc_path)
    assert len(m.components) == 6
    assert [c.window for c in m.components] == [(8, 7), (8, 7), (11, 6), (11, 6), (11, 4), (11, 4)]
    assert [c.mirrored for c in m.components] == [False, True] * 3
    assert not m.extra_octave and m.max_size == (11, 7)


def test_flip_filter_is_an_involution():
    rng = np.random.default_rng(0)
    w = rng.normal(size=(4, 3, 32)).astype(np.float32)
    np.testing.assert_array_equal(flip_filter(flip_filter(w)), w)


def _save_model(path: Path, **fields) -> Path:
    scipy.io.savemat(path, {"model": fields})
    return path


def _write(path: Path, data: bytes) -> Path:
    path.write_bytes(data)
    return path


@pytest.mark.parametrize(
    ("make", "message"),
    [
        # no such file
        (lambda p: p / "missing.mat", "not found"),
        # random bytes with a .mat name
        (lambda p: _write(p / "junk.mat", b"\x00garbage" * 64), "MATLAB"),
        # a text file
        (lambda p: _write(p / "t.mat", b"hello"), "MATLAB"),
        # a MATLAB file without a variable called model
        (lambda p: scipy.io.savemat(p / "w.mat", {"w2c": np.zeros(3)}) or p / "w.mat", "model"),
        # a model struct without rules, filters, blocks...
        (lambda p: _save_model(p / "m.mat", sbin=8, interval=10), "field"),
        # MATLAB's -v7.3 format (HDF5 behind a 512-byte MATLAB header): say how to re-save it
        (lambda p: _write(p / "v73.mat", V73_FILE), "-v7"),
    ],
)
def test_files_that_are_not_models_raise_model_file_error(tmp_path, make, message):
    path = make(tmp_path)
    with pytest.raises(ModelFileError, match=message):
        load_dpm_model(path)


def test_truncated_model_file_raises_model_file_error(tmp_path, inria_path):
    data = inria_path.read_bytes()
    cut = tmp_path / "cut.mat"
    cut.write_bytes(data[: len(data) // 3])
    with pytest.raises(ModelFileError):
        load_dpm_model(cut)


def test_model_file_error_is_a_value_error():
    assert issubclass(ModelFileError, ValueError)
