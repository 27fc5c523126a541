"""The one object that turns frames into per-frame track states (docs/architecture.md §2).

Both the upload worker and the stream worker drive a :class:`FramePipeline`: they hand it frames
with their capture timestamps (and, optionally, detections from an upstream detector) and get
:class:`~tracking.tracks.FrameTracks` back. Which tracker runs behind it is the pipeline's
business: a single object from a first box (thesis Part I), or every person in view (Part II).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import TYPE_CHECKING, Protocol, runtime_checkable

import numpy as np

from tracking.correlation import CorrelationConfig, CorrelationTracker
from tracking.detection.base import Detections, Detector
from tracking.people import MultiPersonTracker, PeopleTrackerConfig
from tracking.tracks import FrameTracks
from tracking.types import Box, TrackerOutput, as_box, checked_timestamp

if TYPE_CHECKING:
    from tracking.detection.pose import PoseEstimator
    from tracking.detection.reid import ReidEmbedder

__all__ = ["FramePipeline", "PeoplePipeline", "SingleTargetPipeline"]


@runtime_checkable
class FramePipeline(Protocol):
    """Frames in, tracks out, one frame at a time."""

    @property
    def part_names(self) -> tuple[str, ...]:
        """Names of the body parts the tracks carry (empty when they carry none)."""
        ...

    @property
    def skeleton(self) -> tuple[tuple[str, str], ...]:
        """Pairs of :attr:`part_names` joined by a limb, for drawing (empty: none)."""
        ...

    def prepare(self) -> None:
        """Do now the one-off work the first frames would do (compiling networks for the
        shapes they will take), for a live stream that would drop frames meanwhile."""
        ...

    def process(
        self, frame: np.ndarray, timestamp: float, detections: Detections | None = None
    ) -> FrameTracks:
        """Track one RGB frame captured at ``timestamp`` seconds.

        Raises
        ------
        ValueError
            For a malformed frame, a timestamp that is not finite or before the previous one,
            or detections where the pipeline takes none.
        TypeError
            For a frame that is not uint8 or a timestamp that is not a number.
        """
        ...


class SingleTargetPipeline:
    """One object followed from its first-frame box by a correlation tracker (thesis Part I).

    The object's track has id 1; its score is the correlation peak, clipped to ``[0, 1]``;
    it is occluded where the tracker's failure signal says the target looks hidden or lost.
    ``first_box`` is a :class:`Box` or four numbers ``(x, y, w, h)``; ``config`` a
    :class:`CorrelationConfig` or a preset's name (:data:`tracking.correlation.PRESETS`).
    """

    def __init__(
        self, first_box: Box | Sequence[float], config: CorrelationConfig | str | None = None
    ) -> None:
        self._tracker = CorrelationTracker(config)
        self._first_box = as_box(first_box)
        self._index = 0
        self._started = False
        self._timestamp: float | None = None
        self._last_output: TrackerOutput | None = None

    @property
    def last_output(self) -> TrackerOutput | None:
        """What the correlation tracker said of the last frame (its unclipped peak, its PSR);
        None before the second frame: the first is the given box."""
        return self._last_output

    @property
    def part_names(self) -> tuple[str, ...]:
        return ()

    @property
    def skeleton(self) -> tuple[tuple[str, str], ...]:
        return ()

    def prepare(self) -> None:
        """Nothing: the correlation tracker compiles nothing."""

    def process(
        self, frame: np.ndarray, timestamp: float, detections: Detections | None = None
    ) -> FrameTracks:
        if detections is not None:
            raise ValueError("single-target tracking takes no detections")
        self._timestamp = checked_timestamp(timestamp, self._timestamp)
        if not self._started:
            self._tracker.initialize(frame, self._first_box)
            self._started = True
            box, score, occluded = self._first_box, 1.0, False
        else:
            out = self._last_output = self._tracker.update(frame)
            box, score, occluded = out.box, float(np.clip(out.peak, 0.0, 1.0)), out.occluded
        result = FrameTracks(
            self._index,
            float(timestamp),
            track_ids=np.ones(1, dtype=np.int64),
            boxes=box.as_array()[None],
            scores=np.array([score]),
            occluded=np.array([occluded]),
            interpolated=np.zeros(1, dtype=bool),
            part_names=(),
            part_xy=np.zeros((1, 0, 2)),
            part_boxes=np.zeros((1, 0, 4)),
            part_visible=np.zeros((1, 0), dtype=bool),
            part_measured=np.zeros((1, 0), dtype=bool),
        )
        self._index += 1
        return result


class PeoplePipeline:
    """Every person in view, with parts and occlusion (thesis Part II, docs/architecture.md §5).

    Parameters
    ----------
    detector:
        Runs when a frame comes without detections; ``None`` requires detections every frame.
    config:
        The multi-person tracker's parameters.
    pose:
        A body-keypoint network whose keypoints measure every person's parts (the parts are
        then its 18 keypoints); ``None``: parts from the detector or the body model.
    reid:
        A re-identification network that tells people apart and recognises them when they
        come back; ``None``: clothing colours do.
    """

    def __init__(
        self,
        detector: Detector | None = None,
        config: PeopleTrackerConfig | None = None,
        pose: PoseEstimator | None = None,
        reid: ReidEmbedder | None = None,
    ) -> None:
        self._tracker = MultiPersonTracker(config, detector=detector, pose=pose, reid=reid)

    @property
    def part_names(self) -> tuple[str, ...]:
        return self._tracker.part_names

    @property
    def skeleton(self) -> tuple[tuple[str, str], ...]:
        return self._tracker.skeleton

    def prepare(self) -> None:
        self._tracker.prepare()

    def process(
        self, frame: np.ndarray, timestamp: float, detections: Detections | None = None
    ) -> FrameTracks:
        # the tracker numbers the frames it tracked from 0, as the pipeline does
        return self._tracker.update(frame, timestamp, detections)
