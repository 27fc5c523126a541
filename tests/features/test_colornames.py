"""Color Names (`tracking.features.colornames`): the §3.2.1 basis, the TSE model, w2c loading."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
import scipy.io

from tests.test_matfiles import V73_FILE
from tracking.features import colornames as cn
from tracking.features.colornames import (
    COLOR_NAMES,
    N_COLOR_BINS,
    ColorNamesError,
    ColorNameTable,
    load_w2c_table,
    tse_color_names,
    zero_sum_basis,
)


@pytest.fixture(scope="module")
def embedded() -> ColorNameTable:
    """One embedded-model table for the module (the table is computed once per instance)."""
    return ColorNameTable.embedded()


@pytest.fixture(scope="session")
def w2c_path(shared_data: Path) -> Path:
    return shared_data / "colornames" / "w2c.mat"


@pytest.fixture(scope="session")
def w2c(w2c_path: Path) -> np.ndarray:
    return load_w2c_table(w2c_path)


def _pixel(rgb: tuple[int, int, int]) -> np.ndarray:
    return np.array([[rgb]], dtype=np.uint8)


# --- the 10-dim orthonormal normalisation (thesis §3.2.1) --------------------------------------


@pytest.mark.parametrize("n", [2, 3, 11])
def test_zero_sum_basis_is_orthonormal_and_orthogonal_to_ones(n: int) -> None:
    basis = zero_sum_basis(n)
    assert basis.shape == (n, n - 1)
    np.testing.assert_allclose(basis.T @ basis, np.eye(n - 1), atol=1e-12)
    np.testing.assert_allclose(np.ones(n) @ basis, 0.0, atol=1e-12)


def test_zero_sum_basis_drops_only_the_constant_direction() -> None:
    # Any vector projected in and back out loses exactly its mean: B B^T p = p - mean(p).
    rng = np.random.default_rng(0)
    basis = zero_sum_basis(11)
    p = rng.dirichlet(np.ones(11), size=100)
    np.testing.assert_allclose(p @ basis @ basis.T, p - p.mean(axis=1, keepdims=True), atol=1e-12)


def test_table10_reconstructs_the_centred_probabilities(embedded: ColorNameTable) -> None:
    basis = zero_sum_basis(11)
    reconstructed = embedded.table10.astype(np.float64) @ basis.T
    np.testing.assert_allclose(reconstructed, embedded.probabilities - 1 / 11, atol=1e-6)


def test_feature_is_the_table10_row_of_each_pixel(embedded: ColorNameTable) -> None:
    # Known answer: row r//8 + 32 g//8 + 1024 b//8, computed by hand for a few pixels.
    image = np.array([[[0, 0, 0], [255, 255, 255]], [[17, 200, 99], [250, 3, 129]]], np.uint8)
    rows = [[0, 31 + 32 * 31 + 1024 * 31], [2 + 32 * 25 + 1024 * 12, 31 + 0 + 1024 * 16]]
    np.testing.assert_array_equal(ColorNameTable.bin_indices(image), rows)
    features = embedded(image)
    assert features.dtype == np.float32 and features.shape == (2, 2, 10)
    np.testing.assert_array_equal(features, embedded.table10[np.array(rows)])


def test_raw_probabilities_and_centred_cn_agree(embedded: ColorNameTable) -> None:
    # The 10 values are the centred 11 in another basis: mapping back gives p - 1/11, sum 0.
    image = np.random.default_rng(1).integers(0, 256, (20, 30, 3), dtype=np.uint8)
    raw = embedded.probabilities_at(image)
    assert raw.shape == (20, 30, 11) and raw.dtype == np.float32
    centred = embedded(image).astype(np.float64) @ zero_sum_basis(11).T
    np.testing.assert_allclose(centred.sum(axis=2), 0.0, atol=1e-6)
    np.testing.assert_allclose(centred + 1 / 11, raw, atol=1e-6)


# --- the embedded TSE model (Benavente et al. 2008) --------------------------------------------


@pytest.mark.parametrize("parameter_set", ["benavente2008", "parraga2009"])
def test_embedded_table_is_a_probability_table(parameter_set: cn.TseParameterSet) -> None:
    table = ColorNameTable.embedded(parameter_set).probabilities
    assert table.shape == (N_COLOR_BINS, 11)
    assert table.min() >= 0.0
    np.testing.assert_allclose(table.sum(axis=1), 1.0, atol=1e-12)


@pytest.mark.parametrize(
    ("rgb", "expected"),
    [
        # Secondary green and yellow sit well inside their categories.
        ((0, 255, 0), "green"),
        ((255, 255, 0), "yellow"),
        # Achromatic axis: the three lightness sigmoids split black / grey / white.
        ((0, 0, 0), "black"),
        ((128, 128, 128), "grey"),
        ((255, 255, 255), "white"),
        # Orange-ish: half-green red.
        ((255, 128, 0), "orange"),
        # A slightly darker primary red (L* 42-47) is red.
        ((200, 0, 0), "red"),
        ((220, 20, 20), "red"),
        # Royal and azure blues are blue.
        ((65, 105, 225), "blue"),
        ((0, 100, 255), "blue"),
        # Pink, purple and brown named by their CSS colours.
        ((255, 192, 203), "pink"),
        ((128, 0, 128), "purple"),
        ((139, 69, 19), "brown"),
        # The sRGB primaries themselves, pinned as the model names them: the TSE model is a
        # Munsell fit in CIELAB, where sRGB red (hue 40 deg, L* 53) lies past the level-4
        # red/orange boundary (about 33 deg) and sRGB blue falls on the purple side (CIELAB's
        # blue-purple hue bend). w2c.mat names them red and blue (see the test below).
        ((255, 0, 0), "orange"),
        ((0, 0, 255), "purple"),
    ],
)
def test_embedded_model_names_colours(
    embedded: ColorNameTable, rgb: tuple[int, int, int], expected: str
) -> None:
    name = COLOR_NAMES[int(embedded.probabilities_at(_pixel(rgb)).argmax())]
    assert name == expected, f"{rgb} named {name}"


@pytest.mark.parametrize(
    ("rgb", "expected"),
    [
        ((255, 0, 0), "red"),  # pure red
        ((0, 0, 255), "blue"),  # pure blue
        ((0, 255, 0), "green"),  # pure green
        ((0, 0, 0), "black"),  # black
        ((255, 255, 255), "white"),  # white
        ((128, 128, 128), "grey"),  # mid grey
        ((255, 255, 0), "yellow"),  # yellow
        ((255, 128, 0), "orange"),  # orange-ish
    ],
)
def test_w2c_table_names_pure_colours(
    w2c: np.ndarray, rgb: tuple[int, int, int], expected: str
) -> None:
    table = ColorNameTable(w2c, source="w2c")
    assert COLOR_NAMES[int(table.probabilities_at(_pixel(rgb)).argmax())] == expected


@pytest.mark.parametrize(
    ("parameter_set", "floor"),
    [
        # Measured 0.783 (shared/data README: 78 %). The floor leaves 3 points for sRGB -> Lab
        # constant choices, which move only bins on category boundaries, and is far above what a
        # wrong model gives: majority class 0.28, nearest RGB prototype 0.34, alpha_x and
        # alpha_y swapped 0.54.
        ("benavente2008", 0.75),
        # Measured 0.739: the 2009 re-fit agrees a little less with the Google-image names.
        ("parraga2009", 0.70),
    ],
)
def test_embedded_model_agrees_with_w2c(
    w2c: np.ndarray, parameter_set: cn.TseParameterSet, floor: float
) -> None:
    model = ColorNameTable.embedded(parameter_set).probabilities
    agreement = float(np.mean(model.argmax(axis=1) == w2c.argmax(axis=1)))
    assert agreement >= floor


def test_embedded_constants_match_the_published_parameters(shared_data: Path) -> None:
    # The constants were transcribed from tse_params.json; every number must match it.
    params = json.loads((shared_data / "colornames" / "tse_params.json").read_text())
    assert tuple(float(t) for t in params["lightness_thresholds"]) == cn._TSE_L_THRESHOLDS
    achromatic = params["achromatic"]
    assert (achromatic["black_grey"]["t"], achromatic["black_grey"]["beta"]) == cn._TSE_BLACK_GREY
    assert (achromatic["grey_white"]["t"], achromatic["grey_white"]["beta"]) == cn._TSE_GREY_WHITE
    assert set(cn._TSE_SETS) == set(params["sets"])
    for set_name, published in params["sets"].items():
        levels = cn._TSE_SETS[set_name]
        assert len(levels) == len(published["levels"])
        for level, expected in zip(levels, published["levels"], strict=True):
            shared = expected["shared"]
            assert level[:6] == tuple(shared[k] for k in ("tx", "ty", "beta_e", "ex", "ey", "phi"))
            categories = {c.name: c[1:] for c in level.categories}
            assert categories == {
                name: (p["alpha_x"], p["alpha_y"], p["beta_x"], p["beta_y"])
                for name, p in expected["categories"].items()
            }


def test_tse_color_names_rejects_unknown_parameter_set() -> None:
    with pytest.raises(ValueError, match="benavente2008"):
        tse_color_names(np.zeros((1, 3)), "nonsense")  # type: ignore[arg-type]
    with pytest.raises(ValueError, match="benavente2008"):
        ColorNameTable.embedded("nonsense")  # type: ignore[arg-type]


def test_tables_are_computed_once_per_instance_and_read_only() -> None:
    calls = []

    def produce() -> np.ndarray:
        calls.append(1)
        return np.full((N_COLOR_BINS, 11), 1 / 11)

    table = ColorNameTable(produce, source="counting")
    assert calls == []  # lazy: nothing computed at construction
    assert table.table10 is table.table10
    table.probabilities_at(_pixel((1, 2, 3)))
    assert calls == [1]
    with pytest.raises(ValueError, match="read-only"):
        table.table10[0, 0] = 1.0
    # Separate instances own separate tables (no module-level cache).
    assert ColorNameTable.embedded().table10 is not ColorNameTable.embedded().table10


# --- loading w2c.mat ---------------------------------------------------------------------------


def test_load_w2c_reads_the_real_table(w2c: np.ndarray, w2c_path: Path) -> None:
    assert w2c.shape == (N_COLOR_BINS, 11) and w2c.dtype == np.float64
    np.testing.assert_allclose(w2c.sum(axis=1), 1.0, atol=1e-9)
    table = ColorNameTable.from_w2c(w2c_path)
    np.testing.assert_array_equal(table.probabilities, w2c)
    assert table.source.startswith("w2c:")


def test_from_config_uses_the_embedded_model_without_a_path(w2c_path: Path) -> None:
    assert ColorNameTable.from_config(None).source == "tse:benavente2008"
    assert ColorNameTable.from_config(w2c_path).source == f"w2c:{w2c_path}"


def _v73_file(tmp_path: Path) -> Path:
    path = tmp_path / "w2c.mat"
    path.write_bytes(V73_FILE)
    return path


def _text_file_named_mat(tmp_path: Path) -> Path:
    path = tmp_path / "w2c.mat"
    path.write_text("this is not a MATLAB file\n" * 20)
    return path


def _mat_without_w2c(tmp_path: Path) -> Path:
    path = tmp_path / "other.mat"
    scipy.io.savemat(path, {"table": np.ones((4, 11))})
    return path


def _mat_wrong_shape(tmp_path: Path) -> Path:
    path = tmp_path / "short.mat"
    scipy.io.savemat(path, {"w2c": np.full((1000, 11), 1 / 11)})
    return path


def _mat_rows_not_summing_to_one(tmp_path: Path) -> Path:
    path = tmp_path / "unnormalised.mat"
    table = np.full((N_COLOR_BINS, 11), 1 / 11)
    table[5] *= 2
    scipy.io.savemat(path, {"w2c": table})
    return path


def _mat_text_w2c(tmp_path: Path) -> Path:
    path = tmp_path / "text.mat"
    scipy.io.savemat(path, {"w2c": np.array(["not numbers"])})
    return path


@pytest.mark.parametrize(
    ("make_file", "message"),
    [
        # No file at all.
        (lambda tmp: tmp / "missing.mat", "does not exist"),
        # A text file with a .mat name: scipy cannot parse it.
        (_text_file_named_mat, "not a readable MATLAB v5/v7 file"),
        # MATLAB's -v7.3 format: say how to save it again.
        (_v73_file, "save -v7"),
        # A valid .mat file that holds something else.
        (_mat_without_w2c, r"no variable 'w2c'; found \['table'\]"),
        # The right variable with the wrong number of bins.
        (_mat_wrong_shape, r"expected shape \(32768, 11\) .* got \(1000, 11\)"),
        # Rows that are not probability distributions.
        (_mat_rows_not_summing_to_one, "expected every row to sum to 1 .* row 5 sums to 2"),
        # Not numbers at all.
        (_mat_text_w2c, "expected a numeric"),
    ],
)
def test_load_w2c_rejects_bad_files(tmp_path: Path, make_file, message: str) -> None:
    path = make_file(tmp_path)
    with pytest.raises(ColorNamesError, match=message):
        load_w2c_table(path)
    with pytest.raises(ValueError):  # ColorNamesError is a ValueError
        ColorNameTable.from_w2c(path)
