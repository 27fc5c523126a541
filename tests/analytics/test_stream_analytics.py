"""A live stream's zone events go out on Zenoh as they happen and reach an MQTT broker through
the outbox; real sessions, a real broker, on loopback."""

from __future__ import annotations

import json
import threading
from itertools import islice

import paho.mqtt.client as mqtt
import pytest

from devtools.testing import Server, wait_for
from service.streams.keys import StreamKeys
from service.streams.session import ZenohOptions
from service.streams.tools import member_session, publish_frames, video_frames
from tests.delivery.receivers import mqtt_broker
from tests.service.conftest import PETS_VIDEO, metrics
from tests.streams.live import all_taken, start_stream

# the whole frame is a zone: every person is in it as soon as seen
ZONE = {"name": "all", "polygon": [[0, 0], [1, 0], [1, 1], [0, 1]], "min_dwell": 0.5}
ANALYTICS = {"coordinates": "normalized", "zones": [ZONE]}


@pytest.fixture(scope="module")
def broker(tmp_path_factory):
    with mqtt_broker(tmp_path_factory.mktemp("broker")) as port:
        yield port


@pytest.fixture(scope="module")
def server(tmp_path_factory, broker):
    folder = tmp_path_factory.mktemp("stream-analytics")
    server = Server(
        folder / "data", workers=1, mqtt_url=f"mqtt://127.0.0.1:{broker}", mqtt_topic_prefix="site"
    ).start()
    yield server
    server.stop()


def test_stream_events_go_out_on_zenoh_and_to_the_mqtt_broker(server, broker, shared_data):
    camera = "platform"
    keys = StreamKeys("vtrack", camera)
    on_mqtt: list[dict] = []
    subscribed = threading.Event()
    listener = mqtt.Client(mqtt.CallbackAPIVersion.VERSION2, client_id="test-listener")
    listener.on_connect = lambda client, *args: client.subscribe("site/#", qos=1)
    listener.on_subscribe = lambda *args: subscribed.set()
    listener.on_message = lambda client, data, message: on_mqtt.append(
        {"topic": message.topic, **json.loads(message.payload)}
    )
    listener.connect("127.0.0.1", broker)
    listener.loop_start()
    session = member_session(ZenohOptions(listen=server.zenoh_listen))
    on_zenoh: list[dict] = []
    subscriber = session.declare_subscriber(
        keys.events, lambda sample: on_zenoh.append(json.loads(sample.payload.to_bytes()))
    )
    try:
        assert subscribed.wait(10)
        frames, _ = video_frames(str(shared_data / PETS_VIDEO))
        with server.client() as client:
            start_stream(client, session, camera, analytics=ANALYTICS)
            publish_frames(session, keys, islice(frames, 40), 10.0)
            all_taken(client, camera, 40)  # no event comes after these
            wait_for(lambda: len(on_mqtt) == len(on_zenoh) > 0, 30, "the events at the broker")
            seen = metrics(client)
            counts = client.get(f"/v1/streams/{camera}").json()["analytics"]
            assert client.delete(f"/v1/streams/{camera}").status_code == 200
    finally:
        subscriber.undeclare()
        session.close()
        listener.loop_stop()
        listener.disconnect()
    assert {e["camera"] for e in on_zenoh} == {camera}
    assert on_zenoh[0]["type"] == "zone_entered" and on_zenoh[0]["name"] == "all"

    def key(event: dict) -> tuple:
        return event["frame_index"], event["track_id"], event["type"]

    # what went out on Zenoh reached the broker, each event once, on its type's topic
    assert sorted(map(key, on_mqtt)) == sorted(map(key, on_zenoh))
    assert {"zone_entered", "dwell"} <= {e["type"] for e in on_zenoh}
    assert all(e["topic"] == f"site/cameras/{camera}/events/{e['type']}" for e in on_mqtt)
    assert seen['vtrack_events_delivered_total{sink="mqtt"}'] >= 1
    # the stream's status counts what went out
    entered = sum(e["type"] == "zone_entered" for e in on_zenoh)
    assert counts["zones"]["all"]["entered"] == entered
