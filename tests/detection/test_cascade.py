"""The star cascade: exact when it prunes nothing, admissible for its positives, and its files."""

from __future__ import annotations

import json
import math
import subprocess
import sys

import cv2
import numpy as np
import pytest

from devtools.cascade_fit import main as fit_main
from devtools.cascade_fit import record_positive, thresholds_for
from tracking.datasets.otb import load_otb_sequence, read_frame
from tracking.detection.dpm import cascade as cascade_module
from tracking.detection.dpm import kernels as dpm_kernels
from tracking.detection.dpm.cascade import (
    CascadeThresholds,
    cascade_level,
    cascade_level_roots,
    load_cascade,
    pca_projection,
    select_thresholds,
)
from tracking.detection.dpm.detector import DpmConfig, DpmDetector
from tracking.detection.dpm.kernels import kernel_filters
from tracking.detection.dpm.model import load_dpm_model
from tracking.detection.dpm.pyramid import level_features, pyramid_levels
from tracking.detection.dpm.scoring import LevelRoots, score_level
from tracking.evaluation.detection import match_frame
from tracking.types import Box


@pytest.fixture(scope="module")
def exact(inria_model) -> DpmDetector:
    return DpmDetector(inria_model, DpmConfig(cascade=False))


def test_pca_basis_is_orthonormal_and_keeps_most_filter_energy(inria_model):
    projection = pca_projection(inria_model, dims=6)
    basis = projection.basis.astype(np.float64)
    np.testing.assert_allclose(basis.T @ basis, np.eye(6), atol=1e-5)
    cells = np.concatenate([s.weights.reshape(-1, 32) for s in inria_model.components[0].symbols])
    kept = np.linalg.norm(cells @ basis) ** 2 / np.linalg.norm(cells) ** 2
    assert kept > 0.5  # 6 of 32 directions hold most of the filters' energy


def test_projection_projects_every_cell_on_the_basis(inria_model, pets_frame):
    projection = pca_projection(inria_model, dims=6)
    levels = pyramid_levels((200, 300), 8, 10, extra_octave=True)
    features = level_features(pets_frame[:200, :300], levels[:1], (5, 5))
    (maps,) = features.values()
    projected = projection.project(maps)
    assert projected.shape == (*maps.shape[:2], 6) and projected.dtype == np.float32
    expected = maps.astype(np.float64) @ projection.basis.astype(np.float64)
    np.testing.assert_allclose(projected, expected, rtol=1e-4, atol=1e-5)
    # a view (as a crop of a map) projects as its copy
    view = maps[3:20, 5:40]
    np.testing.assert_array_equal(projection.project(view), projection.project(view.copy()))


def test_without_pruning_the_cascade_equals_exact_scoring(exact, inria_model, pets_frame):
    crop = pets_frame[150:420, 180:420]  # two people
    projection = pca_projection(inria_model)
    threshold = -2.0
    compared = 0
    for root, needed in exact.search_levels(crop.shape)[::4]:
        features = level_features(crop, needed, exact.pad)
        projected = {k: projection.project(v) for k, v in features.items()}
        reference = score_level(inria_model, features, root, exact.pad, window=4)
        result = cascade_level(
            inria_model, features, projected, projection, root, exact.pad,
            CascadeThresholds.exact(inria_model.num_parts), threshold,
        )  # fmt: skip
        assert result is not None and reference is not None
        got = result[0]
        above = reference.component_scores > threshold
        np.testing.assert_array_equal(np.isfinite(got.component_scores), above)
        np.testing.assert_allclose(
            got.component_scores[above], reference.component_scores[above], atol=1e-4
        )
        where = np.broadcast_to(above[:, None, :, :, None], got.placements.shape)
        np.testing.assert_array_equal(got.placements[where], reference.placements[where])
        compared += int(above.sum())
    assert compared > 20


