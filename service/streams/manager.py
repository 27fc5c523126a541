"""The service side of live streams: a worker process per stream, started, watched, stopped.

:class:`StreamManager` lives in the service process. It opens the hub Zenoh session (the one
cameras and workers meet at), starts a worker process per stream, and keeps each stream's latest
status from the reports its worker sends over a pipe. A supervisor thread restarts a worker
that died, waiting longer after each quick death, and gives up (state ``failed``) after
:data:`MAX_QUICK_DEATHS` in a row. An arbiter thread keeps one tracker per camera across
instances: a stream whose camera another instance tracks stands by until that instance's
liveliness token disappears.

Instances that share a job database (``VTRACK_DATABASE_URL``) share the streams too: each
reads the streams table at every look of the arbiter, and the cameras are spread over the live
instances by rendezvous hashing (highest random weight): a camera belongs to the instance, of
those whose ``<prefix>/instances/<name>`` liveliness token is there, with the highest hash of
camera and name. Every instance computes the same owner from the same tokens, with no
coordinator and no table to keep; an instance that leaves moves only its own cameras (to the
others, spread again), one that joins takes only the cameras that now hash to it. A camera
moves without being tracked twice: its tracker stops and stands by first, and the new owner
starts once no tracker's token is left (two looks in a row, as a standby takes over).
"""

from __future__ import annotations

import builtins
import hashlib
import logging
import os
import shutil
import threading
import time
import uuid
from dataclasses import dataclass, field
from datetime import UTC, datetime
from multiprocessing.connection import wait as wait_for_any
from pathlib import Path
from typing import Any

import zenoh

from api_schemas.streams import (
    StreamCounters,
    StreamDetail,
    StreamSpec,
    StreamState,
    StreamStatus,
    StreamTracksMessage,
)
from service.pipelines import (
    OptionsError,
    PipelineResources,
    check_options,
    choose_detector,
    choose_networks,
)
from service.streams.keys import StreamKeys
from service.streams.session import ZenohOptions, ZenohUnavailable, open_session
from service.streams.store import StreamRecord, StreamStore
from service.streams.tools import trackers_of
from service.streams.worker import StreamContext, job_options, stream_main
from service.worker_processes import (
    ProcessWatch,
    StopSignalDeaths,
    describe_exit,
    shared_flag,
    worker_context,
)

log = logging.getLogger(__name__)

MAX_QUICK_DEATHS = 5
"""Worker deaths in a row, each within :data:`QUICK` seconds of its start, before giving up."""
QUICK = 30.0
STOP_GRACE = 10.0
"""Seconds a stopping worker gets to close its recording and session before it is killed."""
ARBITRATION_INTERVAL = 2.0
"""Seconds between two looks at the cameras' liveliness tokens."""
UNOWNED_LOOKS = 5
"""Looks in a row that found a spread camera tracked by no one (its owner cannot start it:
a missing model there, say) before any instance may take it."""


class StreamConflict(Exception):
    """The camera is tracked already (here or by another instance)."""


class StreamNotFound(KeyError):
    pass


@dataclass(slots=True)
class _Stream:
    record: StreamRecord
    process: Any = None
    watch: ProcessWatch | None = None  # the worker's real end (see _check)
    stop: Any = None
    updates: Any = None
    started_at: float = 0.0
    starts: int = 0
    quick_deaths: int = 0
    restart_at: float | None = None
    state: StreamState = StreamState.starting
    stopping: bool = False
    error: str | None = None
    death: str | None = None  # why the last worker died, while its successor is young
    yield_to: list[str] | None = None  # instances its stopping worker makes way for
    discovering: bool = False  # not started until the arbiter has looked for other instances
    untracked: int = 0  # looks in a row that found no other instance tracking the camera
    unowned: bool = False  # taken although another instance owns the camera (which did not)
    worker_error: str | None = None  # what the current worker said before it ended
    report: dict[str, Any] = field(default_factory=dict)
    # the counters of the stream's earlier workers, to which the current one's add
    carried: dict[str, int] = field(default_factory=dict)


