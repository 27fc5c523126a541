"""Every tunable number of the multi-person tracker (docs/architecture.md §5), in one frozen
object."""

from __future__ import annotations

from dataclasses import dataclass, field

from tracking.correlation.config import CorrelationConfig


def _appearance_default() -> CorrelationConfig:
    # RCSK (thesis ch. 2) on grayscale + Color Names, the thesis's proposed features, averaged on
    # 4-pixel cells and capped at 1600 pixels: a person's appearance in about 0.3 ms per frame.
    return CorrelationConfig(
        learner="rcsk",
        feature="gray+cn",
        cell_size=4,
        padding=1.0,
        learning_rate=0.05,
        max_patch_area=1600,
    )


def default_part_appearance() -> CorrelationConfig:
    """A part tracker for ``PeopleTrackerConfig.part_appearance``: parts are small (a tenth of a
    person's height), so grayscale + Color Names per pixel, the patch at most 256 pixels."""
    return CorrelationConfig(
        learner="rcsk", feature="gray+cn", padding=1.0, learning_rate=0.05, max_patch_area=256
    )


@dataclass(frozen=True, slots=True)
class PeopleTrackerConfig:
    """Parameters of :class:`tracking.people.MultiPersonTracker`.

    Times are in seconds (streams drop frames, so nothing counts frames); lengths are in units
    of the person's height unless they say pixels.

    Attributes
    ----------
    particles:
        Particles per person (the non-linear root state: centre, log height, velocity).
    position_noise:
        Standard deviation of the centre's random acceleration, in heights per second: the
        process noise of the constant-velocity model, proportional to the person's height.
    velocity_damping:
        Per second, the share of the velocity kept (1: pure constant velocity); damping keeps
        a person without measurements from coasting away.
    log_height_noise:
        Standard deviation of the random walk of log height per square-root second.
    occluded_noise_gain:
        Factor on the process noise while the person is occluded (its uncertainty grows).
    detection_sigma:
        Standard deviations ``(x, y)``, in heights, of a detection's centre about the person's.
        Detectors place a person's centre more precisely across than along the body: measured
        on the public detections of PETS09-S2L1 and TUD-Stadtmitte against their ground truth,
        0.04-0.05 heights across and 0.10-0.12 along.
    detection_log_height_sigma:
        Standard deviation of a detection's log height about the person's (measured the same
        way: 0.17-0.23).
    clutter:
        Likelihood floor against a wrong detection (relative to the peak of a matching one):
        keeps a bad association from collapsing the particles. Small, because association
        already gates detections: a larger floor (0.05 puts it 2.4 standard deviations out)
        lets particles that strayed from an associated detection ignore it and drift on.
    appearance_weight:
        Exponent on the appearance likelihood: ``exp(appearance_weight * response)`` at each
        particle, the response of the person's RCSK tracker (Part I).
    appearance:
        The RCSK tracker that models each person's appearance.
    box_aspect:
        Width / height of the reported boxes. Detectors pad their boxes by different amounts
        (the public detections of these sequences are 1.5-1.8 times wider than the people), so
        the default is the standard pedestrian aspect 0.41 (Dollár, Wojek, Schiele, Perona, PAMI
        2012, who normalise every pedestrian box to it for evaluation); ``None`` follows the
        associated detections' aspect, for detectors whose boxes fit the people (the service
        sets it for the CNN detector: with its detections on PETS09-S2L1 and TUD-Stadtmitte,
        HOTA 62.0 against 61.4 at 0.41, 3 seeds; TUD-Stadtmitte alone 58.1 against 54.2).
    match_iou:
        Least overlap between a person's predicted box and a detection to associate them (both
        brought to the aspect 0.41 first).
    identity_weight:
        Weight of the clothing-colour similarity (:mod:`tracking.people.identity`, 0 to 1) in
        the association score, beside the predictive and appearance log likelihoods: colours
        keep two people apart where their paths cross.
    identity_gate:
        Least colour similarity between a person and a detection for them to be associated
        (the same person scores a median 0.8, two people 0.4-0.5): a detection that merges two
        people or belongs to someone else does not drag the track away.
    association_gate:
        Largest squared Mahalanobis distance (centre across and along, log height; in the
        detection's standard deviations, averaged over the person's particles) at which a
        detection may be associated with a person: 11.3 is the 99% point of a chi-square with
        three degrees of freedom.
    low_confidence:
        Detections below this calibrated probability are only used to continue existing tracks
        (second association round), never to start one.
    birth_confidence:
        Least calibrated probability of a detection that may start a track. BoT-SORT's 0.7
        (5 seeds, with re-identification): public TUD-Stadtmitte's false positives fall from
        70 to 46 (small boxes of unannotated people far behind), but PETS09-S2L1 loses a HOTA
        point on both the public and the CNN's detections; 0.8 is no better.
    confirm_hits:
        Associations needed, within ``confirm_window`` seconds of its start, before a track is
        reported. 2 (ByteTrack's) was measured against 3 (2026-12-07, ``benchmarks/mot.py``
        protocol, 5 seeds, with re-identification): HOTA within 0.6 on every row (CNN
        TUD-Stadtmitte +0.6, public PETS09-S2L1 -0.4), public TUD-Stadtmitte 23 more false
        positives; not kept.
    confirm_window:
        See ``confirm_hits``; a tentative track not confirmed in time is dropped.
    max_missing:
        A confirmed track without an associated detection for this long ends.
    occluded_max_missing:
        The same while the track is occluded (the death timeout extends).
    report_missing:
        A track is reported only while it lacks detections for at most this long, unless a
        nearer person covers it (then it is reported, flagged occluded, until it ends); other
        gaps are carried silently until the track is found again or ends. Boxes predicted
        through an unexplained gap are rarely on the person, so the default reports none.
    report_occluded:
        Report a person that a nearer one covers, flagged occluded, even without a detection.
    reid_memory:
        Seconds a lost person (a confirmed track that ended for lack of detections) is
        remembered: a new person who appears within that time where the lost one could have
        walked, and whom the lost one's appearance model recognises, takes the lost one's id.
    reid_min_score:
        Least recognition score for a new person to be a lost one: the similarity of their
        clothing colours (Bhattacharyya coefficient, 1 for the same colours; the same person
        scores a median 0.8, two people 0.4-0.5) minus the distance between them in heights.
    signature_learning_rate:
        Share of a new unoccluded detection's colours in a person's colour signature.
    reid_max_speed:
        Fastest plausible walking speed, in heights per second, bounding where a lost person
        can have gone.
    duplicate_iou:
        Two tracks whose boxes overlap this much are the same person: the younger one ends.
    occlusion_overlap:
        Share of a person's box that a nearer person (lower box bottom) must cover for it to be
        occluded.
    part_process_noise:
        Standard deviation of a part's offset random walk per square-root second, in heights.
    part_measurement_sigma:
        Standard deviation of a part measurement (DPM part placement), in heights.
    part_prior_gain:
        Per second, how strongly a part offset returns to its body-model mean (AR(1)).
    part_appearance:
        The small RCSK tracker that follows each body part when the detector gives no part
        boxes (its peak is the part's measurement; :func:`default_part_appearance` gives one);
        ``None`` (the default) leaves such parts to the body model. Measured on PETS09-S2L1 and
        TUD-Stadtmitte with the public detections, part trackers cost three quarters of the
        speed and 1-4 HOTA points: a patch a tenth of a person tall is easily confused, and its
        errors reach the root through the parts' evidence. They help where people are large.
    part_min_peak:
        A part tracker's response below this gives no measurement.
    part_tracker_sigma:
        Standard deviation, in heights, of a part tracker's measurement: larger than a DPM part
        placement's, since a patch a tenth of a person tall is easily confused.
    keypoint_sigma:
        Standard deviation, in heights, of a body keypoint's measurement (pose network) whose
        heatmap value is 1; a weaker keypoint's is this divided by its value (floored at 0.1).
        The network places joints at 2 input pixels and its heatmaps' peaks are about 0.02
        heights wide for the people of PETS09-S2L1 (about 100 pixels tall).
    keypoint_evidence:
        Weight of the keypoints' evidence in the particles' weights (the exponent on their
        Kalman marginal likelihoods, :func:`tracking.filtering.update`): 0 (default) lets the
        keypoints place the parts, per particle, while the root follows the detections and
        the appearance alone. Measured with the CNN detector on PETS09-S2L1 and
        TUD-Stadtmitte (3 seeds): HOTA 61.4 combined at 0, 57.9 at 0.2 and 54.8 at 1 (the
        full Rao-Blackwellized weight); the pose body model's mean offsets differ from where
        the keypoints sit in the detector's boxes (ankles 0.40 of the box height below its
        centre, not 0.46), and their evidence moves the boxes off the people. With offsets and
        spreads fitted to the CNN's boxes, 59.0 at 1 and 56.6 at 0.3: still below, with half
        again as many identity switches on PETS09-S2L1 (25 against 15), where a skeleton given
        to the wrong one of two crossing people pulls that person along.
    skeleton_min_share:
        Least share of a skeleton's keypoints inside a person's (widened) box for the skeleton
        to be that person's (:func:`tracking.people.keypoints.assign_skeletons`).
    reid_weight:
        Weight of the re-identification log likelihood ratio (``a cos + b`` of the network's
        calibration, :data:`tracking.detection.reid.KNOWN_REID_CALIBRATIONS`) in the association
        score, when the tracker has a re-identification network, beside the clothing colours
        (``identity_weight``). Measured with the CNN detector's detections on PETS09-S2L1 and
        TUD-Stadtmitte (3 seeds, boxes of 0.41 aspect), the embeddings in place of the colours
        scored lower than both together; the association term and the detection's identity
        probability in the particles' weights each helped (HOTA 59.7 without the first, 58.2
        without the second, 60.2 with both; no re-identification: 61.4), with ``reid_gate``
        0.01. With the gate at 0.1 (2026-12-07, 5 seeds, the detections' aspect), it gains over
        no re-identification: HOTA 63.3 -> 64.8 on PETS09-S2L1 and 56.3 -> 59.1 on
        TUD-Stadtmitte, IDF1 85.8 -> 88.1 and 78.0 -> 82.5; it is also what recognises people
        after long gaps (``reid_min_probability``).
    reid_gate:
        Least calibrated probability that a detection shows the person (by the embeddings'
        cosine) for them to be associated. Below 0.1, a person whose own detection is missing
        (covered in a group, or gone) takes another's that the embeddings give a probability
        of 0.06-0.27 (traced on TUD-Stadtmitte), and from then on follows that person.
        Measured with ``ours+reid`` on the public detections and ``ours+detbox+reid`` on the
        CNN's, PETS09-S2L1 and TUD-Stadtmitte, 5 seeds (``benchmarks/mot.py`` protocol), HOTA
        of both sequences together, public / CNN: 53.6 / 61.7 at 0.01, 54.5 / 62.1 at 0.05,
        54.9 / 63.8 at 0.1, 53.9 / 62.7 at 0.2, 53.8 / 61.3 at 0.5. 0.1 gains on PETS09-S2L1
        (CNN: HOTA +2.5, IDF1 +4.8) and loses nothing on TUD-Stadtmitte (CNN +0.3 / -0.3,
        public +0.6 / +2.4). Tried beside it and not kept: a stricter gate (0.5, 0.9) for a
        person who missed the previous frame, as StrongSORT's cascade matches such tracks by
        appearance only (TUD-Stadtmitte's CNN HOTA 61.3, but PETS09-S2L1's 63.0 against
        64.8: its people come back from occlusions looking different); a gallery that learns
        only detections it recognises (probability 0.5 or 0.9: HOTA down 0.6-1.5);
        ``reid_weight`` 2 or ``identity_weight`` 15 (within 0.2 HOTA).
    reid_gallery:
        Embeddings kept per person (the latest, taken only while the person is detected,
        confident and unoccluded); a detection is compared with the most similar.
    reid_min_probability:
        Least calibrated probability that a detection shows a lost person (its embedding
        against the person's gallery) for it to take the lost person's id. With the CNN
        detector's detections, the boxes' own aspect and 3 seeds: HOTA 59.1 / IDF1 79.9 over
        both sequences with no such floor (the colours' 0.1 score, which a tenth of two
        people's pairs pass), 61.1 / 82.8 at 0.5, 61.0 / 81.7 at 0.9, and 62.0 / 84.5 without
        re-identification; of five PETS09-S2L1 people hidden for 2 s by a board, 4 keep their
        ids at 0.5, 3 at 0.9, 2 without re-identification
        (``tests/people/test_pose_reid.py``).
    embedding_memory:
        Seconds a lost person is remembered when the tracker has a re-identification network
        (``reid_memory`` otherwise): embeddings recognise a person who comes back after a long
        occlusion or after leaving the frame.
    camera_motion:
        Move the people's particles with the camera's own motion between frames before
        predicting them (:mod:`tracking.people.camera_motion`, BoT-SORT's global motion
        compensation; about 2.4 ms per 768x576 frame). A static camera gets no move (the
        estimate wanders by under half a pixel there), so PETS09-S2L1 and TUD-Stadtmitte give
        the same results with it. Measured 2026-12-07 on the people of
        ``benchmarks/holdout_people.py`` (5 seeds, CNN detections): the share of the frames
        where the annotated person is kept by its main track rose from 74.8 to 85.3 for
        ``ours+detbox+reid`` (75-78 to 77-82 for the other rows); on a hand-held camera's
        Couple from 52 to 86.
    dense_likelihood:
        When the detector can score densely (the DPM engine and the embedded detector), weigh
        each particle by the detector's calibrated score at its position and height, read over
        the region and heights a region search would scan (``region_margin``,
        ``region_heights``): the image likelihood of docs/architecture.md §5. Otherwise only
        associated detections count. Off by default: with the embedded detector it costs 28 ms
        per person and frame on PETS09-S2L1 and lowers HOTA from 48.7 to 42.0 on PETS09-S2L1 and
        TUD-Stadtmitte together (the scores say "a person", not "this person", and draw
        particles onto neighbours; docs/benchmarks-history.md).
    full_detection_interval:
        Seconds between full-frame detections when the tracker runs its own detector; in
        between, only regions around the tracks are searched
        (:func:`tracking.people.scheduling.search_regions`), at a fraction of a full
        search's cost. People who enter are found at the next full search. 0 (default): every
        frame in full (docs/benchmarks-history.md measures 0.2 and 0.5 against it).
    region_margin:
        Margin, in heights, around a track's box when searching a region of interest.
    region_heights:
        Heights of the people a region of interest is searched for, as fractions of the
        track's predicted height (0.8-1.25: about six pyramid levels of the DPM, five of the
        embedded detector).
    seed:
        Seed of the particle filter's random generator (runs are reproducible).
    """

    particles: int = 128
    position_noise: float = 1.0
    velocity_damping: float = 0.5
    log_height_noise: float = 0.05
    occluded_noise_gain: float = 2.0
    detection_sigma: tuple[float, float] = (0.05, 0.1)
    detection_log_height_sigma: float = 0.2
    clutter: float = 0.001
    appearance_weight: float = 3.0
    appearance: CorrelationConfig = field(default_factory=_appearance_default)
    box_aspect: float | None = 0.41
    match_iou: float = 0.3
    association_gate: float = 11.3
    low_confidence: float = 0.6
    birth_confidence: float = 0.6
    confirm_hits: int = 3
    confirm_window: float = 1.0
    max_missing: float = 1.5
    occluded_max_missing: float = 3.0
    report_missing: float = 0.0
    report_occluded: bool = False
    reid_memory: float = 6.0
    identity_weight: float = 30.0
    identity_gate: float = 0.55
    reid_min_score: float = 0.1
    signature_learning_rate: float = 0.1
    reid_max_speed: float = 1.5
    duplicate_iou: float = 0.7
    occlusion_overlap: float = 0.3
    part_process_noise: float = 0.03
    part_measurement_sigma: float = 0.04
    part_prior_gain: float = 1.0
    part_appearance: CorrelationConfig | None = None
    part_min_peak: float = 0.2
    part_tracker_sigma: float = 0.1
    keypoint_sigma: float = 0.02
    keypoint_evidence: float = 0.0
    skeleton_min_share: float = 0.6
    reid_weight: float = 1.0
    reid_gate: float = 0.1
    reid_gallery: int = 10
    embedding_memory: float = 30.0
    reid_min_probability: float = 0.5
    camera_motion: bool = True
    dense_likelihood: bool = False
    full_detection_interval: float = 0.0
    region_margin: float = 0.5
    region_heights: tuple[float, float] = (0.8, 1.25)
    seed: int = 0

    def __post_init__(self) -> None:
        if self.particles < 2:
            raise ValueError(f"particles must be >= 2, got {self.particles}")
        if min(self.detection_sigma) <= 0:
            raise ValueError(f"detection_sigma must be positive, got {self.detection_sigma}")
        positive = (
            "position_noise",
            "log_height_noise",
            "detection_log_height_sigma",
            "part_measurement_sigma",
            "keypoint_sigma",
        )
        for name in positive:
            if getattr(self, name) <= 0:
                raise ValueError(f"{name} must be positive, got {getattr(self, name)}")
        for name in ("match_iou", "duplicate_iou", "occlusion_overlap"):
            if not 0.0 < getattr(self, name) <= 1.0:
                raise ValueError(f"{name} must be in (0, 1], got {getattr(self, name)}")
        if not 0.0 <= self.identity_gate <= 1.0:
            raise ValueError(f"identity_gate must be in [0, 1], got {self.identity_gate}")
        if not 0.0 < self.signature_learning_rate <= 1.0:
            raise ValueError(
                f"signature_learning_rate must be in (0, 1], got {self.signature_learning_rate}"
            )
        if self.identity_weight < 0 or self.association_gate <= 0:
            raise ValueError("need identity_weight >= 0 and association_gate > 0")
        if not 0.0 <= self.velocity_damping <= 1.0:
            raise ValueError(f"velocity_damping must be in [0, 1], got {self.velocity_damping}")
        if not 0.0 <= self.keypoint_evidence <= 1.0:
            raise ValueError(f"keypoint_evidence must be in [0, 1], got {self.keypoint_evidence}")
        if not 0.0 < self.skeleton_min_share <= 1.0 or not 0.0 <= self.reid_gate < 1.0:
            raise ValueError("need 0 < skeleton_min_share <= 1 and 0 <= reid_gate < 1")
        if not 0.0 <= self.reid_min_probability <= 1.0:
            raise ValueError(
                f"reid_min_probability must be in [0, 1], got {self.reid_min_probability}"
            )
        if self.reid_gallery < 1 or self.reid_weight < 0:
            raise ValueError("need reid_gallery >= 1 and reid_weight >= 0")
        if self.confirm_hits < 1:
            raise ValueError(f"confirm_hits must be >= 1, got {self.confirm_hits}")
        low, high = self.region_heights
        if not 0 < low <= high:
            raise ValueError(f"region_heights must be 0 < low <= high, got {self.region_heights}")
        if self.max_missing < 0 or self.occluded_max_missing < self.max_missing:
            raise ValueError("need 0 <= max_missing <= occluded_max_missing")
