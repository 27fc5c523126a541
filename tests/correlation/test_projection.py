"""Algorithm 4.1: the adaptive projection is orthonormal and keeps the largest variance."""

import numpy as np
import pytest

from tracking.correlation.projection import AdaptiveProjection


def appearance_with_variances(variances, seed=0, shape=(80, 60)):
    """Feature map whose per-pixel vectors have the given variances along a random rotation."""
    rng = np.random.default_rng(seed)
    dims = len(variances)
    rotation, _ = np.linalg.qr(rng.standard_normal((dims, dims)))
    values = rng.standard_normal((*shape, dims)) * np.sqrt(variances)
    return values @ rotation.T + 3.0, rotation  # a large mean, which must not matter (line 1-2)


def test_projection_is_orthonormal_and_spans_the_top_directions():
    appearance, rotation = appearance_with_variances([9.0, 4.0, 1.0, 0.1, 0.01])
    basis = AdaptiveProjection(dim=2, mu=0.15).update(appearance)
    assert basis.shape == (5, 2)
    np.testing.assert_allclose(basis.T @ basis, np.eye(2), atol=1e-6)
    # Same subspace as the two largest-variance directions: projecting them onto it keeps them.
    top = rotation[:, :2]
    np.testing.assert_allclose(basis @ (basis.T @ top), top, atol=0.05)


def test_mu_zero_keeps_the_first_projection():
    first, _ = appearance_with_variances([9.0, 4.0, 1.0], seed=1)
    other, _ = appearance_with_variances([9.0, 4.0, 1.0], seed=2)
    projection = AdaptiveProjection(dim=2, mu=0.0)
    b1 = projection.update(first)
    b2 = projection.update(other)
    # mu = 0: R_t = Q_{t-1}, whose top eigenvectors span the first subspace.
    np.testing.assert_allclose(b2 @ b2.T, b1 @ b1.T, atol=1e-5)


def test_mu_one_uses_only_the_current_appearance():
    first, _ = appearance_with_variances([9.0, 4.0, 1.0], seed=1)
    other, rotation = appearance_with_variances([9.0, 4.0, 1.0], seed=2)
    projection = AdaptiveProjection(dim=1, mu=1.0)
    projection.update(first)
    b = projection.update(other)
    assert abs(float(b[:, 0] @ rotation[:, 0])) == pytest.approx(1.0, abs=0.02)


def test_smoothness_term_slows_the_change_of_subspace():
    first, _ = appearance_with_variances([9.0, 4.0, 1.0], seed=1)
    other, _ = appearance_with_variances([9.0, 4.0, 1.0], seed=2)

    def change(mu):
        projection = AdaptiveProjection(dim=1, mu=mu)
        b1 = projection.update(first)
        b2 = projection.update(other)
        return 1.0 - abs(float(b1[:, 0] @ b2[:, 0]))

    assert change(0.1) < change(1.0)


def test_dimension_above_the_feature_count_is_clamped():
    appearance, _ = appearance_with_variances([2.0, 1.0])
    assert AdaptiveProjection(dim=5, mu=0.1).update(appearance).shape == (2, 2)
