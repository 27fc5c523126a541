"""Events delivered to the systems operators run: webhooks and an MQTT broker, through an
outbox in the job database so that nothing is lost to a restart or a receiver that is down."""
