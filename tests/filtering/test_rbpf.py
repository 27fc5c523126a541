"""The Rao-Blackwellized particle filter against exact references."""

import numpy as np
import pytest
from scipy.stats import multivariate_normal

from tracking.filtering import (
    RbpfState,
    effective_sample_size,
    estimate,
    kalman_predict,
    kalman_update,
    normalize_log_weights,
    predict,
    resample,
    systematic_resample,
    update,
)


def test_kalman_update_matches_the_textbook_formulas():
    rng = np.random.default_rng(0)
    a = rng.standard_normal((3, 3))
    cov = a @ a.T + np.eye(3)
    mean = rng.standard_normal(3)
    h = rng.standard_normal((2, 3))
    r = np.diag([0.5, 2.0])
    z = rng.standard_normal(2)
    new_mean, new_cov, log_lik = kalman_update(mean, cov, z, h, r, offset=np.array([1.0, -1.0]))
    s = h @ cov @ h.T + r
    k = cov @ h.T @ np.linalg.inv(s)
    predicted = h @ mean + np.array([1.0, -1.0])
    np.testing.assert_allclose(new_mean, mean + k @ (z - predicted))
    np.testing.assert_allclose(new_cov, (np.eye(3) - k @ h) @ cov, atol=1e-12)
    assert log_lik == pytest.approx(multivariate_normal(predicted, s).logpdf(z))


def test_rbpf_matches_the_kalman_filter_on_a_linear_gaussian_model():
    """x = [x^n, x^l]: x^n a random walk sampled by particles, x^l an AR(1) state in a Kalman
    filter per particle. y = x^n + e1 weighs the particles; z = x^n + x^l + e2 is the linear
    measurement (offset c(x^n) = x^n, H = 1). The whole model is linear-Gaussian, so a 2-D Kalman
    filter gives the exact posterior mean that the RBPF must approach."""
    q_n, q_l, a, r_y, r_z = 0.5, 0.2, 0.9, 1.0, 0.4
    rng = np.random.default_rng(1)
    steps, n = 15, 20000
    truth_n, truth_l = 0.0, 1.0
    ys, zs = [], []
    for _ in range(steps):
        truth_n += rng.normal(0, np.sqrt(q_n))
        truth_l = a * truth_l + rng.normal(0, np.sqrt(q_l))
        ys.append(truth_n + rng.normal(0, np.sqrt(r_y)))
        zs.append(truth_n + truth_l + rng.normal(0, np.sqrt(r_z)))

    # Exact: the joint Kalman filter.
    f = np.diag([1.0, a])
    q = np.diag([q_n, q_l])
    h = np.array([[1.0, 0.0], [1.0, 1.0]])
    r = np.diag([r_y, r_z])
    mean, cov = np.zeros(2), np.diag([1.0, 1.0])
    # RBPF with the same prior: x^n ~ N(0, 1), x^l ~ N(0, 1) independent.
    filt_rng = np.random.default_rng(2)
    state = RbpfState.from_prior(
        filt_rng.normal(0, 1, (n, 1)), np.zeros((1, 1)), np.ones((1, 1, 1))
    )
    for y, z in zip(ys, zs, strict=True):
        mean, cov = kalman_predict(mean, cov, f, q)
        mean, cov, _ = kalman_update(mean, cov, np.array([y, z]), h, r)

        state = predict(
            state,
            lambda p: p + filt_rng.normal(0, np.sqrt(q_n), p.shape),
            np.array([[a]]),
            np.array([[q_l]]),
        )
        log_lik = -0.5 * (y - state.particles[:, 0]) ** 2 / r_y
        state = update(
            state,
            log_lik,
            blocks=np.array([0]),
            measurement=np.array([[z]]),
            observation=np.ones((1, 1)),
            offset=state.particles[:, None, :1],
            noise=np.array([[r_z]]),
        )
        state = resample(state, filt_rng)
    nonlinear, linear = estimate(state)
    # Monte Carlo error of 20000 particles: a few hundredths of the posterior std (~0.5).
    assert nonlinear[0] == pytest.approx(mean[0], abs=0.05)
    assert linear[0, 0] == pytest.approx(mean[1], abs=0.05)