def test_level_roots_are_the_dense_scores_roots(inria_model, pets_frame):
    # Detection keeps only the roots the cascade finds (cascade_level_roots); they must be
    # the roots above the threshold of the dense LevelScores, with the same components,
    # scores and placements of every symbol.
    detector = DpmDetector(inria_model, DpmConfig(threshold=-1.2))
    thresholds, projection = detector._cascade
    crop = pets_frame[100:460, 120:520]
    compared = 0
    for root, needed in detector.search_levels(crop.shape)[::3]:
        features = level_features(crop, needed, detector.pad)
        projected = {k: projection.project(v) for k, v in features.items()}
        args = (inria_model, features, projected, projection, root, detector.pad, thresholds)
        dense, _ = cascade_level(*args, detector.threshold)
        roots = cascade_level_roots(*args, detector.threshold)
        expected = dense.roots(detector.threshold)
        order = np.lexsort((roots.cols, roots.rows))
        for name in ("rows", "cols", "scores", "components", "placements"):
            np.testing.assert_array_equal(getattr(roots, name)[order], getattr(expected, name))
        compared += roots.rows.size
    assert compared > 20


def test_level_roots_keep_the_best_component_ties_to_the_first():
    level = pyramid_levels((200, 300), 8, 10, extra_octave=True)[10]
    placements = np.arange(4 * 2 * 2).reshape(4, 2, 2)
    roots = LevelRoots.of_mixture(
        level, (0, 0),
        rows=np.array([3, 3, 5, 5]), cols=np.array([1, 1, 2, 2]),
        scores=np.array([0.5, 0.7, 0.2, 0.2]), components=np.array([0, 1, 1, 0]),
        placements=placements,
    )  # fmt: skip
    assert roots.rows.tolist() == [3, 5] and roots.cols.tolist() == [1, 2]
    assert roots.scores.tolist() == [0.7, 0.2]
    assert roots.components.tolist() == [1, 0]  # the better; on a tie, the first component
    np.testing.assert_array_equal(roots.placements, placements[[1, 3]])


def test_cascade_caches_each_part_response_once_in_aligned_blocks(
    inria_model, pets_frame, monkeypatch
):
    # A missing part response is computed with the rest of its aligned block of four columns:
    # blocks are cached whole or not at all (so none is computed twice), and every cached
    # value is the filter response at its placement. The kernel's cache arrays are observed
    # by wrapping the real kernel.
    calls = []

    def observed(*args):
        calls.append(args)
        return dpm_kernels.cascade_roots(*args)

    monkeypatch.setattr(cascade_module, "cascade_roots", observed)
    detector = DpmDetector(inria_model, DpmConfig(threshold=-1.126))
    assert detector.cascade is not None
    crop = pets_frame[150:420, 180:420]  # two people
    projection = pca_projection(inria_model)
    for root, needed in detector.search_levels(crop.shape)[::6]:
        features = level_features(crop, needed, detector.pad)
        projected = {k: projection.project(v) for k, v in features.items()}
        cascade_level(
            inria_model, features, projected, projection, root, detector.pad,
            detector.cascade, -1.126,
        )  # fmt: skip
    assert calls
    rng = np.random.default_rng(0)
    checked = 0
    for args in calls:
        maps, filters, channels, cache, done = args[5:7], args[7:9], args[9:11], *args[18:20]
        for stage in range(2):
            flat_map, n = maps[stage], channels[stage]
            h, row_length = filters[stage].shape[1:]
            width = (flat_map.shape[1] - row_length) // n  # last placement column
            whole = (width + 1) // 4 * 4  # columns of the blocks computed whole
            blocks = done[stage, :, :, :whole].reshape(*done.shape[1:3], -1, 4)
            assert np.all(blocks.all(axis=-1) | ~blocks.any(axis=-1))
            parts, rows, cols = np.nonzero(done[stage])
            for i in rng.choice(len(parts), size=min(len(parts), 20), replace=False):
                p, r, c = parts[i], rows[i], cols[i]
                window = flat_map[r : r + h, c * n : c * n + row_length]
                expected = float(np.sum(window.astype(np.float64) * filters[stage][p]))
                assert cache[stage, p, r, c] == pytest.approx(expected, abs=1e-4)
                checked += 1
    assert checked > 100


