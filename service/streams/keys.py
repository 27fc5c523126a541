"""The key expressions of one camera (the contract is documented in :mod:`api_schemas.streams`)."""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True, slots=True)
class StreamKeys:
    """Key expressions of camera ``camera`` under ``prefix``."""

    prefix: str
    camera: str

    @property
    def frames(self) -> str:
        return f"{self.prefix}/cameras/{self.camera}/frames"

    @property
    def detections(self) -> str:
        return f"{self.prefix}/cameras/{self.camera}/detections"

    @property
    def tracks(self) -> str:
        return f"{self.prefix}/cameras/{self.camera}/tracks"

    @property
    def ended(self) -> str:
        """Where the worker says that the tracks ended."""
        return f"{self.prefix}/cameras/{self.camera}/tracks/ended"

    @property
    def current(self) -> str:
        """The queryable that answers with the latest tracks message."""
        return f"{self.prefix}/cameras/{self.camera}/tracks/current"

    @property
    def events(self) -> str:
        """What people did at the camera's zones and lines (one sample per event)."""
        return f"{self.prefix}/cameras/{self.camera}/events"

    @property
    def trackers(self) -> str:
        """Liveliness tokens of every instance that tracks this camera."""
        return f"{self.prefix}/trackers/{self.camera}/*"

    def tracker_token(self, instance: str) -> str:
        return f"{self.prefix}/trackers/{self.camera}/{instance}"

    def as_dict(self) -> dict[str, str]:
        return {
            "frames": self.frames,
            "detections": self.detections,
            "tracks": self.tracks,
            "ended": self.ended,
            "current": self.current,
            "events": self.events,
            "trackers": self.trackers,
        }
