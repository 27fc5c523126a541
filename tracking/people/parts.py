"""Body parts in the particle filter: one 2-D Kalman filter per part and particle (DESIGN.md
§5). The linear state of part ``p`` is its offset's deviation ``delta`` from the body-model
mean ``mu_p``, in heights; its image position is ``centre + h (mu_p + delta)``."""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

import numpy as np

from tracking.filtering import RbpfState
from tracking.people.body import BodyModel
from tracking.people.config import PeopleTrackerConfig
from tracking.people.motion import CX, CY, LOG_H
from tracking.people.occlusion import occluders

if TYPE_CHECKING:
    from tracking.detection.base import Detections


def prior(body: BodyModel) -> tuple[np.ndarray, np.ndarray]:
    """Mean ``(P, 2)`` and covariance ``(P, 2, 2)`` of the deviations at a person's birth: the
    body model's own spread (the deformation prior)."""
    cov = np.zeros((len(body), 2, 2))
    cov[:, 0, 0] = body.std[:, 0] ** 2
    cov[:, 1, 1] = body.std[:, 1] ** 2
    return np.zeros((len(body), 2)), cov


def transition(
    body: BodyModel, dt: float, config: PeopleTrackerConfig
) -> tuple[np.ndarray, np.ndarray]:
    """``A`` and ``Q`` ``(P, 2, 2)`` of the deviations over ``dt`` seconds.

    An AR(1) pull towards the body-model mean, ``delta' = a delta + w`` with
    ``a = exp(-gain dt)``, whose noise keeps the stationary spread at the body model's
    (``std^2 (1 - a^2)``) plus a small random walk (``part_process_noise^2 dt``).
    """
    a = math.exp(-config.part_prior_gain * max(dt, 0.0))
    transition_ = np.broadcast_to(a * np.eye(2), (len(body), 2, 2))
    variance = body.std**2 * (1.0 - a * a) + config.part_process_noise**2 * max(dt, 0.0)
    noise = np.zeros((len(body), 2, 2))
    noise[:, 0, 0], noise[:, 1, 1] = variance[:, 0], variance[:, 1]
    return transition_, noise


def positions(body: BodyModel, state: RbpfState) -> np.ndarray:
    """Estimated image positions ``(T, P, 2)``: the weighted mean over particles of
    ``centre + h (mu + delta)``."""
    per_particle = _particle_positions(body, state.particles, state.mean)
    return np.einsum("tn,tnpd->tpd", state.weights, per_particle)


def _particle_positions(body: BodyModel, particles: np.ndarray, deviation: np.ndarray):
    height = np.exp(particles[..., LOG_H])[..., None, None]  # (T, N, 1, 1)
    centre = particles[..., None, [CX, CY]]  # (T, N, 1, 2)
    return centre + height * (body.mean + deviation)


def measurements(
    body: BodyModel,
    tracks: list,
    detections: Detections,
    state: RbpfState,
    config: PeopleTrackerConfig,
) -> dict[str, np.ndarray]:
    """Keyword arguments of :func:`tracking.filtering.update` for the part placements of each
    person's associated detection (a DPM detection's part boxes, matched by name); ``{}`` when
    no detection has parts.

    Every person gets one slot per body part; a part without a measurement (no such part in
    the detection, or covered by a nearer person, DESIGN.md §5) has infinite noise, which the
    filter skips.
    """
    if detections.parts.shape[1] == 0:
        return {}
    index = {name: p for p, name in enumerate(body.names)}
    columns = [(k, index[n]) for k, n in enumerate(detections.part_names) if n in index]
    if not columns:
        return {}
    people, parts = len(tracks), len(body)
    z = np.zeros((people, parts, 2))
    noise = np.full((people, parts), np.inf)
    roots = np.einsum("tn,tnd->td", state.weights, state.particles)
    heights = np.exp(roots[:, LOG_H])
    width_height = np.stack([heights * 0.41, heights], axis=1)
    predicted = np.concatenate([roots[:, [CX, CY]] - width_height / 2, width_height], axis=1)
    hidden_by = occluders(predicted, config.occlusion_overlap)
    expected = positions(body, state)
    for t, track in enumerate(tracks):
        if not track.measured:
            continue
        det_parts = detections.parts[track.detection]
        for k, p in columns:
            box = det_parts[k]
            if not np.all(np.isfinite(box)):
                continue
            centre = box[:2] + box[2:] / 2
            covered = any(
                _inside(expected[t, p], predicted[j]) for j in np.flatnonzero(hidden_by[t])
            )
            if covered:
                continue
            z[t, p] = centre
            noise[t, p] = (config.part_measurement_sigma * heights[t]) ** 2
    if not np.any(np.isfinite(noise)):
        return {}
    height = np.exp(state.particles[..., LOG_H])  # (T, N)
    observation = height[..., None, None, None] * np.eye(2)  # H = h I, (T, N, 1, 2, 2)
    offset = state.particles[..., None, [CX, CY]] + height[..., None, None] * body.mean
    r = np.zeros((people, 1, parts, 2, 2))
    r[..., 0, 0] = r[..., 1, 1] = noise[:, None, :]
    r[~np.isfinite(noise)[:, None, :]] = np.inf
    return {
        "blocks": np.broadcast_to(np.arange(parts), (people, parts)),
        "measurement": z,
        "observation": observation,
        "offset": offset,
        "noise": r,
    }


def _inside(point: np.ndarray, box: np.ndarray) -> bool:
    return bool(box[0] <= point[0] <= box[0] + box[2] and box[1] <= point[1] <= box[1] + box[3])