@pytest.mark.parametrize(
    ("level", "rows", "cols", "threshold"),
    [(6, (3, 17), (5, 14), -math.inf), (6, None, None, -math.inf), (10, None, None, -3.0)],
)
def test_exact_kernel_equals_exact_scoring(
    exact, inria_model, pets_frame, level, rows, cols, threshold
):
    # what regions of interest (a rectangle) and cascade=False (whole levels) use: every root
    # scored densely, no approximate stage
    crop = pets_frame[150:420, 180:420]
    root, needed = exact.search_levels(crop.shape)[level]
    features = level_features(crop, needed, exact.pad)
    reference = score_level(inria_model, features, root, exact.pad, rows, cols, window=4)
    result = cascade_level(
        inria_model, features, None, None, root, exact.pad,
        CascadeThresholds.exact(inria_model.num_parts), threshold, rows=rows, cols=cols,
    )  # fmt: skip
    assert result is not None and reference is not None
    got = result[0]
    assert got.origin == reference.origin
    above = reference.component_scores > threshold
    np.testing.assert_array_equal(np.isfinite(got.component_scores), above)
    np.testing.assert_allclose(
        got.component_scores[above], reference.component_scores[above], atol=1e-4
    )
    assert above.sum() > 20 and (~above).sum() > 20  # border roots whose parts fall off
    where = np.broadcast_to(above[:, None, :, :, None], got.placements.shape)
    np.testing.assert_array_equal(got.placements[where], reference.placements[where])
    assert np.all(got.placements[~np.broadcast_to(above[:, None], got.placements.shape[:4])] == -1)


def test_cascade_refuses_filters_without_the_projected_parts(exact, inria_model, pets_frame):
    crop = pets_frame[150:420, 180:420]
    root, needed = exact.search_levels(crop.shape)[6]
    features = level_features(crop, needed, exact.pad)
    projection = pca_projection(inria_model)
    projected = {k: projection.project(v) for k, v in features.items()}
    plain = kernel_filters(inria_model, exact.pad)  # as for exact scoring: no projection
    with pytest.raises(ValueError, match="projected parts"):
        cascade_level(
            inria_model, features, projected, projection, root, exact.pad,
            CascadeThresholds.exact(inria_model.num_parts), -2.0, filters=plain,
        )  # fmt: skip


@pytest.mark.slow
def test_cascade_keeps_the_exact_detections_of_pets_frames(inria_model, exact, pets):
    cascade = DpmDetector(inria_model, DpmConfig())
    assert cascade.cascade is not None
    kept = total = 0
    for i in (0, 200, 400, 600):
        frame = pets.read_frame(i)
        kept, total = _count_kept(exact.detect(frame), cascade.detect(frame), kept, total)
    assert total >= 15
    assert kept / total >= 0.9, f"the cascade kept {kept} of {total} detections"


def _count_kept(reference, found, kept: int, total: int) -> tuple[int, int]:
    """``kept`` and ``total`` plus the exact detections ``found`` keeps and those there are;
    the boxes it keeps must carry their exact scores."""
    for box, score in zip(found.boxes, found.scores, strict=True):
        same = np.all(np.abs(reference.boxes - box) < 1e-6, axis=1)
        if same.any():
            assert reference.scores[same][0] == pytest.approx(score, abs=1e-4)
    matched = match_frame(found.boxes, found.scores, reference.boxes)
    return kept + int(matched.sum()), total + len(reference)


def test_regions_keep_the_exact_detections_of_their_people(inria_model, pets):
    # Regions of interest are pruned by the cascade too (the tracker searches them between
    # full searches, at the threshold of DPM_TRACKING_CONFIG); dense scores stay exact.
    exact = DpmDetector(inria_model, DpmConfig(threshold=-0.7, cascade=False))
    cascade = DpmDetector(inria_model, DpmConfig(threshold=-0.7))
    kept = total = 0
    for i in (0, 200, 400):
        frame = pets.read_frame(i)
        for x, y, w, h in pets.gt[i]:
            region = Box(x - h / 2, y - h / 2, w + h, 2 * h)
            heights = (0.8 * h, 1.25 * h)
            reference = exact.detect_region(frame, region, heights)
            found = cascade.detect_region(frame, region, heights)
            kept, total = _count_kept(reference, found, kept, total)
    assert total >= 10
    assert kept / total >= 0.9, f"the cascade kept {kept} of {total} detections"


