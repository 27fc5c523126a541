"""The detector-fused Rao-Blackwellized particle filter over people (docs/architecture.md §5)."""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, TypeVar

import numpy as np

from tracking.correlation import CorrelationTracker
from tracking.correlation.tracker import ResponseMap
from tracking.detection.base import Detections, Detector
from tracking.detection.nms import box_iou
from tracking.features.maps import FeatureMap
from tracking.filtering import RbpfState, estimate, predict, resample, update
from tracking.people import parts as part_model
from tracking.people.association import assign
from tracking.people.body import EMBEDDED_BODY, POSE_BODY, BodyModel
from tracking.people.camera_motion import CameraMotion, warp_boxes, warp_roots
from tracking.people.config import PeopleTrackerConfig
from tracking.people.identity import colour_signatures, signature_similarity
from tracking.people.keypoints import assign_skeletons, keypoint_measurements, skeletons_in_crops
from tracking.people.likelihoods import (
    dense_score_log_likelihood,
    detection_log_likelihood,
    predictive_log_likelihood,
)
from tracking.people.motion import (
    CX,
    CY,
    LOG_H,
    PEDESTRIAN_ASPECT,
    ROOT_DIM,
    VX,
    VY,
    boxes_from_roots,
    propagate,
    with_aspect,
)
from tracking.people.occlusion import covered_share, hidden_points, occluders
from tracking.people.part_trackers import PartTrackers
from tracking.people.scheduling import DetectionScheduler, widened
from tracking.tracks import FrameTracks
from tracking.types import Box, checked_timestamp, validate_uint8_frame

if TYPE_CHECKING:
    from tracking.detection.pose import PoseEstimator
    from tracking.detection.reid import ReidEmbedder

logger = logging.getLogger(__name__)

_T = TypeVar("_T")


@dataclass(slots=True)
class _Track:
    """What the tracker keeps about one person besides its particles."""

    track_id: int  # 0 until confirmed: only confirmed people are reported, so ids have no gaps
    appearance: CorrelationTracker
    base_height: float  # height when the appearance model was initialised (its scale 1)
    aspect: float  # width / height, smoothed over associated detections
    born: float
    last_seen: float  # time of the last associated detection
    hits: int = 1
    confirmed: bool = False
    occluded: bool = False
    score: float = 0.0
    measured: bool = False  # associated in the current frame
    detection: int = -1  # index of the associated detection in the current frame
    parts: PartTrackers | None = None  # per-part appearance, for detectors without parts
    signature: np.ndarray | None = None  # clothing colours, for recognising the person
    parts_measured: np.ndarray | None = None  # (P,) which parts this frame's image placed
    parts_seen: np.ndarray | None = None  # (P,) keypoints found, when a skeleton was assigned
    gallery: np.ndarray | None = None  # (G, D) re-identification embeddings, NaN rows unused
    gallery_next: int = 0  # the gallery row the next embedding replaces


@dataclass(slots=True)
class _Lost:
    """A confirmed person whose track ended for lack of detections, kept for re-identification."""

    track: _Track
    box: np.ndarray  # the box predicted when it ended
    time: float  # when it ended


@dataclass(slots=True)
class _Frame:
    """Per-frame bookkeeping of :meth:`MultiPersonTracker.update`."""

    image: np.ndarray
    timestamp: float
    detections: Detections
    predicted: np.ndarray = field(default_factory=lambda: np.zeros((0, 4)))  # before the update
    roots: np.ndarray = field(default_factory=lambda: np.zeros((0, 5)))  # estimates, likewise
    responses: list[ResponseMap] = field(default_factory=list)  # each person's appearance
    # (T, D) the association's predictive log likelihoods: each person's particles, each detection
    fit: np.ndarray = field(default_factory=lambda: np.zeros((0, 0)))
    signatures: np.ndarray = field(default_factory=lambda: np.zeros((0, 0)))  # the detections'
    embeddings: np.ndarray | None = None  # (D, E) the detections' re-identification embeddings
    identity: dict[int, np.ndarray] = field(default_factory=dict)  # id(track) -> (D,) log odds
    boxes: np.ndarray = field(default_factory=lambda: np.zeros((0, 4)))  # after the update