class StreamManager:
    """Every stream of this service instance."""

    # declared here: in __init__ the name zenoh is the ZenohOptions parameter
    _hub: zenoh.Session | None  # the hub session; None: not started, unavailable or closed

    def __init__(
        self,
        store: StreamStore,
        zenoh: ZenohOptions,
        prefix: str,
        streams_dir: Path,
        resources: PipelineResources,
        *,
        frame_limit: int = 32 * 1024**2,
        log_level: str = "info",
        check_interval: float = 0.1,
        stop_requested: threading.Event | None = None,
        spread_as: str | None = None,
        sinks: tuple[str, ...] = (),
    ) -> None:
        self._store = store
        self._sinks = sinks  # where the events of the streams' zones and lines go
        # this instance's name among those that share the streams table; None: it is its own
        self._name = spread_as
        self._presence: Any = None  # its liveliness token, <prefix>/instances/<name>
        self._zenoh = zenoh
        self._prefix = prefix
        self._streams_dir = streams_dir
        self._resources = resources
        self._frame_limit = frame_limit
        self._log_level = log_level
        self._check_interval = check_interval
        # ordered by start time (milliseconds in fixed-width hex), so that of two instances that
        # track one camera the older, which had it first, keeps it (see _arbitrate)
        self.instance = f"{time.time_ns() // 1_000_000:011x}{uuid.uuid4().hex[:5]}"
        self._ctx = worker_context()
        self._streams: dict[str, _Stream] = {}
        self._lock = threading.RLock()
        self._stopping = threading.Event()
        # set by the service's stop-signal handler: a worker ended meanwhile is no death
        self._deaths = StopSignalDeaths(stop_requested)
        self._threads: list[threading.Thread] = []
        self._hub = None
        self.unavailable: str | None = None

    # -- lifecycle -------------------------------------------------------------------------

    def start(self, configured: list[StreamSpec]) -> None:
        """Open the hub session; start the configured streams and those the store holds."""
        try:
            self._hub = open_session(self._zenoh.hub_config())
        except ZenohUnavailable as error:
            self.unavailable = f"Zenoh is unavailable: {error}"
            if "in use" in str(error):  # another service or Zenoh program has the port
                self.unavailable += (
                    " (another program listens there: give this service another endpoint "
                    "with VTRACK_ZENOH_LISTEN)"
                )
            log.error("%s; live streams are off", self.unavailable)
            return
        if self._name is not None:
            self._presence = self._hub.liveliness().declare_token(self._instance_key(self._name))
        for spec in configured:
            self._store.put(spec)
        for record in self._store.all():
            stream = _Stream(record)
            if record.stopped_at is not None:
                stream.state = StreamState.stopped
            self._streams[record.id] = stream
            if record.stopped_at is None and (self._zenoh.connect or self._name is not None):
                # Joining a network: other instances' tokens arrive once gossip has connected
                # this hub to their workers; the arbiter's first look, a moment later, decides.
                stream.discovering = True
            elif record.stopped_at is None:
                self._stand_by_or_spawn(stream, self._other_trackers(record.spec.camera))
        self._threads = [
            threading.Thread(target=loop, name=name, daemon=True)
            for loop, name in (
                (self._supervise, "vtrack-streams"),
                (self._arbitrate, "vtrack-arbiter"),
            )
        ]
        for thread in self._threads:
            thread.start()
        log.info("Zenoh session %s open; %d streams", self._hub.zid(), len(self._streams))

    def shutdown(self) -> None:
        """Stop every worker; the streams start again with the next service."""
        self._stopping.set()
        for thread in self._threads:
            thread.join()
        with self._lock:
            streams = list(self._streams.values())
        self._halt(*streams)
        if self._presence is not None:
            self._presence.undeclare()
        if self._hub is not None:
            self._hub.close()
            self._hub = None
        self._store.close()

    # -- requests --------------------------------------------------------------------------

    def create(self, spec: StreamSpec) -> StreamStatus:
        """Start tracking a camera.

        Raises
        ------
        ZenohUnavailable
            The service has no Zenoh session.
        StreamConflict
            The camera is tracked already, here or by another instance.
        OptionsError
            Options that cannot run here (e.g. detector 'dpm' without a model).
        """
        self._require_zenoh()
        check_options(job_options(spec), self._resources)
        if others := self._other_trackers(spec.camera):
            raise StreamConflict(
                f"camera {spec.camera} is tracked already by another instance "
                f"({', '.join(others)}; see the liveliness tokens "
                f"{self._keys(spec.camera).trackers})"
            )
        with self._lock:
            existing = self._streams.get(spec.camera)
            # a failed stream is started again as a stopped one is: it runs no worker
            if existing is not None and existing.state not in (
                StreamState.stopped,
                StreamState.failed,
            ):
                raise StreamConflict(f"camera {spec.camera} is tracked already by this service")
            stream = _Stream(self._store.put(spec))
            self._streams[spec.camera] = stream
        owner = self._owner(spec.camera)
        with self._lock:
            if owner is None or owner == self._name:  # None: this instance shares nothing
                self._spawn(stream)
            else:  # the owner reads the table at its next look and starts it
                self._stand_by(stream, [owner])
            return self._status(stream)

    def stop(self, stream_id: str) -> StreamStatus:
        """Stop a stream; its record and recordings stay until :meth:`remove`."""
        with self._lock:
            stream = self._get(stream_id)
            # The supervisor leaves a stopping stream alone: its worker's exit is no death.
            stream.stopping = True
        self._halt(stream)
        with self._lock:
            stream.stopping = False
            stopped = self._store.mark_stopped(stream_id)
            stream.record = StreamRecord(
                stream.record.id, stream.record.spec, stream.record.created_at, stopped
            )
            stream.state = StreamState.stopped
            stream.restart_at = stream.yield_to = stream.death = None
            return self._status(stream)

    def remove(self, stream_id: str) -> None:
        """Forget a stopped stream and delete its recordings."""
        with self._lock:
            stream = self._get(stream_id)
            if stream.state is not StreamState.stopped:
                raise StreamConflict(f"stream {stream_id} is running; stop it first")
            self._store.delete(stream_id)
            del self._streams[stream_id]
        shutil.rmtree(self.recordings_dir(stream_id), ignore_errors=True)

    def list(self) -> list[StreamStatus]:
        with self._lock:
            return [self._status(s) for s in self._streams.values()]

    def detail(self, stream_id: str) -> StreamDetail:
        with self._lock:
            stream = self._get(stream_id)
            status = self._status(stream)
            tracks = stream.report.get("tracks")
        current = StreamTracksMessage.model_validate_json(tracks) if tracks else None
        return StreamDetail(**status.model_dump(), tracks=current)

    def status(self, stream_id: str) -> StreamStatus:
        with self._lock:
            return self._status(self._get(stream_id))

    def recordings_dir(self, stream_id: str) -> Path:
        return self._streams_dir / stream_id

    def recordings(self, stream_id: str) -> builtins.list[Path]:
        """Finished recordings of a stream, oldest first."""
        self._get(stream_id)
        folder = self.recordings_dir(stream_id)
        return sorted(folder.glob("*.mcap")) if folder.is_dir() else []

    def counts(self) -> dict[str, int]:
        """Streams per state (for /metrics and /readyz)."""
        with self._lock:
            counts: dict[str, int] = {}
            for stream in self._streams.values():
                state = self._state(stream).value
                counts[state] = counts.get(state, 0) + 1
            return counts

    # -- internals -------------------------------------------------------------------------

    def _require_zenoh(self) -> zenoh.Session:
        """The hub session; raises ``ZenohUnavailable`` when there is none."""
        if self._hub is None:
            raise ZenohUnavailable(self.unavailable or "the stream manager is not started")
        return self._hub

    def _keys(self, camera: str) -> StreamKeys:
        return StreamKeys(self._prefix, camera)

    def _get(self, stream_id: str) -> _Stream:
        with self._lock:
            stream = self._streams.get(stream_id)
        if stream is None:
            raise StreamNotFound(stream_id)
        return stream

    def _instance_key(self, name: str) -> str:
        return f"{self._prefix}/instances/{name}"

    def _live_instances(self) -> builtins.list[str]:
        """The names of the instances that share the streams table and are alive (their
        liveliness tokens); empty when this instance shares nothing."""
        if self._name is None or self._hub is None:
            return []
        prefix = self._instance_key("")
        names = {self._name}
        for reply in self._hub.liveliness().get(self._instance_key("*"), timeout=1.0):
            if reply.ok is not None:
                names.add(str(reply.ok.key_expr).removeprefix(prefix))
        return sorted(names)

    def _owner(self, camera: str) -> str | None:
        """The instance a camera belongs to (None: this instance shares nothing)."""
        live = self._live_instances()
        return _owner_of(camera, live) if live else None

    def _follow_table(self) -> None:
        """Take in what other instances changed in the shared streams table: streams created
        there (standing by until the arbiter decides), stopped there, or deleted."""
        records = {record.id: record for record in self._store.all()}
        halted = []
        with self._lock:
            for stream_id, record in records.items():
                stream = self._streams.get(stream_id)
                if stream is None or stream.record.created_at != record.created_at:
                    if stream is not None and stream.process is not None:
                        halted.append(stream)  # replaced by a new spec elsewhere
                    fresh = _Stream(record)
                    if record.stopped_at is None:
                        fresh.state, fresh.discovering = StreamState.standby, True
                    else:
                        fresh.state = StreamState.stopped
                    self._streams[stream_id] = fresh
                elif record.stopped_at is not None and stream.state is not StreamState.stopped:
                    stream.stopping = True
                    halted.append(stream)
            for stream_id in [i for i in self._streams if i not in records]:
                stream = self._streams.pop(stream_id)
                if stream.process is not None:
                    stream.stopping = True
                    halted.append(stream)
        if halted:
            self._halt(*halted)
            with self._lock:
                for stream in halted:
                    if (latest := records.get(stream.record.id)) is not None:
                        stream.record = latest
                    stream.state = StreamState.stopped
                    stream.stopping = False
                    stream.restart_at = stream.yield_to = stream.death = None

    def _other_trackers(self, camera: str) -> builtins.list[str]:
        """Other instances whose liveliness token says they track ``camera`` (a query: call it
        without holding the lock)."""
        hub = self._require_zenoh()
        return [i for i in trackers_of(hub, self._keys(camera)) if i != self.instance]

    def _stand_by(self, stream: _Stream, others: builtins.list[str]) -> None:
        self._fold(stream)
        stream.unowned = False
        stream.report = {}  # the other instance's tracks are the current ones
        stream.state = StreamState.standby
        stream.restart_at = stream.yield_to = stream.death = None
        stream.untracked = 0
        stream.error = (
            f"camera {stream.record.spec.camera} is tracked by another instance "
            f"({', '.join(others)}); this one takes over when that one stops"
        )
        log.info("stream %s: standing by for %s", stream.record.id, ", ".join(others))

    def _stand_by_or_spawn(self, stream: _Stream, others: builtins.list[str]) -> None:
        if others:
            self._stand_by(stream, others)
        else:
            stream.error = None
            self._spawn(stream)

    def _fold(self, stream: _Stream) -> None:
        """Add an ended worker's counters to the stream's, so that they survive it."""
        ended = stream.report.pop("counters", None) or {}
        stream.carried = {k: stream.carried.get(k, 0) + v for k, v in ended.items()}

    def _spawn(self, stream: _Stream) -> None:
        spec = stream.record.spec
        context = StreamContext(
            spec=spec,
            prefix=self._prefix,
            zenoh=self._zenoh,
            instance=self.instance,
            resources=self._resources,
            recordings_dir=self.recordings_dir(spec.camera),
            database=self._store.path,
            frame_limit=self._frame_limit,
            log_level=self._log_level,
            sinks=self._sinks,
        )
        stream.stop = shared_flag(self._ctx)
        # A pipe whose only write end the worker holds (a Queue's is shared with the service
        # and written by a thread): a report cut short by the worker's death then reads as the
        # end of the pipe, where the Queue's reader waited for its rest for ever; and a worker
        # whose service died gets EPIPE, where a Queue's thread waited for room for ever.
        stream.updates, reports = self._ctx.Pipe(duplex=False)
        stream.process = self._ctx.Process(
            target=stream_main,
            args=(context, os.getpid(), stream.stop, reports),
            name=f"vtrack-stream-{spec.camera}",
            daemon=True,
        )
        stream.process.start()
        stream.watch = ProcessWatch(stream.process.pid)
        reports.close()  # the worker has its own copy now
        stream.started_at = time.monotonic()
        stream.worker_error = None
        stream.starts += 1
        stream.state = StreamState.starting
        stream.restart_at = None
        if stream.death is not None:  # said until the new worker has lived QUICK seconds
            stream.error = f"{stream.death}; restarted"
        log.info("stream %s: worker %d started", spec.camera, stream.process.pid)

    def _halt(self, *streams: _Stream) -> None:
        """Stop the workers of ``streams`` together: each gets :data:`STOP_GRACE` seconds to
        close its recording and session, then is killed. Their reports are read meanwhile: a
        worker that cannot send its report (its pipe full) cannot finish."""
        running = [stream for stream in streams if stream.process is not None]
        for stream in running:
            stream.stop.value = True
            if not stream.process.is_alive():
                how = describe_exit(stream.process.exitcode)
                log.info("stream %s: worker had ended (%s)", stream.record.id, how)
        deadline = time.monotonic() + STOP_GRACE
        while time.monotonic() < deadline:
            alive = [stream for stream in running if stream.process.is_alive()]
            if not alive:
                break
            pipes = [stream.updates for stream in alive]
            sentinels = [stream.process.sentinel for stream in alive]
            wait_for_any([*pipes, *sentinels], timeout=deadline - time.monotonic())
            for stream in alive:
                self._drain(stream)
        for stream in running:
            process = stream.process
            if process.is_alive():
                log.warning("stream %s: worker did not stop in time; killed", stream.record.id)
                process.kill()
                process.join(5.0)
            self._drain(stream)
            self._fold(stream)
            process.close()
            stream.process = None
            if stream.watch is not None:
                stream.watch.close()
            stream.updates.close()

    def _drain(self, stream: _Stream) -> None:
        while True:
            try:
                if not stream.updates.poll():
                    return
                update = stream.updates.recv()
            except (EOFError, OSError, ValueError):  # the worker is gone (mid-report, maybe)
                return
            if update.get("state") == StreamState.failed.value:
                stream.worker_error = update.get("error")
                continue
            stream.report = update
            if stream.state is StreamState.starting:
                stream.state = StreamState.waiting

    def _supervise(self) -> None:
        while not self._stopping.wait(self._check_interval):
            try:
                with self._lock:
                    for stream in list(self._streams.values()):
                        self._check(stream)
            except Exception:
                log.exception("stream supervision failed; trying again")

    def _arbitrate(self) -> None:
        """One tracker per camera across instances. A standing-by stream starts once no other
        instance tracks its camera. Of two instances that both track a camera (each started it
        before the other's token reached it, or a standby took over while the tracker's worker
        was restarting), the younger stops its worker and stands by."""
        while not self._stopping.wait(ARBITRATION_INTERVAL):
            try:
                if self._name is not None:
                    self._follow_table()
                live = self._live_instances()
                with self._lock:
                    streams = list(self._streams.values())
                for stream in streams:
                    if stream.state in (StreamState.stopped, StreamState.failed):
                        continue
                    camera = stream.record.spec.camera
                    others = self._other_trackers(camera)
                    owner = _owner_of(camera, live) if live else None
                    with self._lock:
                        if (
                            stream.stopping
                            or stream.state in (StreamState.stopped, StreamState.failed)
                            or self._streams.get(stream.record.id) is not stream
                        ):
                            continue  # stopped, failed or removed meanwhile
                        # [its owner] when the camera belongs to another instance, else []
                        elsewhere = [owner] if owner is not None and owner != self._name else []
                        theirs = bool(elsewhere)
                        if stream.discovering:
                            stream.discovering = False
                            self._stand_by_or_spawn(stream, others or elsewhere)
                            continue
                        if stream.state is StreamState.standby:
                            # Untracked at two looks in a row: a tracker whose worker is
                            # restarting (1-2 s) is not taken over, one that is gone is. A
                            # spread camera is taken by its owner (by anyone, when its owner
                            # has not taken it for UNOWNED_LOOKS looks).
                            stream.untracked = 0 if others else stream.untracked + 1
                            waited = UNOWNED_LOOKS if theirs else 2
                            if stream.untracked >= waited:
                                stream.unowned = theirs
                                self._stand_by_or_spawn(stream, others)
                            continue
                        if theirs and not others and not stream.yield_to and not stream.unowned:
                            # another instance joined, and the camera hashes to it now
                            log.info("stream %s: moves to instance %s", stream.record.id, owner)
                            if stream.process is None:
                                self._stand_by(stream, elsewhere)
                            else:
                                stream.yield_to = elsewhere
                                stream.stop.value = True
                            continue
                        first = [i for i in others if i < self.instance]  # older instances
                        if not first or stream.yield_to:
                            continue
                        log.warning("stream %s: also tracked by %s", stream.record.id, first)
                        if stream.process is None:  # dead, waiting to restart
                            self._stand_by(stream, first)
                        else:  # the supervisor stands it by once the worker is gone
                            stream.yield_to = first
                            stream.stop.value = True
            except Exception:
                log.exception("stream arbitration failed; trying again")

    def _check(self, stream: _Stream) -> None:
        if stream.state in (StreamState.stopped, StreamState.standby) or stream.stopping:
            return
        if stream.process is None:
            if stream.restart_at is not None and time.monotonic() >= stream.restart_at:
                self._spawn(stream)
            return
        self._drain(stream)
        if stream.process.is_alive():
            if stream.quick_deaths and time.monotonic() - stream.started_at > QUICK:
                stream.quick_deaths = 0
                stream.error = stream.death = None
            return
        if stream.watch is not None and stream.watch.alive():
            # multiprocessing says ended (exit code 255 for every worker of a fork server
            # that died) while the process still runs: its parent-death signal ends it at
            # once; a replacement starts only then, so one camera never has two trackers
            return
        if stream.watch is not None:
            stream.watch.close()
        if not self._deaths.replace_now(stream.process.pid, stream.process.exitcode):
            return  # the service stops, or may: shutdown() ends the stream
        how = describe_exit(stream.process.exitcode)
        lived = time.monotonic() - stream.started_at
        self._drain(stream)  # what it said since the look above: why it failed, say
        stream.process.close()
        stream.process = None
        stream.updates.close()
        if stream.yield_to:  # stopped to make way for another instance: no death
            self._stand_by(stream, stream.yield_to)
            return
        self._fold(stream)
        stream.quick_deaths = stream.quick_deaths + 1 if lived < QUICK else 1
        reason = stream.death = stream.worker_error or f"the worker process died ({how})"
        if stream.quick_deaths >= MAX_QUICK_DEATHS:
            stream.state = StreamState.failed
            stream.error = f"{reason}; gave up after {stream.quick_deaths} quick restarts"
            log.error("stream %s failed: %s", stream.record.id, stream.error)
            return
        delay = min(2.0 ** (stream.quick_deaths - 1), 30.0)
        stream.error = f"{reason}; restarting in {delay:g} s"
        stream.restart_at = time.monotonic() + delay
        log.warning("stream %s: %s", stream.record.id, stream.error)

    def _state(self, stream: _Stream) -> StreamState:
        if stream.state in (
            StreamState.stopped,
            StreamState.failed,
            StreamState.starting,
            StreamState.standby,
        ):
            return stream.state
        if stream.process is None:
            return StreamState.starting
        return StreamState(stream.report.get("state", StreamState.waiting.value))

    def _status(self, stream: _Stream) -> StreamStatus:
        report = stream.report
        record = stream.record
        current = report.get("counters") or {}
        counters = StreamCounters(
            **{k: stream.carried.get(k, 0) + current.get(k, 0) for k in StreamCounters.model_fields}
        )
        last = report.get("last_frame_at")
        recordings = sorted(self.recordings_dir(record.id).glob("*.mcap"))
        try:
            choice = choose_detector(record.spec.detector, self._resources)
        except OptionsError:  # the model went away: the worker says so in error
            choice = None
        try:
            tracker = choose_networks(record.spec.tracker, self._resources).tracker
        except OptionsError:  # likewise
            tracker = None
        return StreamStatus(
            detector=None if choice is None else choice.options,
            detector_warning=None if choice is None else choice.warning,
            tracker=tracker,
            analytics=report.get("analytics"),
            id=record.id,
            camera=record.spec.camera,
            state=self._state(stream),
            created_at=_utc(record.created_at),
            stopped_at=_utc(record.stopped_at) if record.stopped_at else None,
            counters=counters,
            fps=report.get("fps"),
            input_fps=report.get("input_fps"),
            latency=report.get("latency"),
            latency_p95=report.get("latency_p95"),
            last_frame_at=_utc(last) if last else None,
            errors=report.get("errors", []),
            error=stream.error if stream.state is not StreamState.stopped else None,
            worker_pid=stream.process.pid if stream.process is not None else None,
            worker_starts=stream.starts,
            keys=self._keys(record.spec.camera).as_dict(),
            recordings=[f"/v1/streams/{record.id}/recordings/{p.name}" for p in recordings],
            spec=record.spec,
        )


def _utc(timestamp: float) -> datetime:
    return datetime.fromtimestamp(timestamp, tz=UTC)


def _owner_of(camera: str, instances: list[str]) -> str:
    """Rendezvous hashing: of ``instances``, the one with the highest weight for ``camera``
    (SHA-256 of both: the same on every instance and across restarts)."""
    return max(instances, key=lambda name: hashlib.sha256(f"{camera}\0{name}".encode()).digest())
