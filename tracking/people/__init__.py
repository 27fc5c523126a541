"""Multi-person tracking with parts: the detector-fused Rao-Blackwellized particle filter of
thesis Part II (docs/architecture.md §5)."""

from tracking.people.body import EMBEDDED_BODY, POSE_BODY, BodyModel, deformation_prior
from tracking.people.config import PeopleTrackerConfig
from tracking.people.tracker import MultiPersonTracker

__all__ = [
    "EMBEDDED_BODY",
    "POSE_BODY",
    "BodyModel",
    "MultiPersonTracker",
    "PeopleTrackerConfig",
    "deformation_prior",
]