def test_split_into_part_filters_equals_the_joint_filter():
    """Three independent 2-D blocks (parts): per-block Kalman filters inside the RBPF give the
    same means, covariances and particle weights as one 6-D filter with block-diagonal
    matrices."""
    rng = np.random.default_rng(3)
    n, k, d = 5, 3, 2
    particles = rng.standard_normal((n, 2))
    means = rng.standard_normal((n, k, d))
    covs = np.stack([np.stack([np.eye(d) * (1 + i + j) for j in range(k)]) for i in range(n)])
    state = RbpfState(particles, np.full(n, 1 / n), means, covs)
    scale = 1.0 + np.abs(particles[:, 0])  # H depends on the particle (the root scale)
    h = scale[:, None, None, None] * np.eye(d)  # (n, 1, d, d), shared by the blocks
    offset = particles[:, None, :]  # (n, 1, d)
    z = rng.standard_normal((k, d))
    r = np.stack([np.eye(d) * (0.5 + j) for j in range(k)])
    split = update(state, blocks=np.arange(k), measurement=z, observation=h, offset=offset, noise=r)
    for i in range(n):
        joint_h = np.kron(np.eye(k), h[i, 0])
        joint_r = np.zeros((k * d, k * d))
        joint_p = np.zeros((k * d, k * d))
        for j in range(k):
            joint_r[j * d : (j + 1) * d, j * d : (j + 1) * d] = r[j]
            joint_p[j * d : (j + 1) * d, j * d : (j + 1) * d] = covs[i, j]
        m, p, log_lik = kalman_update(
            means[i].ravel(), joint_p, z.ravel(), joint_h, joint_r, np.tile(offset[i, 0], k)
        )
        np.testing.assert_allclose(split.mean[i].ravel(), m)
        for j in range(k):
            block = slice(j * d, (j + 1) * d)
            np.testing.assert_allclose(split.cov[i, j], p[block, block], atol=1e-12)
        if i == 0:
            log_liks = []
        log_liks.append(log_lik)
    np.testing.assert_allclose(split.weights, normalize_log_weights(np.array(log_liks)))


def test_infinite_noise_marks_a_padding_measurement():
    state = RbpfState.from_prior(np.zeros((4, 1)), np.zeros((2, 2)), np.stack([np.eye(2)] * 2))
    out = update(
        state,
        blocks=np.array([0, 1]),
        measurement=np.array([[1.0, 1.0], [9.0, 9.0]]),
        observation=np.eye(2),
        noise=np.stack([np.eye(2), np.full((2, 2), np.inf)]),
    )
    np.testing.assert_allclose(out.mean[:, 1], 0.0)  # block 1 untouched
    assert np.all(out.mean[:, 0] > 0.4)  # block 0 moved towards its measurement


def test_evidence_weight_tempers_what_block_measurements_do_to_the_weights():
    # particles with different Kalman means: the measurement favours the first
    state = RbpfState.from_prior(np.zeros((2, 1)), np.zeros((1, 2)), np.eye(2)[None])
    state = RbpfState(
        state.particles, state.weights, np.array([[[0.0, 0.0]], [[3.0, 3.0]]]), state.cov
    )
    measured = dict(
        blocks=np.array([0]),
        measurement=np.array([[0.0, 0.0]]),
        observation=np.eye(2),
        noise=np.eye(2)[None],
    )
    full = update(state, **measured)
    none = update(state, evidence_weight=0.0, **measured)
    half = update(state, evidence_weight=0.5, **measured)
    assert full.weights[0] > half.weights[0] > none.weights[0] == pytest.approx(0.5)
    # the Kalman filters are updated all the same
    np.testing.assert_allclose(none.mean, full.mean)
    np.testing.assert_allclose(none.cov, full.cov)


def test_batched_people_filter_independently():
    rng = np.random.default_rng(4)
    people, n = 3, 50
    particles = rng.standard_normal((people, n, 1))
    state = RbpfState.from_prior(particles, np.zeros((1, 1)), np.ones((1, 1, 1)))
    log_lik = -0.5 * (particles[..., 0] - np.array([[-2.0], [0.0], [2.0]])) ** 2
    out = resample(update(state, log_lik), rng, threshold=1.0)
    nonlinear, _ = estimate(out)
    assert nonlinear[0, 0] < nonlinear[1, 0] < nonlinear[2, 0]


def test_systematic_resampling_keeps_expected_counts():
    weights = np.array([0.5, 0.25, 0.125, 0.125])
    counts = np.bincount(systematic_resample(weights, np.random.default_rng(5)), minlength=4)
    # Systematic resampling gives each particle floor or ceil of N w_i copies.
    assert np.all(np.abs(counts - 4 * weights) < 1)
    batched = systematic_resample(np.stack([weights, weights[::-1]]), np.random.default_rng(6))
    assert batched.shape == (2, 4) and batched.max() < 4


def test_effective_sample_size_and_degenerate_weights():
    assert effective_sample_size(np.full(10, 0.1)) == pytest.approx(10)
    assert effective_sample_size(np.eye(10)[0]) == pytest.approx(1)
    np.testing.assert_allclose(normalize_log_weights(np.full(4, -np.inf)), 0.25)


