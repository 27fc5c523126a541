"""The measurement likelihoods of the root state."""

import numpy as np
import pytest

from tracking.people.likelihoods import dense_score_log_likelihood, detection_log_likelihood


def test_dense_scores_become_calibrated_log_probabilities():
    scores = np.array([-np.inf, -2.0, 0.0, 2.0])
    log_lik = dense_score_log_likelihood(scores, 1.5, 0.5)
    assert np.all(np.diff(log_lik) > 0)  # a higher score is more likely a person
    assert log_lik[2] == pytest.approx(np.log(1 / (1 + np.exp(-0.5))))  # sigmoid(a*0 + b)
    assert np.isfinite(log_lik[0]) and log_lik[0] < -40  # unscored: a clear miss, not NaN


def test_detection_likelihood_peaks_at_the_detection_and_keeps_a_floor():
    box = np.array([100.0, 50.0, 40.0, 100.0])  # centre (120, 100), height 100
    particles = np.array(
        [
            [120.0, 100.0, np.log(100.0), 0, 0],  # on the detection
            [130.0, 100.0, np.log(100.0), 0, 0],  # 0.1 heights aside
            [400.0, 100.0, np.log(100.0), 0, 0],  # far away
        ]
    )
    log_lik = detection_log_likelihood(
        particles, box, 0.9, sigma=(0.05, 0.1), log_height_sigma=0.2, clutter=0.05
    )
    assert log_lik[0] > log_lik[1] > log_lik[2]
    assert log_lik[2] == pytest.approx(np.log(0.05))  # the clutter floor
