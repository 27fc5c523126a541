"""JSON result: the :class:`~api_schemas.tracks.Trajectories` model.

The document groups the frames per track, but frames come one at a time: each track's point of
a frame is serialised as it comes and appended to a scratch file, with its place kept in a
per-track index (two integers per point). ``close`` then writes the document track by track,
copying each point's bytes from the scratch file. Memory stays at the index, whatever the
length of the video: an hour of 25 fps video with eight people and nine parts each is about
720 000 points, 11 MB of index against several GB as models.
"""

from __future__ import annotations

import json
import os
from array import array
from collections.abc import Sequence
from pathlib import Path

from api_schemas.analytics import AnalyticsEvent
from api_schemas.tracks import FrameTracksMessage, Trajectories, TrajectoryPoint
from service import __version__
from service.frames import TimedFrame
from service.outputs.base import RunSummary, StreamInfo


class JsonWriter:
    def __init__(self, path: Path, info: StreamInfo) -> None:
        self.path = path
        self._info = info
        self._points_path = path.with_suffix(".points.partial")
        self._points = self._points_path.open("w+b")
        self._offset = 0
        # per track id: start offsets and lengths of its points in the scratch file
        self._index: dict[int, tuple[array, array]] = {}

    def write(
        self,
        frame: TimedFrame,
        message: FrameTracksMessage,
        events: Sequence[AnalyticsEvent] = (),
    ) -> None:
        self._append(message)  # the events come whole at the end, in the summary

    def write_filled(self, message: FrameTracksMessage) -> None:
        # a track's filled points come before the point that closed its gap: still in order
        self._append(message)

    def _append(self, message: FrameTracksMessage) -> None:
        for track in message.tracks:
            point = TrajectoryPoint(
                frame_index=message.frame_index,
                timestamp=message.timestamp,
                box=track.box,
                score=track.score,
                occluded=track.occluded,
                parts=track.parts,
                interpolated=track.interpolated,
            ).model_dump_json()
            data = point.encode()
            self._points.write(data)
            starts, lengths = self._index.setdefault(track.track_id, (array("q"), array("q")))
            starts.append(self._offset)
            lengths.append(len(data))
            self._offset += len(data)

    def close(self, summary: RunSummary) -> None:
        if summary.video is None:
            raise ValueError("a JSON result describes its video: stream mode has none")
        head = Trajectories(
            vtrack_version=__version__,
            job_id=self._info.job_id,
            options=self._info.options,
            warnings=summary.warnings,
            mode=self._info.mode,
            video=summary.video,
            part_names=list(self._info.part_names),
            skeleton=list(self._info.skeleton),
            frames_processed=summary.frames_processed,
            analytics=summary.analytics,
            tracks=[],
        ).model_dump(mode="json", exclude={"tracks"})
        self._points.flush()
        partial = self.path.with_suffix(".json.partial")
        with partial.open("wb") as out:
            # the document's fields, then its tracks (the last field), one per line
            out.write(json.dumps(head).encode()[:-1] + b', "tracks": [')
            for number, track_id in enumerate(sorted(self._index)):
                out.write(b"," if number else b"")
                out.write(b'\n{"track_id": %d, "frames": [' % track_id)
                starts, lengths = self._index[track_id]
                for k, (start, length) in enumerate(zip(starts, lengths, strict=True)):
                    self._points.seek(start)
                    out.write((b",\n" if k else b"\n") + self._points.read(length))
                out.write(b"]}")
            out.write(b"]}\n")
        os.replace(partial, self.path)
        self.abort()

    def abort(self) -> None:
        self._points.close()
        self._points_path.unlink(missing_ok=True)


def read_trajectories(path: Path) -> Trajectories:
    """Load a JSON result back (tests, tools)."""
    return Trajectories.model_validate(json.loads(Path(path).read_text(encoding="utf-8")))
