"""Prometheus metrics, read from the job store and the stream manager at scrape time.

Workers are separate processes, so counts live where every process can add to them: the
``counters`` table of the job store (they also survive restarts). The collector turns them into
metric families when ``/metrics`` is scraped.
"""

from __future__ import annotations

import time
from pathlib import Path

from prometheus_client import CollectorRegistry
from prometheus_client.core import (
    CounterMetricFamily,
    GaugeMetricFamily,
    HistogramMetricFamily,
)
from prometheus_client.registry import Collector

from api_schemas.jobs import JobState
from api_schemas.streams import StreamState
from service.jobs.store import DURATION_BUCKETS, JobStore
from service.jobs.workers import WorkerPool
from service.storage import free_bytes
from service.streams.manager import StreamManager


class ServiceCollector(Collector):
    def __init__(
        self,
        store: JobStore,
        pool: WorkerPool,
        streams: StreamManager,
        data_dir: Path,
        instance: str = "",
        sinks: tuple[str, ...] = (),
    ) -> None:
        self._instance = instance
        self._sinks = sinks
        self._store = store
        self._pool = pool
        self._streams = streams
        self._data_dir = data_dir

    def collect(self):
        info = GaugeMetricFamily(
            "vtrack_instance",
            "This instance (VTRACK_INSTANCE_NAME), and whether its job database is shared with "
            "other instances (VTRACK_DATABASE_URL): the job gauges are the database's, the "
            "same from every instance; vtrack_jobs_here is this instance's.",
            labels=["instance", "shared"],
        )
        info.add_metric([self._instance, str(self._store.shared).lower()], 1)
        yield info
        yield GaugeMetricFamily(
            "vtrack_jobs_here",
            "Running jobs this instance's workers run.",
            value=len(self._store.running(self._instance if self._store.shared else None)),
        )
        jobs = GaugeMetricFamily(
            "vtrack_jobs", "Jobs in the job store, by state.", labels=["state"]
        )
        for state, count in self._store.counts_by_state().items():
            jobs.add_metric([state.value], count)
        yield jobs
        queued_since, progressed_at = self._store.waits()
        now = time.time()
        # 0 when no job waits: a series that vanishes breaks alerts on it
        yield GaugeMetricFamily(
            "vtrack_oldest_queued_job_seconds",
            "How long the oldest queued job has waited for a worker (0: none queued).",
            value=max(now - queued_since, 0.0) if queued_since is not None else 0.0,
        )
        yield GaugeMetricFamily(
            "vtrack_running_job_stall_seconds",
            "The longest time a running job has gone without reading a frame (0: none "
            "running); VTRACK_JOB_STALL_TIMEOUT fails the job beyond its value.",
            value=max(now - progressed_at, 0.0) if progressed_at is not None else 0.0,
        )
        counters = self._store.counters()
        yield CounterMetricFamily(
            "vtrack_frames_processed",
            "Video frames tracked by the workers, in every attempt (work done: frames redone "
            "after a restart count again).",
            value=counters.get("frames_processed", 0.0),
        )
        finished = CounterMetricFamily(
            "vtrack_jobs_finished", "Jobs that reached an end state.", labels=["state"]
        )
        for state in (JobState.succeeded, JobState.failed, JobState.cancelled):
            finished.add_metric([state.value], counters.get(f"jobs_{state.value}", 0.0))
        yield finished
        buckets = [(f"{b:g}", counters.get(f"processing_le_{b:g}", 0.0)) for b in DURATION_BUCKETS]
        buckets.append(("+Inf", counters.get("processing_count", 0.0)))
        yield HistogramMetricFamily(
            "vtrack_job_processing_seconds",
            "Time from the start of a job's last attempt to its end state.",
            buckets=buckets,
            sum_value=counters.get("processing_seconds", 0.0),
        )
        yield GaugeMetricFamily(
            "vtrack_workers_alive", "Worker processes alive.", value=self._pool.alive()
        )
        yield CounterMetricFamily(
            "vtrack_workers_replaced",
            "Worker processes replaced after they died or overran (since start).",
            value=self._pool.replaced,
        )
        yield GaugeMetricFamily(
            "vtrack_data_free_bytes",
            "Bytes the service may still write on its data folder's disk.",
            value=free_bytes(self._data_dir),
        )
        yield from self._stream_metrics()
        yield from self._event_metrics(counters)

    def _event_metrics(self, counters: dict[str, float]):
        """Events per sink (webhooks, the MQTT broker), from the outbox's counts in the
        database: the same from every instance that shares it."""
        sinks = sorted(
            {*self._sinks, *(n.partition(":")[2] for n in counters if n[:7] == "events_")}
        )
        for kind, what in (
            ("produced", "Events of zones and lines queued for a sink."),
            ("delivered", "Events a sink took (a 2xx answer, an MQTT PUBACK)."),
            ("retried", "Sends that failed and were tried again later."),
            ("dropped", "Events dropped after VTRACK_EVENTS_MAX_AGE_HOURS undelivered (0 is "
             "the aim)."),
        ):  # fmt: skip
            family = CounterMetricFamily(f"vtrack_events_{kind}", what, labels=["sink"])
            for sink in sinks:
                family.add_metric([sink], counters.get(f"events_{kind}:{sink}", 0.0))
            yield family

    def _stream_metrics(self):
        by_state = GaugeMetricFamily("vtrack_streams", "Live streams, by state.", labels=["state"])
        counts = self._streams.counts()
        # every state, 0 included: a series that vanishes breaks alerts and graphs on it
        for state in StreamState:
            by_state.add_metric([state.value], counts.get(state.value, 0))
        yield by_state
        frames = CounterMetricFamily(
            "vtrack_stream_frames",
            "Frames of live streams since this service started them (worker restarts "
            "included), by camera and fate "
            "(in, processed, skipped, malformed).",
            labels=["camera", "fate"],
        )
        latency = GaugeMetricFamily(
            "vtrack_stream_latency_seconds",
            "Median processing latency of a stream's recent frames.",
            labels=["camera"],
        )
        for status in self._streams.list():
            c = status.counters
            for fate, value in (
                ("in", c.frames_in),
                ("processed", c.frames_processed),
                ("skipped", c.frames_skipped),
                ("malformed", c.malformed),
            ):
                frames.add_metric([status.camera, fate], value)
            # a camera that sends nothing has no latency (its last figure would stay for ever)
            if status.latency is not None and status.state is StreamState.running:
                latency.add_metric([status.camera], status.latency)
        yield frames
        yield latency


def make_registry(
    store: JobStore,
    pool: WorkerPool,
    streams: StreamManager,
    data_dir: Path,
    instance: str = "",
    sinks: tuple[str, ...] = (),
) -> CollectorRegistry:
    registry = CollectorRegistry(auto_describe=False)
    registry.register(ServiceCollector(store, pool, streams, data_dir, instance, sinks))
    return registry
