"""Sending the outbox's events: a thread per sink, in order, with backoff while it is down.

A sink that fails (a receiver down, a broker away) keeps its events in the outbox: the one
that failed is due again after a backoff that doubles with each failure in a row (0.5 s up to
``max_backoff``), and the sink's thread waits that long before it tries again, oldest first,
so that order holds and a receiver coming back is not flooded by retries of every event at
once. Tracking never waits for any of this: producers only write to the outbox.
"""

from __future__ import annotations

import logging
import threading
import time
from collections.abc import Sequence

from service.delivery.outbox import Outbox, OutboxEvent
from service.delivery.sinks import DeliveryError, Sink
from service.jobs.database import DATABASE_ERRORS

__all__ = ["Dispatcher", "backoff"]

log = logging.getLogger(__name__)

TIDY_INTERVAL = 60.0
"""Seconds between looks for events too old for their sink, and delivered ones to forget."""


def backoff(failures: int, first: float = 0.5, largest: float = 60.0) -> float:
    """Seconds to wait after ``failures`` failed sends in a row: ``first * 2^(failures - 1)``,
    at most ``largest``."""
    return min(first * 2.0 ** max(failures - 1, 0), largest)


class Dispatcher:
    """Sends each sink's due events from ``outbox``, one thread per sink.

    Parameters
    ----------
    batch:
        Events claimed at a time.
    lease:
        Seconds a claim holds its events (another instance's dispatcher skips them until
        then); longer than a batch takes to send.
    poll:
        Seconds between looks at an empty outbox.
    max_age:
        Seconds an event may wait for its sink before it is dropped (and counted so).
    keep_delivered:
        Seconds a delivered event's row is kept (for a look at what went out).
    """

    def __init__(
        self,
        outbox: Outbox,
        sinks: Sequence[Sink],
        *,
        batch: int = 100,
        lease: float = 300.0,
        poll: float = 0.5,
        max_backoff: float = 60.0,
        max_age: float = 7 * 86400.0,
        keep_delivered: float = 3600.0,
    ) -> None:
        self.outbox = outbox
        self.sinks = tuple(sinks)
        self.batch, self.lease, self.poll = batch, lease, poll
        self.max_backoff, self.max_age, self.keep_delivered = max_backoff, max_age, keep_delivered
        self._stop = threading.Event()
        self._threads: list[threading.Thread] = []

    def start(self) -> Dispatcher:
        for sink in self.sinks:
            thread = threading.Thread(
                target=self._run, args=(sink,), name=f"deliver-{sink.name}", daemon=True
            )
            thread.start()
            self._threads.append(thread)
        return self

    def stop(self, timeout: float = 15.0) -> None:
        """Stop sending (the events not sent stay in the outbox) and close the sinks."""
        self._stop.set()
        for thread in self._threads:
            thread.join(timeout)
        for sink in self.sinks:
            sink.close()

    def _run(self, sink: Sink) -> None:
        failures, tidy_at = 0, 0.0
        while not self._stop.is_set():
            try:
                if sink is self.sinks[0] and time.monotonic() >= tidy_at:  # one tidies for all
                    self.outbox.expire(self.max_age, self.keep_delivered)
                    tidy_at = time.monotonic() + TIDY_INTERVAL
                events = self.outbox.claim(sink.name, self.batch, self.lease)
                if not events:
                    self._stop.wait(self.poll)
                    continue
                failures = self._send(sink, events, failures)
            except DATABASE_ERRORS as error:
                # a claimed event whose delivery was not recorded goes again after its lease:
                # its receiver can tell it by its key
                log.warning("events for %s wait: the database failed (%s)", sink.name, error)
                self._stop.wait(5 * self.poll)

    def _send(self, sink: Sink, events: Sequence[OutboxEvent], failures: int) -> int:
        """Send ``events`` in order until one fails; the failures in a row after them."""
        for index, event in enumerate(events):
            if self._stop.is_set():
                self.outbox.release(events[index:])
                break
            try:
                sink.send(event)
            except DeliveryError as error:
                failures += 1
                delay = backoff(failures, largest=self.max_backoff)
                if failures == 1:
                    log.warning("events for %s wait: %s; retrying", sink.name, error)
                self.outbox.failed(sink.name, event, str(error), delay)
                self.outbox.release(events[index + 1 :])
                self._stop.wait(delay)
                break
            if failures:
                log.info("events for %s flow again after %d failures", sink.name, failures)
                failures = 0
            self.outbox.delivered(sink.name, event)
        return failures