def test_kalman_update_of_two_dimensional_measurements_in_a_batch():
    """A batch of 2-D measurements of 4-D states gives the textbook update of each."""
    rng = np.random.default_rng(1)
    a = rng.standard_normal((5, 7, 4, 4))
    cov = a @ np.swapaxes(a, -1, -2) + np.eye(4)
    mean = rng.standard_normal((5, 7, 4))
    h = np.hstack([np.eye(2), np.zeros((2, 2))])
    r = np.diag([0.3, 0.7])
    z = rng.standard_normal((5, 7, 2))
    new_mean, new_cov, log_lik = kalman_update(mean, cov, z, h, r)
    for i, j in np.ndindex(5, 7):
        s = h @ cov[i, j] @ h.T + r
        k = cov[i, j] @ h.T @ np.linalg.inv(s)
        np.testing.assert_allclose(new_mean[i, j], mean[i, j] + k @ (z[i, j] - h @ mean[i, j]))
        np.testing.assert_allclose(new_cov[i, j], (np.eye(4) - k @ h) @ cov[i, j], atol=1e-12)
        expected = multivariate_normal(h @ mean[i, j], s).logpdf(z[i, j])
        assert log_lik[i, j] == pytest.approx(expected)


def test_every_block_in_order_updates_as_the_same_blocks_shuffled():
    """The parts' filters measured all at once, in order (the pose network's slots), give what
    the same measurements in another order give (the gathered path)."""
    rng = np.random.default_rng(5)
    blocks, n = 4, 6
    a = rng.standard_normal((n, blocks, 2, 2))
    state = RbpfState(
        rng.standard_normal((n, 1)),
        np.full(n, 1 / n),
        rng.standard_normal((n, blocks, 2)),
        a @ np.swapaxes(a, -1, -2) + np.eye(2),
    )
    z = rng.standard_normal((blocks, 2))
    noise = np.stack([np.eye(2) * 0.5, np.full((2, 2), np.inf), np.eye(2), np.eye(2) * 2])
    order = np.array([2, 0, 3, 1])
    ordered = update(
        state, blocks=np.arange(blocks), measurement=z, observation=np.eye(2), noise=noise
    )
    shuffled = update(
        state, blocks=order, measurement=z[order], observation=np.eye(2), noise=noise[order]
    )
    np.testing.assert_allclose(ordered.mean, shuffled.mean)
    np.testing.assert_allclose(ordered.cov, shuffled.cov)
    np.testing.assert_allclose(ordered.weights, shuffled.weights)
    np.testing.assert_allclose(ordered.mean[:, 1], state.mean[:, 1])  # the infinite noise's


def test_one_dimensional_blocks_filter_as_the_axes_of_diagonal_two_dimensional_ones():
    """The body parts' x and y as 1-D blocks (elementwise updates) give what 2-D blocks with
    diagonal matrices give (the matrix path), per particle, with the evidence summed."""
    rng = np.random.default_rng(7)
    people, n, parts = 3, 5, 4
    variance = rng.uniform(0.5, 2.0, (people, n, parts, 2))
    deviation = rng.standard_normal((people, n, parts, 2))
    a, q = rng.uniform(0.5, 1.0, (parts, 2)), rng.uniform(0.1, 0.3, (parts, 2))
    h = rng.uniform(20.0, 80.0, (people, n))  # the particles' heights
    offset = rng.standard_normal((people, n, parts, 2))
    z = rng.standard_normal((people, parts, 2))
    r = rng.uniform(0.5, 3.0, (people, parts, 2))
    r[0, 1] = np.inf  # a part without a measurement
    square = RbpfState(
        rng.standard_normal((people, n, 1)),
        np.full((people, n), 1 / n),
        deviation,
        variance[..., None] * np.eye(2),
    )
    square = predict(square, lambda p: p, a[..., None] * np.eye(2), q[..., None] * np.eye(2))
    square = update(
        square,
        blocks=np.broadcast_to(np.arange(parts), (people, parts)),
        measurement=z,
        observation=h[..., None, None, None] * np.eye(2),
        offset=offset,
        noise=np.where(np.eye(2, dtype=bool), r[:, None, :, :, None], 0.0),
    )
    flat = RbpfState(
        square.particles,
        np.full((people, n), 1 / n),
        deviation.reshape(people, n, 2 * parts, 1),
        variance.reshape(people, n, 2 * parts, 1, 1),
    )
    flat = predict(flat, lambda p: p, a.reshape(-1, 1, 1), q.reshape(-1, 1, 1))
    flat = update(
        flat,
        blocks=np.broadcast_to(np.arange(2 * parts), (people, 2 * parts)),
        measurement=z.reshape(people, 2 * parts, 1),
        observation=h[..., None, None, None],
        offset=offset.reshape(people, n, 2 * parts, 1),
        noise=r.reshape(people, 1, 2 * parts, 1, 1),
    )
    np.testing.assert_allclose(flat.mean.reshape(deviation.shape), square.mean)
    np.testing.assert_allclose(
        flat.cov.reshape(variance.shape), np.diagonal(square.cov, axis1=-2, axis2=-1)
    )
    np.testing.assert_allclose(flat.weights, square.weights)
    assert np.all(square.cov[..., 0, 1] == 0)  # diagonal stays diagonal
