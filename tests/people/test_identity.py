"""Colour signatures, the predictive association likelihood and gated assignment."""

import numpy as np

from tracking.people.association import assign
from tracking.people.identity import SIGNATURE_SIZE, colour_signatures, signature_similarity
from tracking.people.likelihoods import detection_log_likelihood, predictive_log_likelihood


def _person(shirt, trousers, size=(120, 80)):
    """An RGB frame with one person: a grey background, a shirt over trousers, noise."""
    rng = np.random.default_rng(0)
    image = np.full((*size, 3), 128, dtype=np.float64)
    image[20:50, 30:50] = shirt
    image[50:90, 30:50] = trousers
    image += rng.normal(0, 4, image.shape)
    return np.clip(image, 0, 255).astype(np.uint8)


BOX = np.array([[28.0, 10.0, 24.0, 95.0]])


def test_same_clothes_are_similar_and_other_clothes_are_not():
    red_blue = colour_signatures(_person((200, 30, 30), (30, 30, 160)), BOX)
    again = colour_signatures(_person((190, 40, 35), (35, 30, 150)), BOX)
    green_black = colour_signatures(_person((30, 170, 40), (20, 20, 20)), BOX)
    assert red_blue.shape == (1, SIGNATURE_SIZE)
    same = signature_similarity(red_blue, again)[0, 0]
    other = signature_similarity(red_blue, green_black)[0, 0]
    assert same > 0.8 and other < 0.3
    assert np.isclose(signature_similarity(red_blue, red_blue)[0, 0], 1.0)


def test_boxes_outside_the_image_give_empty_signatures():
    image = _person((200, 30, 30), (30, 30, 160))
    out = colour_signatures(image, np.array([[500.0, 500.0, 20.0, 50.0], [-40, -90, 10, 20]]))
    assert out.shape == (2, SIGNATURE_SIZE) and not out.any()
    assert colour_signatures(image, np.zeros((0, 4))).shape == (0, SIGNATURE_SIZE)


def test_predictive_likelihood_is_the_particle_mean_of_the_detection_density():
    rng = np.random.default_rng(1)
    particles = np.zeros((2, 50, 5))
    particles[..., 0] = rng.normal([[100.0], [300.0]], 5.0, (2, 50))
    particles[..., 1] = rng.normal(200.0, 5.0, (2, 50))
    particles[..., 2] = np.log(80.0) + rng.normal(0, 0.05, (2, 50))
    boxes = np.array([[85.0, 160.0, 30.0, 82.0], [290.0, 150.0, 33.0, 90.0]])
    sigma, log_sigma = (0.05, 0.1), 0.2
    got = predictive_log_likelihood(particles, boxes, sigma=sigma, log_height_sigma=log_sigma)
    for t in range(2):
        for d in range(2):
            with np.errstate(divide="ignore"):  # without clutter, far particles log to -inf
                log_density = detection_log_likelihood(
                    particles[t], boxes[d], 1.0, sigma=sigma, log_height_sigma=log_sigma, clutter=0
                )
            density = np.exp(log_density)
            if t == d:
                assert np.isclose(got[t, d], np.log(density.mean()))
            else:  # the density underflows to 0; the log-sum-exp stays finite and far below
                assert density.max() == 0 and got[t, d] < got[d, d] - 100


def test_assignment_never_pairs_a_forbidden_pair():
    similarity = np.array([[5.0, -np.inf], [-np.inf, -np.inf], [1.0, 2.0]])
    assert sorted(assign(similarity)) == [(0, 0), (2, 1)]
    assert assign(np.full((2, 2), -np.inf)) == []
    assert assign(np.array([[0.2, 0.9]]), threshold=0.5) == [(0, 1)]