def _crossing_positives(shared_data, count):
    sequence = load_otb_sequence(shared_data / "otb" / "Crossing")
    for index in range(0, count * 30, 30):
        image = read_frame(sequence.frame_paths[index])
        x, y, w, h = sequence.ground_truth[index]
        # the person is ~50 px tall: enlarge 2.5x so that the model's windows fit
        y0, x0 = max(0, int(y - h / 2)), max(0, int(x - w))
        crop = image[y0 : int(y + 1.5 * h), x0 : int(x + 2 * w)]
        crop = cv2.resize(crop, None, fx=2.5, fy=2.5, interpolation=cv2.INTER_LINEAR)
        yield crop, ((x - x0) * 2.5, (y - y0) * 2.5, w * 2.5, h * 2.5)


def test_fitted_thresholds_admit_their_positives(inria_model, shared_data):
    detector = DpmDetector(inria_model, DpmConfig(cascade=False))
    positives = list(_crossing_positives(shared_data, 3))
    records = [record_positive(detector, crop, box) for crop, box in positives]
    assert all(r is not None for r in records)
    for score, stages, margins in records:
        assert stages[-1] == pytest.approx(score, abs=1e-4)  # the last stage is the exact score
        assert np.all(np.isfinite(stages))
        parts = inria_model.num_parts
        assert np.isnan(margins[0]) and np.isnan(margins[1 + parts])  # root stages: no margin
        # a part's margin is the partial score before it minus a non-negative deformation cost
        assert np.all(margins[1 : 1 + parts] <= stages[:parts] + 1e-9)
    low = min(r[0] for r in records) - 0.01
    thresholds = thresholds_for(records, low)
    assert thresholds is not None
    pruned = DpmDetector(inria_model, DpmConfig(threshold=low))
    projection = pca_projection(inria_model)
    pruned._cascade = (thresholds, projection)
    pruned._filters = kernel_filters(inria_model, pruned.pad, projection)
    for (crop, _), (score, _, _) in zip(positives, records, strict=True):
        found = pruned.detect(crop)
        assert len(found) and found.scores.max() >= score - 1e-4
    assert thresholds_for(records, max(r[0] for r in records)) is None


def test_select_thresholds_takes_the_highest_fit_not_above_the_threshold():
    table = [CascadeThresholds(t, np.zeros(4), np.zeros(4)) for t in (-1.0, -0.5, 0.0)]
    assert select_thresholds(table, -0.7).score_threshold == -1.0
    assert select_thresholds(table, 0.3).score_threshold == 0.0
    assert select_thresholds(table, -0.5).score_threshold == -0.5
    assert select_thresholds(table, -1.5) is None


def test_shipped_thresholds_load_for_the_inria_model(inria_model):
    detector = DpmDetector(inria_model, DpmConfig())
    assert detector.cascade is not None
    assert detector.cascade.score_threshold <= detector.threshold
    assert detector.cascade.stage.shape == (2 + 2 * inria_model.num_parts,)
    # below the lowest fitted threshold, or with the cascade off: exact scoring
    assert DpmDetector(inria_model, DpmConfig(threshold=-5.0)).cascade is None
    assert DpmDetector(inria_model, DpmConfig(cascade=False)).cascade is None
    assert DpmDetector(inria_model, DpmConfig(deformation_window=None)).cascade is None


def test_models_without_thresholds_score_exactly(voc_path):
    assert DpmDetector(load_dpm_model(voc_path), DpmConfig()).cascade is None


