"""The sinks the service's settings configure: each webhook by its name, and the MQTT broker
as ``mqtt``."""

from __future__ import annotations

from typing import TYPE_CHECKING

from service.delivery.sinks import MqttSink, Sink, WebhookSink

if TYPE_CHECKING:
    from service.settings import Settings

MQTT_SINK = "mqtt"
"""The MQTT broker's name as a sink (in the outbox, logs and metrics)."""


def sink_names(settings: Settings) -> tuple[str, ...]:
    """The names of the sinks of ``settings`` (what producers queue events for)."""
    names = tuple(hook.name for hook in settings.webhooks)
    return (*names, MQTT_SINK) if settings.mqtt_url is not None else names


def make_sinks(settings: Settings) -> list[Sink]:
    """The sinks of ``settings``, ready to send (the MQTT client connects in the background)."""
    sinks: list[Sink] = [
        WebhookSink(
            hook.name, hook.url, None if hook.secret is None else hook.secret.get_secret_value()
        )
        for hook in settings.webhooks
    ]
    if settings.mqtt_url is not None:
        url = settings.mqtt_url.get_secret_value()
        sinks.append(MqttSink(MQTT_SINK, url, topic_prefix=settings.mqtt_topic_prefix))
    return sinks