class MultiPersonTracker:
    """Tracks every person in view, with stable ids, boxes, occlusion flags and body parts.

    Per frame: predict every person's particles and part filters with the real time step;
    associate detections with people; weigh each particle by the detection likelihood and by
    the person's RCSK appearance response read at the particle, and by the Kalman evidence of
    each part measurement; update the part filters; resample; estimate; reason about
    occlusion; learn appearances; start, confirm and end tracks (docs/architecture.md §5).

    Parameters
    ----------
    config:
        Every parameter, with documented defaults.
    detector:
        Runs when :meth:`update` gets no detections (full frame or regions of interest, on the
        configured schedule). ``None``: detections must be handed in every frame.
    body:
        The body model; by default the pose network's keypoints (:data:`POSE_BODY`) with a
        ``pose`` estimator, else the embedded one (:data:`EMBEDDED_BODY`: head, shoulders,
        hips, knees and feet of an upright adult). A detector's part boxes and a pose
        network's keypoints are measurements of the body model's parts of the same name;
        parts of other names (another model's) are not used.
    pose:
        A body-keypoint network (:class:`~tracking.detection.pose.PoseEstimator`), run on
        every frame with people in it: each person's skeleton measures its parts (issue 76).
    reid:
        A re-identification network (:class:`~tracking.detection.reid.ReidEmbedder`): the
        detections' embeddings, against each person's gallery, are the identity term of the
        association (beside the clothing colours) and of the particles' weights, and
        recognise people who come back.
    """

    def __init__(
        self,
        config: PeopleTrackerConfig | None = None,
        detector: Detector | None = None,
        body: BodyModel | None = None,
        pose: PoseEstimator | None = None,
        reid: ReidEmbedder | None = None,
    ) -> None:
        _check_arguments(config, detector)
        self.config = config or PeopleTrackerConfig()
        self._detector = detector
        self._pose = pose
        self._reid = reid
        self._body = body or (POSE_BODY if pose is not None else EMBEDDED_BODY)
        self._features = FeatureMap.from_config(self.config.appearance)
        part_config = self.config.part_appearance
        self._part_features = FeatureMap.from_config(part_config) if part_config else None
        self._rng = np.random.default_rng(self.config.seed)
        self._scheduler = DetectionScheduler(detector, self.config) if detector else None
        self.reset()

    @property
    def part_names(self) -> tuple[str, ...]:
        return self._body.names

    @property
    def skeleton(self) -> tuple[tuple[str, str], ...]:
        """Pairs of :attr:`part_names` joined by a limb (the body model's, for drawing)."""
        return self._body.skeleton

    def prepare(self) -> None:
        """Compile the pose and re-identification networks for every batch of crops now, not
        on the frames that first need each (a live stream would drop the frames behind)."""
        if self._pose is not None:
            self._pose.prepare_crops()
        if self._reid is not None:
            self._reid.prepare()

    def reset(self) -> None:
        """Forget every person; ids start again at 1, frame indices at 0."""
        self._frames_tracked = 0  # frames reported so far: the next one's index
        self._tracks: list[_Track] = []
        self._lost: list[_Lost] = []
        self._state: RbpfState | None = None
        self._next_id = 1
        self._frame_shape: tuple[int, ...] | None = None
        self._last_timestamp: float | None = None
        self._camera = CameraMotion() if self.config.camera_motion else None
        if self._scheduler is not None:
            self._scheduler.reset()

    # -- the frame step ------------------------------------------------------------------------

    def update(
        self, frame: np.ndarray, timestamp: float, detections: Detections | None = None
    ) -> FrameTracks:
        """Track the people of one frame; the result's ``frame_index`` counts the frames
        tracked since the tracker was made or :meth:`reset`.

        Parameters
        ----------
        frame:
            RGB uint8 ``(H, W, 3)``. A frame of another size than the previous one ends every
            track (the geometry changed, e.g. a camera switched resolution); the people found
            from then on get new ids.
        timestamp:
            Capture time in seconds; must not go backwards.
        detections:
            The frame's detections (public, or from an upstream detector); ``None`` runs the
            tracker's own detector.

        Raises
        ------
        ValueError
            For a malformed frame (empty, wrongly shaped, grayscale), a timestamp that is not
            finite or before the previous one, or no detections and no detector.
        TypeError
            For a frame that is not uint8, a timestamp that is not a number, or detections
            that are not :class:`~tracking.detection.Detections`.
        """
        frame = validate_uint8_frame(frame, "the people tracker")
        self._features.check_frame(frame)
        if detections is not None and not isinstance(detections, Detections):
            raise TypeError(
                "detections must be a tracking.detection.Detections (detections_from_arrays "
                f"makes one from boxes and scores), got {type(detections).__name__}"
            )
        timestamp = checked_timestamp(timestamp, self._last_timestamp)
        if self._frame_shape is not None and frame.shape != self._frame_shape:
            logger.warning(
                "frame size changed from %s to %s: every track ends and tracking starts again",
                self._frame_shape,
                frame.shape,
            )
            # New ids continue from the old ones: an id never names two people.
            next_id, frames = self._next_id, self._frames_tracked
            self.reset()
            self._next_id, self._frames_tracked = next_id, frames
        dt = 0.0 if self._last_timestamp is None else timestamp - self._last_timestamp
        self._frame_shape = frame.shape
        self._last_timestamp = timestamp

        motion = None
        if self._camera is not None:  # the people's last boxes are not the background
            motion = self._camera.estimate(frame, self._predicted_boxes())
        if motion is not None:
            self._follow_camera(motion)
        if self._state is not None:
            # Past the longest time a track survives unseen, a longer prediction only grows the
            # boxes (every track ends at this frame anyway); a camera clock jumping by years
            # would grow them past any image.
            self._predict(min(dt, self.config.occluded_max_missing))
        predicted = self._predicted_boxes()
        if detections is None:
            if self._scheduler is None:
                raise ValueError("no detections given and the tracker has no detector")
            detections = self._scheduler.detect(frame, timestamp, predicted)
        current = _Frame(frame, timestamp, detections, predicted)
        current.signatures = colour_signatures(frame, detections.boxes)
        if self._reid is not None:
            # one batched inference for the frame's detections
            current.embeddings = self._reid.embed(frame, detections.boxes)
        if self._state is not None:
            current.roots, _ = estimate(self._state)
            current.responses = [
                self._respond(track, frame, root)
                for track, root in zip(self._tracks, current.roots, strict=True)
            ]
            self._associate(current)
            self._weigh_and_update(current)
            self._learn(current)
        self._manage(current)
        tracks = self._report(current)
        self._frames_tracked += 1
        return tracks

    # -- steps ---------------------------------------------------------------------------------

    def _predict(self, dt: float) -> None:
        c = self.config
        gain = np.array([c.occluded_noise_gain if t.occluded else 1.0 for t in self._tracks])
        a, q = part_model.transition(self._body, dt, c)
        self._state = predict(
            _known(self._state, "the people's particles"),
            lambda p: propagate(
                p,
                np.full(len(self._tracks), dt),
                gain,
                self._rng,
                position_noise=c.position_noise,
                velocity_damping=c.velocity_damping,
                log_height_noise=c.log_height_noise,
            ),
            a,
            q,
        )

    @staticmethod
    def _respond(track: _Track, frame: np.ndarray, root: np.ndarray) -> ResponseMap:
        """The person's RCSK response over its search window at the predicted estimate (one FFT
        serves the association and every particle)."""
        return track.appearance.respond(
            frame, (float(root[CX]), float(root[CY])), math.exp(root[LOG_H]) / track.base_height
        )

    def _follow_camera(self, motion: np.ndarray) -> None:
        """Move every person's particles, and where lost people were last seen, by the
        camera's motion since the previous frame (:mod:`tracking.people.camera_motion`)."""
        if self._state is not None:
            warp_roots(self._state.particles, motion)
        for lost in self._lost:
            lost.box[:] = warp_boxes(lost.box, motion)[0]

    def _predicted_boxes(self) -> np.ndarray:
        if self._state is None:
            return np.zeros((0, 4))
        roots, _ = estimate(self._state)
        aspect = np.array([t.aspect for t in self._tracks])
        return boxes_from_roots(roots, aspect)

    def _associate(self, current: _Frame) -> None:
        """Two rounds of optimal assignment, confident detections first (the low ones only
        continue tracks), confirmed tracks before tentative ones in each round.

        A pair may match when the boxes overlap (brought to one aspect ratio around their
        centres, so a detector's padding does not count against a match) and the detection is
        plausible under the person's predicted particles (within ``association_gate``) and
        dressed like the person (colour similarity at least ``identity_gate``); among those,
        the assignment maximises the predictive log likelihood plus the appearance log
        likelihood at the detection's centre (the terms that weigh the particles) plus
        ``identity_weight`` times the colour similarity.
        """
        c = self.config
        dets = current.detections
        overlap = box_iou(with_aspect(current.predicted), with_aspect(dets.boxes))
        fit = current.fit = predictive_log_likelihood(
            _known(self._state, "the people's particles").particles,
            dets.boxes,
            sigma=c.detection_sigma,
            log_height_sigma=c.detection_log_height_sigma,
        )
        centres = dets.boxes[:, :2] + dets.boxes[:, 2:] / 2
        look = np.array([r.at(centres) for r in current.responses]).reshape(fit.shape)
        allowed = (overlap >= c.match_iou) & (fit >= -0.5 * c.association_gate)
        score = fit + c.appearance_weight * look
        colour = signature_similarity(
            np.array([_known(t.signature, "a person's colours") for t in self._tracks]),
            current.signatures,
        )
        allowed &= colour >= c.identity_gate
        score += c.identity_weight * colour
        if current.embeddings is not None:
            # a detection without an embedding (too small a crop) is judged without one
            log_odds = np.nan_to_num(self._identity_log_odds(self._tracks, current), nan=0.0)
            allowed &= log_odds >= _logit(c.reid_gate)
            score += c.reid_weight * log_odds
        similarity = np.where(allowed, score, -np.inf)
        for track in self._tracks:
            track.measured, track.detection = False, -1
        taken = np.zeros(len(dets), dtype=bool)
        confident = dets.probabilities >= c.low_confidence
        confirmed = np.array([t.confirmed for t in self._tracks], dtype=bool)
        for det_mask in (confident, ~confident):
            for track_mask in (confirmed, ~confirmed):
                free = np.array([not t.measured for t in self._tracks], dtype=bool)
                rows = np.flatnonzero(track_mask & free)
                cols = np.flatnonzero(det_mask & ~taken)
                if rows.size == 0 or cols.size == 0:
                    continue
                for r, col in assign(similarity[np.ix_(rows, cols)]):
                    track = self._tracks[rows[r]]
                    track.measured, track.detection = True, int(cols[col])
                    taken[cols[col]] = True
        self._reacquire(current, taken, confident)

    def _reacquire(self, current: _Frame, taken: np.ndarray, confident: np.ndarray) -> None:
        """Third round: a confirmed person who has gone without detections may take a leftover
        confident detection that is within walking reach of where it was last seen and that
        its colours match (its predicted box may have drifted out of overlap)."""
        c = self.config
        candidates = []
        for i, track in enumerate(self._tracks):
            if track.measured or not track.confirmed:
                continue
            for j in np.flatnonzero(confident & ~taken):
                score = self._recognition(
                    current, track, current.predicted[i], track.last_seen, int(j)
                )
                if score >= c.reid_min_score:
                    candidates.append((score, i, int(j)))
        for _, i, column in sorted(candidates, reverse=True):
            track = self._tracks[i]
            if track.measured or taken[column]:
                continue
            track.measured, track.detection = True, column
            taken[column] = True

    def _weigh_and_update(self, current: _Frame) -> None:
        c = self.config
        state = _known(self._state, "the people's particles")
        dets = current.detections
        self._restart_beyond_reach(state, current)
        log_lik = np.zeros(state.weights.shape)
        roots = current.roots
        # The probability that the associated detection is the person at all (its embedding
        # against the person's): a doubtful identity pulls the particles less.
        same = np.ones(len(self._tracks))
        if current.embeddings is not None and len(dets):
            columns = [max(t.detection, 0) for t in self._tracks]
            log_odds = self._identity_log_odds(self._tracks, current)[
                np.arange(len(self._tracks)), columns
            ]
            same = np.where(np.isnan(log_odds), 1.0, _sigmoid(log_odds))
        for i, track in enumerate(self._tracks):
            particles = state.particles[i]
            # Appearance: the person's RCSK response, read at every particle.
            log_lik[i] += c.appearance_weight * current.responses[i].at(particles[:, :2])
            if track.measured:
                log_lik[i] += detection_log_likelihood(
                    particles,
                    dets.boxes[track.detection],
                    float(dets.probabilities[track.detection] * same[i]),
                    sigma=c.detection_sigma,
                    log_height_sigma=c.detection_log_height_sigma,
                    clutter=c.clutter,
                )
        log_lik += self._dense_log_likelihood(current, state)
        measurement = self._part_measurements(current, state, roots)
        evidence = c.keypoint_evidence if self._pose is not None else 1.0
        state = update(state, log_lik, evidence_weight=evidence, **measurement)
        self._state = resample(state, self._rng)
        for track in self._tracks:
            if track.measured:
                box = dets.boxes[track.detection]
                if c.box_aspect is None:
                    track.aspect = 0.8 * track.aspect + 0.2 * float(box[2] / box[3])
                track.hits += 1
                track.last_seen = current.timestamp
                track.score = 0.7 * track.score + 0.3 * float(dets.probabilities[track.detection])
        current.boxes = self._predicted_boxes()
        cover = occluders(current.boxes, c.occlusion_overlap)
        for track, covered in zip(self._tracks, np.any(cover, axis=1), strict=True):
            track.occluded = bool(covered)

    def _dense_log_likelihood(self, current: _Frame, state: RbpfState) -> np.ndarray:
        """The detector's calibrated dense scores at every particle (``(T, N)``, zeros when the
        detector cannot score densely or is not calibrated)."""
        out = np.zeros(state.weights.shape)
        c = self.config
        calibration = getattr(self._detector, "calibration", None)
        if not c.dense_likelihood or self._detector is None or calibration is None:
            return out
        corners, usable = widened(current.predicted, current.image.shape, c.region_margin)
        low, high = c.region_heights
        for i in np.flatnonzero(usable):
            x0, y0, x1, y1 = corners[i].tolist()
            # the heights a region search looks for: the detector's own default would read
            # the widened region's height, twice the person's, and score levels no particle
            # reads
            height = float(current.predicted[i, 3])
            dense = self._detector.dense_scores(
                current.image, Box(x0, y0, x1 - x0, y1 - y0), (low * height, high * height)
            )
            if dense is None:
                continue
            particles = state.particles[i]
            raw = dense.lookup(particles[:, [CX, CY]], np.exp(particles[:, LOG_H]))
            out[i] = dense_score_log_likelihood(raw, calibration.a, calibration.b)
        return out

    def _part_measurements(
        self, current: _Frame, state: RbpfState, roots: np.ndarray
    ) -> dict[str, np.ndarray]:
        """Part measurements: a DPM detection's part placements where the person's detection
        has them, else the peaks of the person's part trackers; none for covered parts."""
        c = self.config
        if self._pose is not None:
            return self._keypoint_measurements(current, state, self._pose)
        z, found = part_model.from_detections(self._body, self._tracks, current.detections)
        heights = np.exp(roots[:, LOG_H])
        expected = part_model.positions(self._body, state)
        sigma = np.full(len(self._tracks), c.part_measurement_sigma)
        for t, track in enumerate(self._tracks):
            if track.parts is not None and not found[t].any():
                z[t], found[t] = track.parts.measure(current.image, expected[t], heights[t])
                sigma[t] = c.part_tracker_sigma
        boxes = boxes_from_roots(roots, np.array([t.aspect for t in self._tracks]))
        found &= ~part_model.hidden(self._body, state, boxes, c.occlusion_overlap)
        for track, placed in zip(self._tracks, found, strict=True):
            track.parts_measured = placed
        return part_model.filter_arguments(self._body, state, z, found, sigma)

    def _keypoint_measurements(
        self, current: _Frame, state: RbpfState, pose: PoseEstimator
    ) -> dict[str, np.ndarray]:
        """Part measurements from the pose network: the frame's skeletons (of the whole frame,
        or of a crop around each person when that costs the network less) assigned to the
        people (each person's associated detection box, else its predicted box), each keypoint
        measuring the part of its name with a noise from its heatmap value. The grouping of
        keypoints into skeletons decides whose a keypoint is, so a keypoint inside a nearer
        person's box still counts (a head above the shoulder of someone in front)."""
        # imported here: the pose module loads OpenVINO, which a tracker without one never needs
        from tracking.detection.pose import KEYPOINT_NAMES

        c = self.config
        boxes = current.predicted.copy()
        for i, track in enumerate(self._tracks):
            if track.measured:
                boxes[i] = current.detections.boxes[track.detection]
        if pose.crops_cheaper(current.image.shape, len(boxes)):
            crops = pose.estimate_crops(current.image, boxes)
            keypoints, scores, skeleton_of = skeletons_in_crops(
                [(crop.keypoints, crop.scores) for crop in crops],
                KEYPOINT_NAMES,
                boxes,
                c.skeleton_min_share,
            )
        else:
            poses = pose.estimate(current.image)
            keypoints, scores = poses.keypoints, poses.scores
            skeleton_of = assign_skeletons(keypoints, KEYPOINT_NAMES, boxes, c.skeleton_min_share)
        z, found, sigma = keypoint_measurements(
            self._body, KEYPOINT_NAMES, keypoints, scores, skeleton_of, c.keypoint_sigma
        )
        for track, placed, has in zip(self._tracks, found, skeleton_of >= 0, strict=True):
            track.parts_measured = placed
            track.parts_seen = placed if has else None
        return part_model.filter_arguments(self._body, state, z, found, sigma)

    def _identity_log_odds(self, tracks: list[_Track], current: _Frame) -> np.ndarray:
        """``(T, D)`` log odds that each detection shows each person, from the cosine of its
        embedding to the most similar of the person's gallery (the network's calibration);
        NaN where either has no embedding. Each person's row is computed once per frame (the
        association, the weights and the recognition of lost people all ask)."""
        embeddings = _known(current.embeddings, "the detections' embeddings")
        missing = [t for t in tracks if id(t) not in current.identity]
        if missing and len(embeddings):
            galleries = np.stack(  # (T, G, E)
                [_known(t.gallery, "a person's gallery") for t in missing]
            )
            with np.errstate(invalid="ignore"):
                cosine = np.einsum("tge,de->tgd", galleries, embeddings)
                best = np.max(np.where(np.isnan(cosine), -np.inf, cosine), axis=1)
            best[~np.isfinite(best)] = np.nan
            calibration = _known(self._reid, "the re-identification network").calibration
            for track, row in zip(missing, calibration.a * best + calibration.b, strict=True):
                current.identity[id(track)] = row
        if not tracks or len(embeddings) == 0:
            return np.zeros((len(tracks), len(embeddings)))
        return np.stack([current.identity[id(t)] for t in tracks])

    def _learn(self, current: _Frame) -> None:
        """Appearance learning at the estimate, only where a detection confirms the person and
        nobody covers it (an occluded person stops learning, docs/architecture.md §5): the RCSK
        model, the colour signature (from the associated detection's box) and the visible parts'
        trackers."""
        state = _known(self._state, "the people's particles")
        roots, _ = estimate(state)
        boxes = boxes_from_roots(roots, np.array([t.aspect for t in self._tracks]))
        positions = part_model.positions(self._body, state)
        covered = part_model.hidden(self._body, state, boxes, self.config.occlusion_overlap)
        for i, (track, root) in enumerate(zip(self._tracks, roots, strict=True)):
            if not track.measured or track.occluded:
                continue
            rate = self.config.signature_learning_rate
            seen = current.signatures[track.detection]
            signature = _known(track.signature, "a person's colours")
            track.signature = (1 - rate) * signature + rate * seen
            confident = current.detections.probabilities[track.detection] >= (
                self.config.low_confidence
            )
            if current.embeddings is not None and confident:
                self._remember(track, current.embeddings[track.detection], current)
            track.appearance.learn(
                current.image,
                (float(root[CX]), float(root[CY])),
                math.exp(root[LOG_H]) / track.base_height,
            )
            if track.parts is not None:
                track.parts.learn(current.image, positions[i], math.exp(root[LOG_H]), ~covered[i])

    def _manage(self, current: _Frame) -> None:
        """End, merge, confirm and start tracks."""
        c = self.config
        t = current.timestamp
        height, width = current.image.shape[:2]
        alive_flags = []
        boxes = (
            current.boxes if len(current.boxes) == len(self._tracks) else self._predicted_boxes()
        )
        for i, track in enumerate(self._tracks):
            box = boxes[i]
            cx, cy = box[0] + box[2] / 2, box[1] + box[3] / 2
            missing = t - track.last_seen
            limit = c.occluded_max_missing if track.occluded else c.max_missing
            if not track.confirmed and track.hits >= c.confirm_hits:
                self._confirm(track)
            inside = 0 <= cx < width and 0 <= cy < height
            if track.confirmed:
                alive = inside and missing <= limit
                if inside and not alive:
                    self._lost.append(_Lost(track, boxes[i].copy(), t))
            else:
                alive = inside and t - track.born <= c.confirm_window
                alive = alive and missing <= c.confirm_window / 2
            alive_flags.append(alive)
        keep = np.array(alive_flags, dtype=bool)
        # Duplicates: of two tracks on the same person, the younger ends. Two people crossing
        # overlap as much, but stand at different depths: a duplicate also has the same bottom
        # edge and height (within a tenth of the height).
        if len(self._tracks) > 1:
            overlap = box_iou(boxes, boxes)
            np.fill_diagonal(overlap, 0.0)
            bottom = boxes[:, 1] + boxes[:, 3]
            heights = boxes[:, 3]
            same_depth = np.abs(bottom[:, None] - bottom[None, :]) < 0.1 * heights[:, None]
            same_depth &= np.abs(np.log(heights[:, None] / heights[None, :])) < 0.1
            duplicate = np.triu(overlap > c.duplicate_iou) & same_depth
            for i, j in zip(*np.nonzero(duplicate), strict=True):
                younger = i if self._tracks[i].born > self._tracks[j].born else j
                keep[younger] = False
        self._remove(~keep)
        memory = c.reid_memory if self._reid is None else c.embedding_memory
        self._lost = [lost for lost in self._lost if t - lost.time <= memory]
        self._start_tracks(current)

    def _start_tracks(self, current: _Frame) -> None:
        c = self.config
        dets = current.detections
        if len(dets) == 0:
            return
        taken = np.zeros(len(dets), dtype=bool)
        for track in self._tracks:
            if track.measured and 0 <= track.detection < len(dets):
                taken[track.detection] = True
        existing = self._predicted_boxes()
        covered = np.zeros(len(dets), dtype=bool)
        if len(existing):
            covered = box_iou(with_aspect(dets.boxes), with_aspect(existing)).max(axis=1)
            covered = covered >= c.match_iou
            # A box around a group holds most of two or more smaller tracked people (one could
            # be a farther person behind a new nearer one). Detectors give these where people
            # walk close together; a track born on one spans the group.
            inside = covered_share(existing, dets.boxes).T >= 0.5  # (D, T)
            smaller = existing[None, :, 3] < 0.8 * dets.boxes[:, None, 3]
            covered |= (inside & smaller).sum(axis=1) >= 2
        height, width = current.image.shape[:2]
        centre_x = dets.boxes[:, 0] + dets.boxes[:, 2] / 2
        centre_y = dets.boxes[:, 1] + dets.boxes[:, 3] / 2
        inside = (centre_x >= 0) & (centre_x < width) & (centre_y >= 0) & (centre_y < height)
        inside &= (dets.boxes[:, 2] >= 2) & (dets.boxes[:, 3] >= 4)
        start = np.flatnonzero(
            ~taken & ~covered & inside & (dets.probabilities >= c.birth_confidence)
        )
        for index in start:
            self._add_track(current, int(index))

    def _add_track(self, current: _Frame, index: int) -> None:
        c = self.config
        box = current.detections.boxes[index]
        probability = float(current.detections.probabilities[index])
        x, y, w, h = (float(v) for v in box)
        lost = self._recognise(current, index)
        appearance = CorrelationTracker(c.appearance, features=self._features)
        appearance.initialize(current.image, Box(x, y, w, h))
        n = c.particles
        roots = np.empty((n, ROOT_DIM))
        roots[:, VX] = self._rng.normal(0, 0.5 * h, n)
        roots[:, VY] = self._rng.normal(0, 0.25 * h, n)
        self._place_at(roots, box)
        mean, cov = part_model.prior(self._body)
        born = RbpfState.from_prior(roots[None], mean, cov)
        if self._state is None:
            self._state = born
        else:
            s = self._state
            self._state = RbpfState(
                np.concatenate([s.particles, born.particles]),
                np.concatenate([s.weights, born.weights]),
                np.concatenate([s.mean, born.mean]),
                np.concatenate([s.cov, born.cov]),
            )
        track = _Track(
            track_id=0,
            appearance=appearance,
            base_height=h,
            aspect=w / h if c.box_aspect is None else PEDESTRIAN_ASPECT,
            born=current.timestamp,
            last_seen=current.timestamp,
            score=probability,
            measured=True,
            signature=current.signatures[index].copy(),
        )
        if current.embeddings is not None:
            track.gallery = np.full((c.reid_gallery, current.embeddings.shape[1]), np.nan)
            self._remember(track, current.embeddings[index], current)
        if c.part_appearance is not None and current.detections.parts.shape[1] == 0:
            track.parts = PartTrackers(
                c.part_appearance,
                self._body,
                _known(self._part_features, "the part trackers' features"),
                c.part_min_peak,
            )
            centre = np.array([x + w / 2, y + h / 2])
            track.parts.initialize(current.image, centre + h * self._body.mean, h)
        if lost is not None:
            # The same person again: the old id, confirmed at once, its history kept.
            track.track_id, track.confirmed, track.hits = lost.track_id, True, lost.hits
        elif c.confirm_hits <= 1:
            self._confirm(track)
        self._tracks.append(track)

    def _place_at(self, roots: np.ndarray, box: np.ndarray) -> None:
        """Draw the centres and log heights of ``roots`` ``(N, 5)`` about detection ``box`` with
        the detection's spread (``detection_sigma``, ``detection_log_height_sigma``)."""
        c, n = self.config, len(roots)
        x, y, w, h = (float(v) for v in box)
        roots[:, CX] = x + w / 2 + self._rng.normal(0, c.detection_sigma[0] * h, n)
        roots[:, CY] = y + h / 2 + self._rng.normal(0, c.detection_sigma[1] * h, n)
        roots[:, LOG_H] = math.log(h) + self._rng.normal(0, c.detection_log_height_sigma, n)

    def _restart_beyond_reach(self, state: RbpfState, current: _Frame) -> None:
        """Restart at its detection a person whose associated detection lies beyond its
        particles' reach (outside ``association_gate``): only the third round,
        :meth:`_reacquire`, associates such a pair, a person recognised after a camera jerk,
        a gap or a jump the motion model does not expect. Every particle's likelihood would
        sit at the clutter floor there, so none would be preferred: the particles would stay
        where they were and the person's box off the person. Detector-fused particle filters
        draw particles about the detections for this (the mixture proposal of Okuma et al.,
        "A boosted particle filter", ECCV 2004); here all of them, as the recognised person
        is where the detection is. Velocities and part filters are kept.

        On the held-out sequences of ``benchmarks/holdout_people.py`` (5 seeds, before the
        camera's motion was followed, ``PeopleTrackerConfig.camera_motion``), the share
        of frames where the annotated person is followed by its main track rose from 67.6 to
        74.8 (``ours+detbox+reid``; 65.3-69.9 to 74.9-77.5 for the other rows), most on a
        hand-held camera's Couple (25 to 52); the MOT sequences moved by -0.2 to +0.7 HOTA.
        """
        rows = np.flatnonzero([t.measured for t in self._tracks])
        columns = np.array([self._tracks[i].detection for i in rows], dtype=np.int64)
        # the association's predictive log likelihoods, of these particles and detections
        far = current.fit[rows, columns] < -0.5 * self.config.association_gate
        for i, column in zip(rows[far], columns[far], strict=True):
            self._place_at(state.particles[i], current.detections.boxes[column])
            state.weights[i] = 1.0 / state.weights.shape[1]

    @staticmethod
    def _remember(track: _Track, embedding: np.ndarray, current: _Frame) -> None:
        """Put an embedding in the person's gallery in place of its oldest (the frame's log
        odds for the person, if any, no longer hold)."""
        current.identity.pop(id(track), None)
        if track.gallery is None or not np.all(np.isfinite(embedding)):
            return
        track.gallery[track.gallery_next] = embedding
        track.gallery_next = (track.gallery_next + 1) % len(track.gallery)

    def _confirm(self, track: _Track) -> None:
        """Make a tentative track a person, with the next id."""
        track.track_id, track.confirmed = self._next_id, True
        self._next_id += 1

    def _recognise(self, current: _Frame, index: int) -> _Track | None:
        """The lost person detection ``index`` most likely is, if any (see
        :meth:`_recognition`)."""
        scores = [
            self._recognition(current, lost.track, lost.box, lost.time, index)
            for lost in self._lost
        ]
        if not scores or max(scores) < self.config.reid_min_score:
            return None
        return self._lost.pop(int(np.argmax(scores))).track

    def _recognition(
        self, current: _Frame, track: _Track, box: np.ndarray, since: float, index: int
    ) -> float:
        """How likely detection ``index`` is ``track``'s person, expected at ``box`` and last
        detected at time ``since``: the similarity of their clothing colours
        (:mod:`tracking.people.identity`) minus the distance between detection and ``box`` in
        heights; ``-inf`` when the person cannot have walked there or is of another size.
        With a re-identification network, the calibrated probability that the embeddings show
        the same person (at least ``reid_min_probability``) minus the distance as a share of
        how far the person can have walked (a person may come back far from where it was lost,
        after a long time).

        Measured on PETS09-S2L1's re-appearances, the same person is a median 0.42 heights from
        where it was lost, another 0.70; colour similarities are 0.80 against 0.39.
        """
        c = self.config
        found = current.detections.boxes[index]
        gap = current.timestamp - since
        cx, cy = found[0] + found[2] / 2, found[1] + found[3] / 2
        lx, ly = box[0] + box[2] / 2, box[1] + box[3] / 2
        distance = math.hypot(cx - lx, cy - ly) / box[3]
        reach = c.reid_max_speed * max(gap, 0.1) + 0.5
        if distance > reach or abs(math.log(found[3] / box[3])) > 0.4:
            return -math.inf
        if current.embeddings is not None:
            log_odds = self._identity_log_odds([track], current)[0, index]
            same = 0.0 if np.isnan(log_odds) else _sigmoid(log_odds)
            return -math.inf if same < c.reid_min_probability else same - distance / reach
        signature = _known(track.signature, "a person's colours")
        colour = signature_similarity(signature, current.signatures[index])[0, 0]
        return float(colour) - distance

    def _remove(self, drop: np.ndarray) -> None:
        if not np.any(drop):
            return
        keep = ~drop
        self._tracks = [t for t, k in zip(self._tracks, keep, strict=True) if k]
        if not self._tracks:
            self._state = None
            return
        s = _known(self._state, "the people's particles")
        self._state = RbpfState(s.particles[keep], s.weights[keep], s.mean[keep], s.cov[keep])

    def _report(self, current: _Frame) -> FrameTracks:
        """The confirmed people to report in this frame, as columns: boxes from the particle
        estimate of the roots, parts at the body model's positions given the roots, visible
        unless covered by a nearer person or outside the frame."""
        index = self._frames_tracked
        if self._state is None:
            return FrameTracks.empty(index, current.timestamp, self._body.names)
        c = self.config
        roots, _ = estimate(self._state)
        aspect = np.array([t.aspect for t in self._tracks])
        boxes = boxes_from_roots(roots, aspect)
        report_boxes = boxes if c.box_aspect is None else with_aspect(boxes, c.box_aspect)
        positions = part_model.positions(self._body, self._state)  # (T, P, 2)
        cover = occluders(boxes, c.occlusion_overlap)
        hidden = hidden_points(positions, cover, boxes)
        height, width = current.image.shape[:2]
        outside = (
            (positions[..., 0] < 0)
            | (positions[..., 0] >= width)
            | (positions[..., 1] < 0)
            | (positions[..., 1] >= height)
        )
        missing = [current.timestamp - t.last_seen for t in self._tracks]
        keep = np.array(
            [
                track.confirmed
                and not (gone > c.report_missing and not (track.occluded and c.report_occluded))
                for track, gone in zip(self._tracks, missing, strict=True)
            ],
            dtype=bool,
        )
        kept = [t for t, k in zip(self._tracks, keep, strict=True) if k]
        out_boxes = report_boxes[keep]
        xy = positions[keep]
        # part boxes of the body model's size for the person's height, centred on the part
        size = self._body.size[None, :, :] * out_boxes[:, 3, None, None]  # (N, P, 2)
        part_boxes = np.concatenate([xy - size / 2.0, size], axis=-1)
        beyond = outside[keep]
        visible = ~(hidden[keep] | beyond)
        measured = np.zeros(visible.shape, dtype=bool)
        for row, track in enumerate(kept):
            if track.parts_seen is not None:  # a skeleton was assigned: its keypoints say
                visible[row] = np.asarray(track.parts_seen, bool) & ~beyond[row]
            if track.parts_measured is not None:
                measured[row] = np.asarray(track.parts_measured, bool)
        # Confidence fades while the person goes without detections.
        scale = max(c.max_missing, 1e-6)
        scores = [
            t.score * math.exp(-gone / scale)
            for t, gone, k in zip(self._tracks, missing, keep, strict=True)
            if k
        ]
        return FrameTracks(
            index,
            current.timestamp,
            track_ids=np.array([t.track_id for t in kept], dtype=np.int64),
            boxes=out_boxes,
            scores=np.array(scores, dtype=np.float64),
            occluded=np.array([t.occluded for t in kept], dtype=bool),
            interpolated=np.zeros(len(kept), dtype=bool),
            part_names=self._body.names,
            part_xy=xy,
            part_boxes=part_boxes,
            part_visible=visible,
            part_measured=measured,
        )