@pytest.mark.parametrize(
    "text", ["not json", "{}", '{"thresholds": [{"score_threshold": -1}]}', "[1, 2]"]
)
def test_bad_threshold_files_raise_clear_errors(tmp_path, text):
    path = tmp_path / "bad.cascade.json"
    path.write_text(text)
    with pytest.raises(ValueError, match="is not a cascade thresholds file"):
        load_cascade(path)


def test_fit_command_writes_thresholds_the_detector_uses(inria_path, shared_data, tmp_path):
    out = tmp_path / "inria.cascade.json"
    code = fit_main(
        ["--model", str(inria_path), "--sequences", str(shared_data / "otb" / "Crossing"),
         "--step", "40", "--out", str(out)]
    )  # fmt: skip
    assert code == 0
    payload = json.loads(out.read_text())
    assert payload["model"] == "inriaperson" and payload["thresholds"]
    table = load_cascade(out)
    assert [t.score_threshold for t in table] == sorted(t.score_threshold for t in table)
    lowest = table[0].score_threshold
    detector = DpmDetector.from_file(
        inria_path, DpmConfig(threshold=lowest, cascade_thresholds=out)
    )
    assert detector.cascade is not None and math.isclose(detector.cascade.score_threshold, lowest)


@pytest.mark.parametrize(
    "args, message",
    [
        (["--model", "{tmp}/missing.mat", "--sequences", "{otb}/Crossing"], "not found"),
        (["--model", "{model}", "--sequences", "{tmp}/no-such-folder"], "does not exist"),
        (["--model", "{model}", "--sequences", "{otb}/Crossing", "--out", "{tmp}/no/dir/x.json"],
         "the folder"),
    ],
)  # fmt: skip
def test_fit_command_reports_bad_input_and_writes_nothing(
    inria_path, shared_data, tmp_path, capsys, args, message
):
    values = {"tmp": tmp_path, "otb": shared_data / "otb", "model": inria_path}
    argv = [a.format(**values) for a in args]
    if "--out" not in argv:
        argv += ["--out", str(tmp_path / "out.cascade.json"), "--step", "60"]
    else:
        argv += ["--step", "60"]
    assert fit_main(argv) == 2
    assert message in capsys.readouterr().err
    assert not list(tmp_path.rglob("*.json"))


def test_fit_command_rejects_a_zero_step(inria_path, shared_data):
    with pytest.raises(SystemExit):
        fit_main(
            ["--model", str(inria_path), "--sequences", str(shared_data / "otb"), "--step", "0"]
        )


_AFTER_WARM_UP = """
import sys
import numpy as np
from tracking.detection.dpm import kernels as dpm_kernels
from tracking.detection.dpm.detector import DpmConfig, DpmDetector
from tracking.detection.dpm.model import load_dpm_model
from tracking.features import hog
from tracking.types import Box
from tracking.warmup import warm_up

warm_up()
kernels = [dpm_kernels.cascade_roots, dpm_kernels._dot, dpm_kernels._responses,
           dpm_kernels.exact_component, hog._features]
before = [len(k.signatures) for k in kernels]
crop = np.load(sys.argv[2])
detector = DpmDetector(load_dpm_model(sys.argv[1]), DpmConfig())
detector.detect(crop)
detector.dense_scores(crop, Box(60, 60, 60, 60))
hog.hog_feature_map(crop[:64, :64], 4)
print([len(k.signatures) for k in kernels], before)
"""


def test_warm_up_compiles_what_detection_runs(inria_path, pets_frame, tmp_path):
    # after tracking.warmup, a real detection (cascade, region, HOG map) compiles nothing more;
    # in a fresh interpreter, as other tests may have compiled the kernels already
    crop = tmp_path / "crop.npy"
    np.save(crop, pets_frame[150:420, 180:420])
    done = subprocess.run(
        [sys.executable, "-c", _AFTER_WARM_UP, str(inria_path), str(crop)],
        capture_output=True, text=True, timeout=600, check=False,
    )  # fmt: skip
    assert done.returncode == 0, done.stderr
    after, before = done.stdout.strip().split("] [")
    assert after + "]" == "[" + before, done.stdout
