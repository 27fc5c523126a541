"""Two instances on one PostgreSQL database share the outbox: every event reaches the
receiver once, whichever instance sends it."""

from __future__ import annotations

import pytest

from devtools.testing import free_port, wait_for
from service.delivery.dispatch import Dispatcher
from service.delivery.outbox import Outbox
from service.delivery.sinks import WebhookSink
from tests.delivery.receivers import SECRET, Receiver, events

pytestmark = pytest.mark.scaleout


def test_two_instances_deliver_each_event_once(database_url):
    port = free_port()
    receiver = Receiver(port)
    url = f"http://127.0.0.1:{port}/hook"
    outboxes = [Outbox(database_url), Outbox(database_url)]
    # small batches, so that both instances take turns at the queue
    dispatchers = [
        Dispatcher(box, [WebhookSink("ops", url, SECRET)], batch=5, poll=0.05).start()
        for box in outboxes
    ]
    try:
        outboxes[0].add(["ops"], events(60, "gate"))
        outboxes[1].add(["ops"], events(60, "platform"))
        wait_for(lambda: len(receiver.received) >= 120, 60, "every event to arrive")
        wait_for(lambda: outboxes[0].pending() == {}, 10, "the outbox to empty")
    finally:
        for dispatcher in dispatchers:
            dispatcher.stop()
        receiver.close()
    keys = [key for key, _ in receiver.received]
    assert sorted(keys) == sorted({*keys}) and len(keys) == 120  # each once
    assert receiver.bad_signatures == 0
    assert outboxes[0].counts()["ops"]["delivered"] == 120  # counted across instances
    for box in outboxes:
        box.close()
