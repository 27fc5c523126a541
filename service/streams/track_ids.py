"""The track ids a stream publishes: never one given twice, across restarts of the tracker, of
the worker and of the service.

A tracker numbers its tracks from 1. The stream adds an offset: each new tracker of a worker
(the camera started over, changed resolution, went silent) starts above every id published
before, and a new worker above every id reserved in the service's database
(:class:`~service.streams.store.StreamStore`) by the workers before it.
"""

from __future__ import annotations

import dataclasses
import logging
import time
from collections.abc import Callable
from pathlib import Path

from service.jobs.database import DATABASE_ERRORS
from service.streams.store import StreamStore
from tracking.tracks import FrameTracks

log = logging.getLogger(__name__)

ID_BLOCK = 100
"""Track ids reserved in the database at a time. The reservation is written before the first
id beyond the last one is published, so the database is written once per this many new people
(not per frame) and a worker that starts again continues above every id that may have gone out;
the price is a gap of up to this many ids after a restart."""

RESERVE_RETRY = 5.0
"""Seconds before a reservation that failed (a full disk, a locked database) is tried again;
tracking goes on meanwhile."""

DATABASE_TIMEOUT = 5.0
"""Seconds the tracking thread waits for the database's lock (the service writes it too)."""


class TrackIds:
    """The ids of one camera's tracks as published.

    Parameters
    ----------
    camera:
        The stream's camera.
    database:
        The service's database (``stream_track_ids``); None: ids start at 1 with each worker
        and nothing is reserved.
    note_error:
        Told, with a log level, why a reservation failed (tracking goes on).
    """

    def __init__(
        self,
        camera: str,
        database: str | Path | None,
        note_error: Callable[[str, int], None],
    ) -> None:
        self._camera = camera
        self._note_error = note_error
        self._store: StreamStore | None = None
        self._reserved = 0  # ids up to this are reserved in the database
        self._reserve_retry_at = 0.0  # time.monotonic()
        if database is not None:
            # Continue above every id an earlier worker of this stream may have published.
            self._store = StreamStore(database, timeout=DATABASE_TIMEOUT)
            self._reserved = self._store.reserved_track_ids(camera)
            if self._reserved:
                log.info("camera %s: track ids continue above %d", camera, self._reserved)
        self._offset = self._reserved  # added to the tracker's ids
        self._max_id = self._reserved  # the highest id that may have been published

    def published(self, tracks: FrameTracks) -> FrameTracks:
        """``tracks`` with their ids as published: the current tracker's offset added, the ids
        beyond the reserved ones reserved first."""
        shifted = dataclasses.replace(tracks, track_ids=tracks.track_ids + self._offset)
        if len(shifted):
            self._max_id = max(self._max_id, int(shifted.track_ids.max()))
        self._reserve(self._max_id)
        return shifted

    def start_over(self) -> None:
        """A new tracker takes over, numbering from 1 again: its ids go above every id
        published so far."""
        self._offset = self._max_id

    def close(self) -> None:
        if self._store is not None:
            self._store.close()
            self._store = None

    def _reserve(self, highest: int) -> None:
        """Reserve ids beyond ``highest`` in the database before ``highest`` is published."""
        if self._store is None or highest <= self._reserved:
            return
        now = time.monotonic()
        if now < self._reserve_retry_at:
            return
        up_to = highest + ID_BLOCK
        try:
            self._store.reserve_track_ids(self._camera, up_to)
        except DATABASE_ERRORS as error:
            self._reserve_retry_at = now + RESERVE_RETRY
            self._note_error(
                f"track ids could not be reserved in the database ({error}); tracking goes on, "
                f"but ids above {self._reserved} may be given again if the stream restarts",
                logging.ERROR,
            )
            return
        self._reserved = up_to
