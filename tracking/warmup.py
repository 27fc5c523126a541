"""Compile the numba kernels ahead of use: ``python -m tracking.warmup``.

The kernels (HOG features, the DPM's star cascade) compile on their first call, about 20 s in
all on a fresh install, and are cached on disk (``__pycache__`` beside the sources, or
``NUMBA_CACHE_DIR``). Running this once, e.g. while a container image is built, moves that cost
out of the first request. It runs every kernel on small synthetic inputs of the types the
library passes them.
"""

from __future__ import annotations

import time

import numpy as np

from tracking.detection.dpm.cascade import CascadeThresholds, cascade_level, pca_projection
from tracking.detection.dpm.model import DpmComponent, DpmModel, FilterSymbol
from tracking.detection.dpm.pyramid import level_features, pyramid_levels
from tracking.features.hog import fhog, hog_feature_map

__all__ = ["warm_up"]


def _tiny_model() -> DpmModel:
    """A one-part star model with random filters (only its array types matter)."""
    rng = np.random.default_rng(0)

    def symbol(index: int, shape: tuple[int, int], anchor: tuple[int, int, int], deformed: bool):
        weights = rng.standard_normal((*shape, 32)).astype(np.float32)
        weights.flags.writeable = False  # as the model loader leaves them (numba types differ)
        deformation = np.array([0.1, 0.0, 0.1, 0.0]) if deformed else None
        return FilterSymbol(index, weights, anchor, deformation, 0.0, np.zeros(3))

    root = symbol(0, (3, 2), (0, 0, 0), deformed=False)
    part = symbol(1, (2, 2), (1, 1, 1), deformed=True)
    component = DpmComponent(0, root, (part,), 0.0, np.zeros(3), (3, 2), (0, 0), False, None)
    return DpmModel("warmup", (component,), 8, 2, 0.0, (3, 2), False)


def warm_up() -> float:
    """Call every kernel once; returns the seconds it took."""
    start = time.perf_counter()
    rng = np.random.default_rng(0)
    image = rng.integers(0, 256, (48, 40, 3), dtype=np.uint8)
    for variant in (image, image[..., ::-1], image.astype(np.float32)):
        fhog(variant, 8, truncation_feature=True)
        fhog(variant[..., 0], 4)
        hog_feature_map(variant, 4)
    model = _tiny_model()
    levels = pyramid_levels(image.shape, model.sbin, model.interval, model.extra_octave)
    root = levels[model.interval]
    features = level_features(image, (root, levels[0]), model.max_size)
    projection = pca_projection(model, dims=2)
    projected = {k: projection.project(v) for k, v in features.items()}
    for record in (None, np.array([[0, 0]])):
        cascade_level(
            model, features, projected, projection, root, model.max_size,
            CascadeThresholds.exact(1), -np.inf, positions=record,
        )  # fmt: skip
    # no projection: the dense exact kernel of regions of interest
    cascade_level(
        model, features, None, None, root, model.max_size, CascadeThresholds.exact(1), -np.inf
    )
    return time.perf_counter() - start


if __name__ == "__main__":
    import argparse

    argparse.ArgumentParser(
        prog="python -m tracking.warmup", description=__doc__.split("\n\n")[0]
    ).parse_args()  # no options; --help says what it does instead of doing it
    print(f"numba kernels ready ({warm_up():.1f} s)")