def _known(value: _T | None, what: str) -> _T:
    """``value``, which the tracker sets before any step that uses it; RuntimeError if it is
    not set (a step run out of order)."""
    if value is None:
        raise RuntimeError(f"{what} used before it is set")
    return value


def _sigmoid(x: np.ndarray | float) -> np.ndarray | float:
    return 1.0 / (1.0 + np.exp(-x))


def _logit(p: float) -> float:
    return -math.inf if p <= 0 else math.log(p / (1.0 - p))


def _check_arguments(config: object, detector: object) -> None:
    """A config and a detector of the right kinds, or a TypeError that says which went where
    (``MultiPersonTracker(detector)`` reads the detector as the config, ``PeoplePipeline``
    takes the detector first)."""
    if config is not None and not isinstance(config, PeopleTrackerConfig):
        hint = " (pass a detector as detector=...)" if hasattr(config, "detect") else ""
        raise TypeError(f"config must be a PeopleTrackerConfig, got {type(config).__name__}{hint}")
    if detector is not None and not callable(getattr(detector, "detect", None)):
        hint = " (pass it as config=...)" if isinstance(detector, PeopleTrackerConfig) else ""
        raise TypeError(
            f"detector must be a Detector (with detect()), got {type(detector).__name__}{hint}"
        )
