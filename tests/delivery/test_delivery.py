"""Events reach a webhook receiver that was down, and an MQTT broker, each exactly once and in
order, through the outbox; real servers on loopback."""

from __future__ import annotations

import json
import threading
from pathlib import Path

import pytest

from devtools.testing import free_port, wait_for
from service.delivery.dispatch import Dispatcher, backoff
from service.delivery.outbox import Outbox
from service.delivery.sinks import MqttSink, WebhookSink
from tests.delivery.receivers import SECRET, Receiver, events, mqtt_broker


def test_backoff_doubles_up_to_its_cap():
    assert [backoff(n, 0.5, 4.0) for n in (1, 2, 3, 4, 5, 9)] == [0.5, 1, 2, 4, 4, 4]


def test_events_survive_a_restart_and_reach_a_receiver_down_for_10_s_once(tmp_path: Path):
    database = tmp_path / "jobs.sqlite3"
    port = free_port()
    url = f"http://127.0.0.1:{port}/hook"
    outbox = Outbox(database)
    assert outbox.add(["ops"], events(20)) == 20
    assert outbox.add(["ops"], events(20)) == 0  # the same events again: keys already queued
    # the service runs while the receiver is down, then stops (a restart)
    first = Dispatcher(outbox, [WebhookSink("ops", url, SECRET, timeout=2)], poll=0.1).start()
    wait_for(lambda: outbox.counts().get("ops", {}).get("retried", 0) >= 2, 30, "retries")
    first.stop()
    outbox.close()
    # the service starts again; the receiver comes up 10 s after it went down
    outbox = Outbox(database)
    assert outbox.pending() == {"ops": 20}
    second = Dispatcher(
        outbox, [WebhookSink("ops", url, SECRET, timeout=2)], poll=0.1, max_backoff=2
    ).start()
    receiver = None
    try:
        threading.Event().wait(10)  # the receiver's outage: what the test is about
        receiver = Receiver(port)
        wait_for(lambda: len(receiver.received) >= 20, 30, "every event to arrive")
        wait_for(lambda: outbox.pending() == {}, 10, "the outbox to empty")
    finally:
        second.stop()
        if receiver is not None:
            receiver.close()
    keys = [key for key, _ in receiver.received]
    assert keys == [f"gate-{i}" for i in range(20)]  # each once, in order
    assert [body["n"] for _, body in receiver.received] == list(range(20))
    assert receiver.bad_signatures == 0
    counts = outbox.counts()["ops"]
    assert (counts["produced"], counts["delivered"], counts["dropped"]) == (20, 20, 0)
    assert counts["retried"] >= 2
    outbox.close()


def test_events_too_old_for_their_sink_are_dropped_and_counted(tmp_path: Path):
    outbox = Outbox(tmp_path / "jobs.sqlite3")
    outbox.add(["ops", "mqtt"], events(3))
    assert outbox.expire(max_age=0, keep_delivered=3600) == {"ops": 3, "mqtt": 3}
    assert outbox.pending() == {}
    assert outbox.counts()["ops"]["dropped"] == 3
    outbox.close()


@pytest.fixture
def broker(tmp_path: Path):
    with mqtt_broker(tmp_path) as port:
        yield port


def test_events_reach_an_mqtt_broker_with_qos_1_on_a_topic_per_camera_and_type(
    tmp_path: Path, broker: int
):
    import paho.mqtt.client as mqtt

    received: list[tuple[str, dict, int]] = []
    subscribed = threading.Event()
    listener = mqtt.Client(mqtt.CallbackAPIVersion.VERSION2, client_id="listener")
    listener.on_subscribe = lambda *args: subscribed.set()
    listener.on_message = lambda client, data, message: received.append(
        (message.topic, json.loads(message.payload), message.qos)
    )
    listener.on_connect = lambda client, *args: client.subscribe("site/#", qos=1)

    def connect() -> bool:
        try:
            listener.connect("127.0.0.1", broker)
        except OSError:
            return False
        return True

    wait_for(connect, 30, "the broker to listen")
    listener.loop_start()
    outbox = Outbox(tmp_path / "jobs.sqlite3")
    try:
        assert subscribed.wait(10)
        outbox.add(["broker"], events(5, "gate") + events(3, "platform"))
        sink = MqttSink("broker", f"mqtt://127.0.0.1:{broker}", topic_prefix="site")
        dispatcher = Dispatcher(outbox, [sink], poll=0.1).start()
        wait_for(lambda: len(received) >= 8, 30, "the broker's messages")
        wait_for(lambda: outbox.pending() == {}, 10, "the outbox to empty")
        dispatcher.stop()
    finally:
        listener.loop_stop()
        listener.disconnect()
    topics = sorted({topic for topic, _, _ in received})
    assert topics == [
        "site/cameras/gate/events/line_crossed",
        "site/cameras/platform/events/line_crossed",
    ]
    assert [body["n"] for topic, body, _ in received if "gate" in topic] == list(range(5))
    assert {qos for _, _, qos in received} == {1}
    assert outbox.counts()["broker"]["delivered"] == 8
    outbox.close()


def test_every_way_a_job_ends_queues_its_summary_once(tmp_path: Path):
    from api_schemas.jobs import JobState
    from service.jobs.store import JobStore

    store = JobStore(tmp_path / "jobs.sqlite3", sinks=("ops", "mqtt"))
    labels = {"camera": "gate"}
    for job_id in ("cancelled", "killed", "done"):
        store.create(job_id, {"labels": labels}, tmp_path / f"{job_id}.mp4", tmp_path / job_id)
    store.request_cancel("cancelled")  # before it started: the API ends it
    killed = store.claim(worker_pid=11)
    assert store.fail_running(killed.id, "the worker died (signal 9)")  # the supervisor
    done = store.claim(worker_pid=12)
    assert store.finish(done, 12, JobState.succeeded, results={"json": "trajectories.json"})
    assert not store.finish(done, 12, JobState.failed)  # no longer its own: nothing more
    outbox = Outbox(tmp_path / "jobs.sqlite3")
    sent = outbox.claim("ops", 10, 60)
    assert [(e.key, e.topic) for e in sent] == [
        (f"job:{job_id}", f"jobs/{job_id}/finished") for job_id in ("cancelled", "killed", "done")
    ]
    bodies = [json.loads(e.body) for e in sent]
    assert [b["state"] for b in bodies] == ["cancelled", "failed", "succeeded"]
    assert bodies[1]["error"] == "the worker died (signal 9)"
    assert bodies[2]["results"] == {"json": "/v1/jobs/done/result?format=json"}
    assert all(b["labels"] == labels for b in bodies)
    assert outbox.pending() == {"ops": 3, "mqtt": 3}
    outbox.close()
    store.close()
