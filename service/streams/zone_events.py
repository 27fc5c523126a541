"""A stream's zones and lines: placed on the frames of each run of the tracker, fed the tracks
as published, their events sent out on Zenoh and, through the outbox, to the sinks."""

from __future__ import annotations

import collections
import logging
import uuid
from collections.abc import Callable
from typing import TYPE_CHECKING, Any

import zenoh

from api_schemas.analytics import AnalyticsEvent
from service.analytics import AnalyticsProblem, FrameAnalytics, analytics_config
from service.delivery.messages import stream_event
from service.delivery.outbox import Outbox, OutgoingEvent
from service.jobs.database import DATABASE_ERRORS
from service.streams.keys import StreamKeys
from tracking.analytics import AnalyticsConfig
from tracking.tracks import FrameTracks

if TYPE_CHECKING:
    from service.streams.worker import StreamContext

log = logging.getLogger(__name__)

BACKLOG = 10_000
"""Events kept for the outbox while the database is away; beyond, the oldest go (logged)."""


class ZoneEvents:
    """The events of the zones and lines of one camera's stream.

    Each run of the tracker (a start, a camera that started over or changed resolution) places
    the zones anew on its frame size and counts from zero; its events carry a run id of their
    own in their idempotency keys.
    """

    def __init__(self, context: StreamContext, note_error: Callable[[str, int], None]) -> None:
        self._options = context.spec.analytics
        self._camera = context.spec.camera
        self._keys = StreamKeys(context.prefix, context.spec.camera)
        self._sinks = context.sinks
        self._database = context.database
        self._note_error = note_error
        self._publisher: zenoh.Publisher | None = None
        self._outbox: Outbox | None = None
        self._analytics: FrameAnalytics | None = None
        self._size: tuple[int, int] | None = None
        self._run = ""
        self._backlog: collections.deque[OutgoingEvent] = collections.deque()

    @property
    def config(self) -> AnalyticsConfig | None:
        """The zones and lines of this run, in pixels (None: none, or not placed yet)."""
        return None if self._analytics is None else self._analytics.config

    def counts(self) -> dict[str, Any] | None:
        """This run's counts as plain data (None: no zones or lines placed)."""
        if self._analytics is None:
            return None
        return self._analytics.counts().model_dump(mode="json", by_alias=True)

    def open(self, session: zenoh.Session) -> None:
        """Declare the events' publisher and open the outbox (when there is anything to do)."""
        if self._options is None:
            return
        self._publisher = session.declare_publisher(
            self._keys.events, encoding=zenoh.Encoding.APPLICATION_JSON
        )
        if self._sinks and self._database is not None:
            self._outbox = Outbox(self._database)

    def new_run(self) -> None:
        self._analytics, self._size, self._run = None, None, uuid.uuid4().hex[:12]

    def update(
        self, tracks: FrameTracks, frame_index: int, size: tuple[int, int]
    ) -> list[AnalyticsEvent]:
        """The events of one frame of ``size`` (width, height), its tracks as published; sent
        on at once."""
        if self._options is None:
            return []
        if size != self._size:
            self._size = size
            try:
                config = analytics_config(self._options, size)
            except AnalyticsProblem as problem:
                self._analytics = None
                self._note_error(f"the zones and lines are not watched: {problem}", logging.ERROR)
            else:
                self._analytics = FrameAnalytics(config, keep=False)
        if self._analytics is None:
            return []
        events = self._analytics.update(tracks, frame_index)
        outgoing = [stream_event(event, self._camera, self._run) for event in events]
        if self._publisher is not None:
            for message in outgoing:
                self._publisher.put(message.body)
        if self._outbox is not None:
            self._backlog.extend(outgoing)
            self._queue()
        return events

    def _queue(self) -> None:
        """Hand the backlog to the outbox; while the database is away it waits (bounded)."""
        assert self._outbox is not None
        if not self._backlog:
            return
        try:
            self._outbox.add(self._sinks, self._backlog)
        except DATABASE_ERRORS as error:
            while len(self._backlog) > BACKLOG:
                self._backlog.popleft()
                log.error("camera %s: an event was dropped: the database is away", self._camera)
            self._note_error(f"events wait for the database: {error}", logging.WARNING)
            return
        self._backlog.clear()

    def close(self) -> None:
        if self._outbox is not None:
            self._queue()
            self._outbox.close()
            self._outbox = None
        if self._publisher is not None:
            self._publisher.undeclare()
            self._publisher = None
