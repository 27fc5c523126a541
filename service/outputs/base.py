"""What every result writer has in common."""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Literal, Protocol

from api_schemas.analytics import AnalyticsEvent, AnalyticsResult
from api_schemas.jobs import JobOptions, OutputFormat
from api_schemas.tracks import FrameTracksMessage, TrackState, VideoInfo
from service.frames import TimedFrame
from tracking.analytics import AnalyticsConfig

RESULT_FILES: dict[OutputFormat, str] = {
    OutputFormat.json: "trajectories.json",
    OutputFormat.mcap: "tracks.mcap",
    OutputFormat.mot: "tracks_mot.txt",
    OutputFormat.mp4: "annotated.mp4",
}
"""File name of each format inside a result folder."""

ANALYTICS_FILE = "analytics.json"
"""The events and counts of a run's zones and lines (an ``AnalyticsResult``), beside the
result files of a run that watched any."""

MEDIA_TYPES: dict[OutputFormat, str] = {
    OutputFormat.json: "application/json",
    OutputFormat.mcap: "application/vnd.mcap",
    OutputFormat.mot: "text/plain; charset=utf-8",
    OutputFormat.mp4: "video/mp4",
}
"""Content type of each format's download (MCAP's, ``application/vnd.mcap``, is registered with
IANA since October 2026)."""


@dataclass(frozen=True, slots=True)
class StreamInfo:
    """What writers know before the first frame."""

    width: int
    height: int
    fps: float
    frame_step: int
    part_names: tuple[str, ...]
    mode: str
    options: JobOptions = field(default_factory=JobOptions)
    job_id: str | None = None
    filename: str | None = None
    mcap_images: Literal["h264", "jpeg"] = "h264"
    pixel_aspect: float = 1.0
    skeleton: tuple[tuple[str, str], ...] = ()
    """Pairs of :attr:`part_names` joined by a limb, for drawing (empty: none)."""
    analytics: AnalyticsConfig | None = None
    """The zones and lines watched, in pixels (None: none): drawn in the MP4 and the MCAP."""
    live: bool = False
    """Stream mode: the frames of a live camera, not of a video. Nothing is announced (no
    frame rate, no frame count: :attr:`RunSummary.video` is None), every frame read is
    tracked, and the messages written are :class:`~api_schemas.streams.StreamTracksMessage`
    (the camera, the frame's sequence number, latency... as their fields)."""

    @classmethod
    def of_stream(
        cls,
        width: int,
        height: int,
        part_names: tuple[str, ...],
        skeleton: tuple[tuple[str, str], ...],
        options: JobOptions,
        images: Literal["h264", "jpeg"],
        analytics: AnalyticsConfig | None = None,
    ) -> StreamInfo:
        """What a live recording knows before its first frame: the frame size, the parts, the
        options that run (people, every frame) and the zones and lines watched."""
        return cls(
            width=width,
            height=height,
            fps=0.0,
            frame_step=1,
            part_names=part_names,
            mode="people",
            options=options,
            mcap_images=images,
            skeleton=skeleton,
            analytics=analytics,
            live=True,
        )


def limbs(
    track: TrackState, skeleton: tuple[tuple[str, str], ...]
) -> list[tuple[tuple[float, float], tuple[float, float]]]:
    """The ends (x, y) of each ``skeleton`` edge of a track whose two parts are both visible,
    in skeleton order: what the MCAP and the MP4 draw as the track's limbs."""
    parts = {part.name: part for part in track.parts if part.visible}
    return [
        ((parts[a].x, parts[a].y), (parts[b].x, parts[b].y))
        for a, b in skeleton
        if a in parts and b in parts
    ]


@dataclass(slots=True)
class RunSummary:
    """What writers learn at the end."""

    video: VideoInfo | None
    """The video as read; None in stream mode (:attr:`StreamInfo.live`), where nothing was
    announced and every frame read was tracked."""
    frames_processed: int
    warnings: list[str] = field(default_factory=list)
    analytics: AnalyticsResult | None = None
    """The events and counts of the zones and lines (None: none watched)."""


class ResultWriter(Protocol):
    """One output file, written frame by frame."""

    path: Path

    def write(
        self,
        frame: TimedFrame,
        message: FrameTracksMessage,
        events: Sequence[AnalyticsEvent] = (),
    ) -> None:
        """Write a tracked frame, with the ``events`` of its zones and lines."""
        ...

    def write_filled(self, message: FrameTracksMessage) -> None:
        """Estimates filled in for an earlier frame (job option ``fill_gaps``), given before
        the frame that closed the gap. Trajectory formats add them; formats that show frames
        as they were tracked (mcap, mp4) ignore them."""
        ...

    def close(self, summary: RunSummary) -> None: ...

    def abort(self) -> None: ...


def open_writers(
    formats: list[OutputFormat], folder: Path, info: StreamInfo
) -> dict[OutputFormat, ResultWriter]:
    """A writer per format, each writing ``folder / RESULT_FILES[format]``."""
    from service.outputs.json_out import JsonWriter
    from service.outputs.mcap_out import McapWriter
    from service.outputs.mot_out import MotWriter
    from service.outputs.video_out import VideoWriter

    makers: dict[OutputFormat, Callable[[Path, StreamInfo], ResultWriter]] = {
        OutputFormat.json: JsonWriter,
        OutputFormat.mcap: McapWriter,
        OutputFormat.mot: MotWriter,
        OutputFormat.mp4: VideoWriter,
    }
    writers: dict[OutputFormat, ResultWriter] = {}
    try:
        for fmt in formats:
            writers[fmt] = makers[fmt](folder / RESULT_FILES[fmt], info)
    except BaseException:
        for writer in writers.values():
            writer.abort()
        raise
    return writers
