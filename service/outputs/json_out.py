"""JSON result: the :class:`~api_schemas.tracks.Trajectories` model.

Frames are appended to a JSON-lines scratch file as they come; ``close`` groups them per track
into the final document.
"""

from __future__ import annotations

import json
from pathlib import Path

from api_schemas.tracks import FrameTracksMessage, Trajectories, Trajectory, TrajectoryPoint
from service.frames import TimedFrame
from service.outputs.base import RunSummary, StreamInfo


class JsonWriter:
    def __init__(self, path: Path, info: StreamInfo) -> None:
        self.path = path
        self._info = info
        self._lines_path = path.with_suffix(".frames.jsonl")
        self._lines = self._lines_path.open("w", encoding="utf-8")

    def write(self, frame: TimedFrame, message: FrameTracksMessage) -> None:
        self._lines.write(message.model_dump_json() + "\n")

    def close(self, summary: RunSummary) -> None:
        self._lines.close()
        tracks: dict[int, list[TrajectoryPoint]] = {}
        with self._lines_path.open(encoding="utf-8") as lines:
            for line in lines:
                message = FrameTracksMessage.model_validate_json(line)
                for track in message.tracks:
                    tracks.setdefault(track.track_id, []).append(
                        TrajectoryPoint(
                            frame_index=message.frame_index,
                            timestamp=message.timestamp,
                            box=track.box,
                            score=track.score,
                            occluded=track.occluded,
                            parts=track.parts,
                        )
                    )
        document = Trajectories(
            job_id=self._info.job_id,
            mode=self._info.mode,  # type: ignore[arg-type]
            video=summary.video,
            part_names=list(self._info.part_names),
            frames_processed=summary.frames_processed,
            tracks=[Trajectory(track_id=i, frames=tracks[i]) for i in sorted(tracks)],
        )
        self.path.write_text(document.model_dump_json(indent=1), encoding="utf-8")
        self._lines_path.unlink()

    def abort(self) -> None:
        self._lines.close()


def read_trajectories(path: Path) -> Trajectories:
    """Load a JSON result back (tests, tools)."""
    return Trajectories.model_validate(json.loads(Path(path).read_text(encoding="utf-8")))
