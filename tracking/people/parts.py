"""Body parts in the particle filter: Kalman filters per part and particle (docs/architecture.md
§5). The linear state of part ``p`` is its offset's deviation ``delta`` from the body-model mean
``mu_p``, in heights; its image position is ``centre + h (mu_p + delta)``.

Every matrix of the model is diagonal (the prior, the AR(1) pull and its noise, ``H = h I``,
the measurement noise), so a part's x and y deviations are independent: the filter holds them
as ``2P`` blocks of one dimension, part ``p``'s x at block ``2p`` and y at ``2p + 1`` (the same
memory as ``(P, 2)``). The updates are then elementwise, and exactly those of ``P`` 2-D blocks.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

import numpy as np

from tracking.filtering import RbpfState
from tracking.people.body import BodyModel
from tracking.people.config import PeopleTrackerConfig
from tracking.people.motion import CX, CY, LOG_H
from tracking.people.occlusion import hidden_points, occluders

if TYPE_CHECKING:
    from tracking.detection.base import Detections


def prior(body: BodyModel) -> tuple[np.ndarray, np.ndarray]:
    """Mean ``(2P, 1)`` and variance ``(2P, 1, 1)`` of the deviations at a person's birth: the
    body model's own spread (the deformation prior)."""
    return np.zeros((2 * len(body), 1)), (body.std**2).reshape(-1, 1, 1)


def transition(
    body: BodyModel, dt: float, config: PeopleTrackerConfig
) -> tuple[np.ndarray, np.ndarray]:
    """``A`` and ``Q`` ``(2P, 1, 1)`` of the deviations over ``dt`` seconds.

    An AR(1) pull towards the body-model mean, ``delta' = a delta + w`` with
    ``a = exp(-gain dt)``, whose noise keeps the stationary spread at the body model's
    (``std^2 (1 - a^2)``) plus a small random walk (``part_process_noise^2 dt``).
    """
    a = math.exp(-config.part_prior_gain * max(dt, 0.0))
    variance = body.std**2 * (1.0 - a * a) + config.part_process_noise**2 * max(dt, 0.0)
    return np.full((2 * len(body), 1, 1), a), variance.reshape(-1, 1, 1)


def positions(body: BodyModel, state: RbpfState) -> np.ndarray:
    """Estimated image positions ``(T, P, 2)``: the weighted mean over particles of
    ``centre + h (mu + delta)``."""
    deviation = state.mean.reshape(*state.mean.shape[:-2], len(body), 2)
    per_particle = _particle_positions(body, state.particles, deviation)
    return np.einsum("tn,tnpd->tpd", state.weights, per_particle)


def _particle_positions(body: BodyModel, particles: np.ndarray, deviation: np.ndarray):
    height = np.exp(particles[..., LOG_H])[..., None, None]  # (T, N, 1, 1)
    centre = particles[..., None, [CX, CY]]  # (T, N, 1, 2)
    return centre + height * (body.mean + deviation)


def from_detections(
    body: BodyModel, tracks: list, detections: Detections
) -> tuple[np.ndarray, np.ndarray]:
    """Part centres ``(T, P, 2)`` from each person's associated detection (a DPM detection's
    part boxes, matched by name), and which slots hold one ``(T, P)``."""
    people, parts = len(tracks), len(body)
    z = np.zeros((people, parts, 2))
    found = np.zeros((people, parts), dtype=bool)
    if detections.parts.shape[1] == 0:
        return z, found
    index = {name: p for p, name in enumerate(body.names)}
    columns = [(k, index[n]) for k, n in enumerate(detections.part_names) if n in index]
    for t, track in enumerate(tracks):
        if not track.measured:
            continue
        boxes = detections.parts[track.detection]
        for k, p in columns:
            if np.all(np.isfinite(boxes[k])):
                z[t, p] = boxes[k, :2] + boxes[k, 2:] / 2
                found[t, p] = True
    return z, found


def hidden(body: BodyModel, state: RbpfState, boxes: np.ndarray, min_overlap: float):
    """Which parts ``(T, P)`` a nearer person's box covers (they get no measurement and are
    reported not visible, docs/architecture.md §5)."""
    return hidden_points(positions(body, state), occluders(boxes, min_overlap), boxes)


def filter_arguments(
    body: BodyModel, state: RbpfState, z: np.ndarray, found: np.ndarray, sigma: np.ndarray
) -> dict[str, np.ndarray]:
    """Keyword arguments of :func:`tracking.filtering.update` for part measurements ``z``
    ``(T, P, 2)`` where ``found``; ``{}`` when there is none.

    The measurement of part ``p`` is ``z = centre + h mu_p + h delta_p + e``: linear in the
    deviation ``delta_p`` with ``H = h I`` and offset ``centre + h mu_p`` per particle, noise
    ``e`` with a standard deviation of ``sigma`` heights, per person ``(T,)`` or per person and
    part ``(T, P)``. Every person has a slot per part and axis; slots without a measurement
    carry infinite noise, which the filter skips.
    """
    if not np.any(found):
        return {}
    people, parts = found.shape
    roots = np.einsum("tn,tnd->td", state.weights, state.particles)
    sigma = np.broadcast_to(np.asarray(sigma, dtype=np.float64).reshape(people, -1), found.shape)
    variance = (sigma * np.exp(roots[:, LOG_H])[:, None]) ** 2  # (T, P)
    variance = np.where(found, variance, np.inf)  # infinite: no measurement
    height = np.exp(state.particles[..., LOG_H])  # (T, N)
    offset = state.particles[..., None, [CX, CY]] + height[..., None, None] * body.mean
    return {  # the blocks of x and y (the module's docstring)
        "blocks": np.broadcast_to(np.arange(2 * parts), (people, 2 * parts)),
        "measurement": z.reshape(people, 2 * parts, 1),
        "observation": height[..., None, None, None],
        "offset": offset.reshape(*offset.shape[:2], 2 * parts, 1),
        "noise": np.repeat(variance, 2, axis=1).reshape(people, 1, 2 * parts, 1, 1),
    }
