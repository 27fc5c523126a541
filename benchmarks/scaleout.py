"""Scale-out (issue 79): service instances on one PostgreSQL database and one data folder.

    python benchmarks/scaleout.py [--parts throughput,requeue,cameras] [--workers 1]
                                  [--jobs 24] [--frames 60] [--rounds 1]
                                  [--leases 15,3] [--kills 5] [--kill-frames 600]
                                  [--kill-at 20] [--moves 5] [--cameras 2]
                                  [--video PATH] [--out scaleout.json] [--json] [--keep]

Real ``vtrack serve`` processes (:class:`devtools.testing.Server`) and a real PostgreSQL server
of the benchmark's own (:func:`tests.postgres.running_postgres`: pgserver's programs, as
``nobody`` under root, in a folder of :func:`tempfile.mkdtemp`; it needs the ``dev`` extra's
``pgserver`` wheel or ``VTRACK_POSTGRES_BIN``). Every configuration below gets a database and a
data folder of its own, shared by its instances. Jobs are the first ``--frames`` frames of the
PETS09-S2L1 video with the tests' fast options (embedded detector at 1.0x, JSON only). Three
parts:

``throughput``
    ``--jobs`` jobs uploaded round-robin to the instances, all at once, with every worker idle
    and warmed up (one job per worker first, not counted); the time runs from the first upload
    to the last job's ``finished_at``. Jobs per hour, for:

    * SQLite, 1 instance x ``--workers`` (no ``VTRACK_DATABASE_URL``: the single service);
    * PostgreSQL, 1 instance x ``--workers``;
    * PostgreSQL, 2 instances x ``--workers`` each (twice the workers in all);
    * PostgreSQL, 1 instance x 2 ``--workers`` (as many workers as the two instances).

    The ratio of the third to the second is the issue's (jobs per hour, 2 instances vs 1); on a
    machine of few cores, where twice the workers cannot run twice the jobs, the third to the
    fourth says what the distributed mode costs, and the second to the first what PostgreSQL
    costs beside SQLite. ``--rounds`` runs the four that many times, interleaved (a machine's
    load drifts; each round starts with the next of the four), and takes each one's median.

``requeue``
    For each lease of ``--leases`` (``VTRACK_JOB_LEASE_SECONDS``; 15 is the product's
    default): instances ``a`` and ``b``, one worker each. ``--kills`` times: a job of
    ``--kill-frames`` frames is uploaded (to ``a`` and ``b`` in turn); once its worker has read
    ``--kill-at`` frames, and a random share of a renewal period (a third of a lease) later (the
    kill lands at any phase of the renewals, as a machine dies at any moment; sooner once the
    job has read three quarters of its frames; a job that ended before its kill is followed by
    another), the instance running it is killed (SIGKILL of the service; its workers end with
    it). The job's row is polled in the database every 20 ms: the lease it had left at the
    kill, the kill until it is queued again (``requeued_s``), running on the survivor
    (``claimed_s``) and succeeded (its ``finished_at``); then the killed instance is started
    again, and the next job uploaded, each after another random share of a renewal period (so
    that the instances' renewals and looks and the next claim keep no phase to each other). A
    dead instance's job is queued again by another once the lease has run out: its last
    renewal (every third of a lease) plus a lease, seen at the other's next renewal look (every
    third of a lease too), so between 2/3 and 4/3 of a lease after the kill.

``cameras``
    Instances ``a`` (its Zenoh endpoint the network's hub) and ``b`` (connected to it), and
    ``--cameras`` live streams created through ``a``'s API, with names that rendezvous hashing
    spreads over both; no frames are sent (a tracked camera's stream is ``waiting``). A
    watcher session joins the network through ``a`` and follows the liveliness tokens of the
    cameras' trackers and of the instances. ``--moves`` times: once every camera is tracked by
    its owner alone (its API in state waiting or running, exactly one tracker token), and after
    a pause of one look of the arbiters and a half (each has looked at the settled spread)
    plus a random share of a look (the kill lands at any phase of the looks), ``b`` is killed
    (it, not ``a``: the watcher and ``b`` reach the network through ``a``); for each of its
    cameras: the kill until its tracker's token went (``token_gone_s``), until ``a``'s API
    says its stream is waiting or running (``survivor_api_s``) and until exactly one tracker
    token is there again, a new one (``one_token_s``); then ``b`` is started again and the
    camera moves back (``back_s``: from ``b``'s start until the spread is settled again).

Every instance of the requeue and cameras parts has one job worker. The tables go to standard
output (``--json``: the whole report instead), the report to ``--out``; ``--keep`` keeps the data
folders and the instances' logs.
"""

from __future__ import annotations

import argparse
import contextlib
import json
import os
import random
import shutil
import signal
import statistics
import sys
import tempfile
import threading
import time
import uuid
from collections.abc import Callable, Iterator
from datetime import datetime
from pathlib import Path

import httpx
import psycopg
import zenoh

# Run as a script, benchmarks/ comes first on sys.path and this file would shadow the service
# package.
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from devtools.clips import cut_video
from devtools.testing import Server, free_port, try_get, wait_for
from service.streams.keys import StreamKeys
from service.streams.manager import ARBITRATION_INTERVAL, _owner_of
from service.streams.session import ZenohOptions
from service.streams.tools import member_session, trackers_of, watch_trackers
from tests.postgres import PostgresServer, running_postgres

try:  # run as a script: benchmarks/ is on sys.path
    from _paths import SHARED_DATA
    from _report import finite, print_json
except ImportError:  # python -m benchmarks.<name> from the repository root
    from benchmarks._paths import SHARED_DATA
    from benchmarks._report import finite, print_json

DEFAULT_VIDEO = SHARED_DATA / "video" / "pets09_s2l1_480x360.avi"
FAST_OPTIONS = {"formats": ["json"], "detector": {"name": "default", "upscale": 1.0}}
"""The tests' options for jobs whose people do not matter (tests/service/conftest.py): the
embedded detector on the frames as they are, JSON only."""
PARTS = ("throughput", "requeue", "cameras")
PREFIX = "vtrack"
"""The service's default Zenoh key prefix (``VTRACK_ZENOH_PREFIX``)."""
TRACKING = ("waiting", "running")
"""A stream's states with a worker tracking its camera."""
_FINAL = ("succeeded", "failed", "cancelled")


# -- set-up ---------------------------------------------------------------------------------


class Scratch:
    """The run's folders, and a database of its own for each configuration."""

    def __init__(self, postgres: PostgresServer, folder: Path) -> None:
        self.postgres = postgres
        self.folder = folder

    def data_dir(self, label: str) -> Path:
        """A new folder holding ``data/`` (shared by the configuration's instances) and the
        instances' logs."""
        folder = self.folder / f"{label}-{uuid.uuid4().hex[:6]}"
        folder.mkdir()
        return folder / "data"

    def database(self) -> str:
        """The URL of a new, empty database."""
        name = f"bench_{uuid.uuid4().hex[:12]}"
        with psycopg.connect(self.postgres.url, autocommit=True) as connection:
            connection.execute(f"CREATE DATABASE {name}")
        return self.postgres.database_url(name)


def _fully_ready(server: Server, workers: int) -> bool:
    """``/readyz`` answers 200 with all ``workers`` ready (200 alone says one is)."""
    response = try_get(f"{server.url}/readyz")
    return (
        response is not None
        and response.status_code == 200
        and response.json().get("workers_ready") == workers
    )


def start_all(servers: list[Server], timeout: float = 120.0) -> None:
    """Start the servers one after the other (each ready before the next starts), then wait
    until each has all its workers ready."""
    for server in servers:
        server.start(timeout)
    for server in servers:
        wait_for(lambda s=server: _fully_ready(s, s.workers), timeout, "every worker ready")


@contextlib.contextmanager
def running(servers: list[Server]) -> Iterator[list[Server]]:
    """The servers started and ready; stopped (SIGTERM) at the end, however it ends."""
    try:
        start_all(servers)
        yield servers
    finally:
        for server in servers:
            server.stop()


def upload(client: httpx.Client, video: bytes, name: str) -> str:
    files = {"video": (name, video, "video/x-msvideo")}
    response = client.post("/v1/jobs", files=files, data={"options": json.dumps(FAST_OPTIONS)})
    if response.status_code != 202:
        raise RuntimeError(f"the upload was refused: {response.status_code} {response.text}")
    return response.json()["id"]


def _timestamp(text: str) -> float:
    return datetime.fromisoformat(text).timestamp()


def _spread(values: list[float | None]) -> dict:
    known = sorted(v for v in values if v is not None)
    if not known:
        return {"median": None, "max": None, "min": None, "missing": len(values)}
    return {
        "median": round(statistics.median(known), 3),
        "min": round(known[0], 3),
        "max": round(known[-1], 3),
        "missing": len(values) - len(known),
    }


def _round(value: float | None, digits: int = 3) -> float | None:
    return None if value is None else round(value, digits)


# -- throughput -----------------------------------------------------------------------------


def configurations(workers: int) -> list[dict]:
    """The throughput part's configurations (see the module's docstring)."""
    return [
        {"label": f"sqlite 1x{workers}", "database": False, "instances": 1, "workers": workers},
        {"label": f"postgres 1x{workers}", "database": True, "instances": 1, "workers": workers},
        {"label": f"postgres 2x{workers}", "database": True, "instances": 2, "workers": workers},
        {
            "label": f"postgres 1x{2 * workers}",
            "database": True,
            "instances": 1,
            "workers": 2 * workers,
        },
    ]


def _wait_final(client: httpx.Client, ids: list[str], timeout: float) -> dict[str, dict]:
    """Every job of ``ids`` in a final state (polled through one instance's job list, which
    shows every instance's jobs on a shared database): their statuses."""
    wanted = set(ids)

    def finals() -> dict[str, dict] | None:
        listed = client.get("/v1/jobs", params={"limit": 1000}).json()["jobs"]
        done = {job["id"]: job for job in listed if job["id"] in wanted}
        if len(done) == len(wanted) and all(j["state"] in _FINAL for j in done.values()):
            return done
        return None

    return wait_for(finals, timeout, f"{len(ids)} jobs to end", 0.25)


def throughput_run(scratch: Scratch, config: dict, video: Path, jobs: int) -> dict:
    """One configuration: warm-up jobs, then ``jobs`` jobs timed (see the module)."""
    data_dir = scratch.data_dir(config["label"].replace(" ", "-"))
    url = scratch.database() if config["database"] else None
    names = ["a", "b"][: config["instances"]]
    settings: dict[str, object] = {"zenoh_enabled": "false"}
    servers = []
    for name in names:
        if url is not None:
            settings.update(database_url=url, instance_name=name)
        servers.append(
            Server(data_dir, workers=config["workers"], log_level="warning", name=name, **settings)
        )
    content = video.read_bytes()
    total_workers = config["workers"] * config["instances"]
    with running(servers), contextlib.ExitStack() as stack:
        clients = [stack.enter_context(s.client(timeout=120)) for s in servers]
        # warm-up: a job per worker (each idle worker takes one), not counted
        warm = [
            upload(clients[i % len(clients)], content, video.name) for i in range(total_workers)
        ]
        _wait_final(clients[0], warm, 600)
        for server in servers:  # idle again before the clock starts
            wait_for(lambda s=server: _fully_ready(s, s.workers), 60, "every worker ready")
        load = os.getloadavg()[0]
        started = time.time()
        ids = [upload(clients[i % len(clients)], content, video.name) for i in range(jobs)]
        uploaded = time.time()
        statuses = _wait_final(clients[0], ids, 3600)
        per_instance: dict[str, int] = {}
        if url is not None:
            with psycopg.connect(url) as connection:
                rows = connection.execute(
                    "SELECT instance, count(*) FROM jobs WHERE id = ANY(%s) GROUP BY instance",
                    (ids,),
                ).fetchall()
            per_instance = {str(instance): count for instance, count in rows}
    failed = [s for s in statuses.values() if s["state"] != "succeeded"]
    finished = max(_timestamp(s["finished_at"]) for s in statuses.values() if s["finished_at"])
    seconds = finished - started
    tracking = [
        _timestamp(s["finished_at"]) - _timestamp(s["started_at"])
        for s in statuses.values()
        if s["state"] == "succeeded"
    ]
    return {
        "label": config["label"],
        "database": "postgresql" if url else "sqlite",
        "instances": config["instances"],
        "workers_per_instance": config["workers"],
        "workers_total": total_workers,
        "jobs": jobs,
        "succeeded": jobs - len(failed),
        "failed": [s.get("error") for s in failed],
        "seconds": round(seconds, 2),
        "jobs_per_hour": round(jobs / seconds * 3600, 1),
        "upload_s": round(uploaded - started, 2),
        "job_s": _spread(tracking),
        "jobs_per_instance": per_instance or {"a": jobs},
        "load_average_at_start": round(load, 2),
    }


def throughput(scratch: Scratch, video: Path, args: argparse.Namespace) -> dict:
    runs: dict[str, list[dict]] = {}
    for number in range(args.rounds):
        order = configurations(args.workers)
        order = order[number % len(order) :] + order[: number % len(order)]  # each goes first
        for config in order:
            result = throughput_run(scratch, config, video, args.jobs)
            runs.setdefault(config["label"], []).append(result)
            print(
                f"throughput round {number + 1}/{args.rounds}, {result['label']}: "
                f"{result['jobs']} jobs in {result['seconds']:.1f} s, "
                f"{result['jobs_per_hour']:.0f} jobs/h ({result['jobs_per_instance']})",
                file=sys.stderr,
            )
    summary = {
        label: {
            **{k: v for k, v in results[0].items() if k in ("database", "instances")},
            "workers_per_instance": results[0]["workers_per_instance"],
            "workers_total": results[0]["workers_total"],
            "jobs_per_hour": round(statistics.median(r["jobs_per_hour"] for r in results), 1),
            "jobs_per_hour_rounds": [r["jobs_per_hour"] for r in results],
            "job_s_median": round(statistics.median(r["job_s"]["median"] for r in results), 2),
        }
        for label, results in runs.items()
    }
    w = args.workers
    pairs = {
        f"postgres 2x{w} / postgres 1x{w} (2 instances vs 1, twice the workers)": (
            f"postgres 2x{w}",
            f"postgres 1x{w}",
        ),
        f"postgres 2x{w} / postgres 1x{2 * w} (same workers: the distributed mode's cost)": (
            f"postgres 2x{w}",
            f"postgres 1x{2 * w}",
        ),
        f"postgres 1x{w} / sqlite 1x{w} (PostgreSQL beside SQLite)": (
            f"postgres 1x{w}",
            f"sqlite 1x{w}",
        ),
    }
    # of the medians; and round by round (the two runs of a ratio minutes apart, not half an
    # hour: on a shared machine whose load changes, the steadier figure)
    ratios = {
        name: round(summary[top]["jobs_per_hour"] / summary[bottom]["jobs_per_hour"], 3)
        for name, (top, bottom) in pairs.items()
    }
    by_round = {
        name: [
            round(a["jobs_per_hour"] / b["jobs_per_hour"], 3)
            for a, b in zip(runs[top], runs[bottom], strict=True)
        ]
        for name, (top, bottom) in pairs.items()
    }
    return {"summary": summary, "ratios": ratios, "ratios_by_round": by_round, "runs": runs}


# -- requeue --------------------------------------------------------------------------------


def _job_row(connection: psycopg.Connection, job_id: str) -> dict | None:
    row = connection.execute(
        "SELECT state, instance, frames_done, lease_until, finished_at, attempts FROM jobs"
        " WHERE id = %s",
        (job_id,),
    ).fetchone()
    if row is None:
        return None
    keys = ("state", "instance", "frames_done", "lease_until", "finished_at", "attempts")
    return dict(zip(keys, row, strict=True))


def _poll_row(
    connection: psycopg.Connection,
    job_id: str,
    condition: Callable[[dict], bool],
    timeout: float,
    what: str,
) -> tuple[dict, float]:
    """Poll the job's row every 20 ms until ``condition``; the row and ``time.time()`` then."""
    found: list[tuple[dict, float]] = []

    def look() -> bool:
        row = _job_row(connection, job_id)
        if row is not None and condition(row):
            found.append((row, time.time()))
            return True
        return False

    wait_for(look, timeout, what, 0.02)
    return found[-1]


def _job_to_kill(
    connection: psycopg.Connection,
    server: Server,
    content: bytes,
    name: str,
    args: argparse.Namespace,
    phases: random.Random,
    lease: float,
) -> tuple[str, dict, float] | None:
    """Upload a job to ``server`` and wait until it is time to kill the instance running it:
    its worker has read ``--kill-at`` frames, then a random share of a renewal period (a third
    of a lease) has passed, so that the kill lands at any phase of the renewals (a machine dies
    at any moment), or the job has read three quarters of its frames. The job's id, its row
    then and when it had read ``--kill-at`` frames; ``None`` where it ended before."""
    with server.client(timeout=120) as client:
        job_id = upload(client, content, name)
    row, started_at = _poll_row(
        connection,
        job_id,
        lambda r: r["state"] != "queued" and r["frames_done"] >= args.kill_at,
        300,
        f"the job to read {args.kill_at} frames",
    )
    deadline = time.time() + phases.uniform(0, lease / 3)
    while (
        row["state"] == "running"
        and time.time() < deadline
        and row["frames_done"] < 0.75 * args.kill_frames
    ):
        time.sleep(0.02)
        row = _job_row(connection, job_id) or row
    return (job_id, row, started_at) if row["state"] == "running" else None


def requeue_lease(scratch: Scratch, video: Path, lease: float, args: argparse.Namespace) -> dict:
    """``--kills`` kills of the instance running a job, with this lease (see the module)."""
    data_dir = scratch.data_dir(f"requeue-{lease:g}")
    url = scratch.database()
    servers = {
        name: Server(
            data_dir,
            workers=1,
            log_level="info",  # the "queued again" lines
            name=name,
            database_url=url,
            instance_name=name,
            job_lease_seconds=lease,
            zenoh_enabled="false",
        )
        for name in ("a", "b")
    }
    content = video.read_bytes()
    rounds = []
    phases = random.Random(79)
    with (
        running(list(servers.values())),
        psycopg.connect(url, autocommit=True) as connection,
    ):
        for number in range(args.kills):
            target = "ab"[number % 2]
            chosen = None
            for _ in range(3):  # a job that ended before its kill is followed by another
                chosen = _job_to_kill(
                    connection, servers[target], content, video.name, args, phases, lease
                )
                if chosen is not None:
                    break
                print(
                    f"requeue: the job ended before its kill; another ({lease:g} s)",
                    file=sys.stderr,
                )
            if chosen is None:
                raise RuntimeError(
                    "three jobs ended before their kill: give them more frames (--kill-frames)"
                )
            job_id, before, started_at = chosen
            victim = before["instance"]
            survivor = "b" if victim == "a" else "a"
            killed = time.time()
            servers[victim].kill()
            requeued, requeued_at = _poll_row(
                connection,
                job_id,
                lambda r, v=victim: r["instance"] != v,
                10 * lease + 60,
                "the job to be queued again",
            )
            claimed, claimed_at = _poll_row(
                connection,
                job_id,
                lambda r: r["state"] != "queued",
                120,
                "the job to be claimed again",
            )
            final, _ = _poll_row(
                connection, job_id, lambda r: r["state"] in _FINAL, 600, "the job to end"
            )
            result = {
                "victim": victim,
                "uploaded_to": target,
                "frames_at_kill": before["frames_done"],
                "kill_delay_s": _round(killed - started_at),
                "lease_left_s": _round(before["lease_until"] - killed),
                "requeued_s": _round(requeued_at - killed),
                "state_seen_requeued": requeued["state"],
                "after_lease_s": _round(requeued_at - before["lease_until"]),
                "claimed_s": _round(claimed_at - killed),
                "claimed_by": claimed["instance"],
                "succeeded_s": _round(final["finished_at"] - killed)
                if final["state"] == "succeeded"
                else None,
                "final_state": final["state"],
                "ran_on": final["instance"],
                "attempts": final["attempts"],
            }
            rounds.append(result)
            print(
                f"requeue, lease {lease:g} s, kill {number + 1}/{args.kills} of {victim} at frame "
                f"{result['frames_at_kill']}: lease left {result['lease_left_s']:.2f} s, queued "
                f"again {result['requeued_s']:.2f} s, running on {survivor} "
                f"{result['claimed_s']:.2f} s, {final['state']} {result['succeeded_s']} s",
                file=sys.stderr,
            )
            # started again, and the next job uploaded, each after a random share of a renewal
            # period: else the instances' renewals and looks, and the next claim (whose lease
            # holds until the first renewal), would keep one phase to each other (this loop
            # follows the job that the survivor queued again), and the wait after a lease ran
            # out would be the same kill after kill
            time.sleep(phases.uniform(0, lease / 3))
            start_all([servers[victim]])
            time.sleep(phases.uniform(0, lease / 3))
        logs = {name: server.log() for name, server in servers.items()}
    lost_lines = sum(
        log.count("queued again: the instance running it was lost") for log in logs.values()
    )
    return {
        "lease_s": lease,
        "kills": len(rounds),
        "job_frames": args.kill_frames,
        "kill_at_frame": args.kill_at,
        "rounds": rounds,
        "requeued_s": _spread([r["requeued_s"] for r in rounds]),
        "claimed_s": _spread([r["claimed_s"] for r in rounds]),
        "succeeded_s": _spread([r["succeeded_s"] for r in rounds]),
        "lease_left_s": _spread([r["lease_left_s"] for r in rounds]),
        "after_lease_s": _spread([r["after_lease_s"] for r in rounds]),
        "all_succeeded_once_more": all(
            r["final_state"] == "succeeded" and r["attempts"] == 2 and r["ran_on"] != r["victim"]
            for r in rounds
        ),
        "requeue_log_lines": lost_lines,
    }


# -- cameras --------------------------------------------------------------------------------


def cameras_split(count: int) -> list[str]:
    """``count`` camera names (at least 2) that rendezvous hashing gives to both ``a`` and
    ``b``, as tests/scaleout/test_cameras.py picks them."""
    names = [f"cam{index}" for index in range(100)]
    for start in range(len(names) - count):
        chosen = names[start : start + count]
        if {_owner_of(camera, ["a", "b"]) for camera in chosen} == {"a", "b"}:
            return chosen
    raise RuntimeError("no split of camera names")  # 100 names always split


class TokenWatch:
    """The tracker tokens of each camera and the instances' tokens, as a session on the
    network sees them, with the time of each change (``time.monotonic()``)."""

    def __init__(self, session: zenoh.Session, cameras: list[str]) -> None:
        self._lock = threading.Lock()
        self.live: dict[str, set[str]] = {camera: set() for camera in cameras}
        self.most: dict[str, int] = dict.fromkeys(cameras, 0)  # tokens of a camera at once
        self.events: dict[str, list[tuple[float, str, bool]]] = {c: [] for c in cameras}
        self.instance_events: list[tuple[float, str, bool]] = []
        self._subscribers = []
        for camera in cameras:
            keys = StreamKeys(PREFIX, camera)
            self._subscribers.append(
                watch_trackers(session, keys, lambda i, alive, c=camera: self._changed(c, i, alive))
            )
        self._subscribers.append(
            session.liveliness().declare_subscriber(
                f"{PREFIX}/instances/*", self._instance_changed, history=True
            )
        )

    def _changed(self, camera: str, instance: str, alive: bool) -> None:
        with self._lock:
            self.events[camera].append((time.monotonic(), instance, alive))
            if alive:
                self.live[camera].add(instance)
            else:
                self.live[camera].discard(instance)
            self.most[camera] = max(self.most[camera], len(self.live[camera]))

    def _instance_changed(self, sample: zenoh.Sample) -> None:
        name = str(sample.key_expr).rsplit("/", 1)[-1]
        alive = sample.kind == zenoh.SampleKind.PUT
        with self._lock:
            self.instance_events.append((time.monotonic(), name, alive))

    def tokens(self, camera: str) -> set[str]:
        with self._lock:
            return set(self.live[camera])

    def since(self, camera: str, moment: float) -> list[tuple[float, str, bool]]:
        with self._lock:
            return [e for e in self.events[camera] if e[0] >= moment]

    def instance_gone(self, name: str, moment: float) -> float | None:
        with self._lock:
            return next(
                (
                    t
                    for t, n, alive in self.instance_events
                    if t >= moment and n == name and not alive
                ),
                None,
            )

    def close(self) -> None:
        for subscriber in self._subscribers:
            with contextlib.suppress(Exception):
                subscriber.undeclare()


def _stream_state(server: Server, camera: str) -> str | None:
    try:
        with server.client(timeout=5) as client:
            response = client.get(f"/v1/streams/{camera}")
    except httpx.TransportError:
        return None
    return response.json()["state"] if response.status_code == 200 else None


def _settled(servers: dict[str, Server], owners: dict[str, str], watch: TokenWatch) -> bool:
    """Every camera tracked by its owner alone (APIs) and by exactly one token (Zenoh)."""
    for camera, owner in owners.items():
        if len(watch.tokens(camera)) != 1:
            return False
        for name, server in servers.items():
            tracking = _stream_state(server, camera) in TRACKING
            if tracking != (name == owner):
                return False
    return True


def _one_move(
    servers: dict[str, Server], owners: dict[str, str], watch: TokenWatch, moved: list[str]
) -> dict:
    """Kill ``b`` (the spread settled), follow its cameras to ``a``, start ``b`` again and
    wait until the spread is settled again."""
    old = {camera: watch.tokens(camera) for camera in moved}
    killed = time.monotonic()
    servers["b"].kill()
    seen_api: dict[str, float] = {}

    def arrived() -> bool:
        for camera in set(moved) - set(seen_api):
            if _stream_state(servers["a"], camera) in TRACKING:
                seen_api[camera] = time.monotonic() - killed
        return len(seen_api) == len(moved) and all(
            len(tokens := watch.tokens(camera)) == 1 and not tokens & old[camera]
            for camera in moved
        )

    wait_for(arrived, 120, "b's cameras tracked by a", 0.02)
    presence = watch.instance_gone("b", killed)
    per_camera = {}
    for camera in moved:
        events = watch.since(camera, killed)
        gone = next((t for t, i, alive in events if not alive and i in old[camera]), None)
        new = next((t for t, i, alive in events if alive and i not in old[camera]), None)
        per_camera[camera] = {
            "token_gone_s": _round(None if gone is None else gone - killed),
            "survivor_api_s": _round(seen_api[camera]),
            "one_token_s": _round(None if new is None else new - killed),
        }
    restarted = time.monotonic()
    start_all([servers["b"]])
    wait_for(lambda: _settled(servers, owners, watch), 120, "the spread settled again", 0.1)
    return {
        "instance_token_gone_s": _round(None if presence is None else presence - killed),
        "cameras": per_camera,
        "back_s": _round(time.monotonic() - restarted),
    }


def camera_moves(scratch: Scratch, args: argparse.Namespace) -> dict:
    data_dir = scratch.data_dir("cameras")
    url = scratch.database()
    hub = f"tcp/127.0.0.1:{free_port()}"
    common: dict[str, object] = {"database_url": url, "workers": 1, "log_level": "info"}
    servers = {
        "a": Server(
            data_dir, name="a", instance_name="a", zenoh_listen=json.dumps([hub]), **common
        ),
        "b": Server(
            data_dir,
            name="b",
            instance_name="b",
            zenoh_listen=json.dumps([f"tcp/127.0.0.1:{free_port()}"]),
            zenoh_connect=json.dumps([hub]),
            **common,
        ),
    }
    cameras = cameras_split(args.cameras)
    owners = {camera: _owner_of(camera, ["a", "b"]) for camera in cameras}
    moved = [camera for camera in cameras if owners[camera] == "b"]
    rounds = []
    with running(list(servers.values())):
        with servers["a"].client() as client:
            for camera in cameras:
                response = client.post("/v1/streams", json={"camera": camera})
                if response.status_code != 201:
                    raise RuntimeError(f"stream {camera} refused: {response.text}")
        session = member_session(ZenohOptions(listen=(hub,)))
        watch = TokenWatch(session, cameras)
        try:
            wait_for(lambda: _settled(servers, owners, watch), 120, "the cameras spread", 0.2)
            phases = random.Random(79)
            for number in range(args.moves):
                # every arbiter looks at the settled spread at least once (a standby's count of
                # looks that found its camera untracked, from the hand-over, starts again at 0),
                # then the kill comes at a random phase of the looks
                time.sleep(ARBITRATION_INTERVAL + 0.5 + phases.uniform(0, ARBITRATION_INTERVAL))
                result = _one_move(servers, owners, watch, moved)
                rounds.append(result)
                print(
                    f"cameras, kill {number + 1}/{args.moves} of b: "
                    + ", ".join(
                        f"{c}: token gone {v['token_gone_s']} s, a's API {v['survivor_api_s']} s, "
                        f"one token {v['one_token_s']} s"
                        for c, v in result["cameras"].items()
                    )
                    + f"; back on b {result['back_s']} s after its start",
                    file=sys.stderr,
                )
            final_tokens = {
                camera: len(trackers_of(session, StreamKeys(PREFIX, camera))) for camera in cameras
            }
        finally:
            watch.close()
            session.close()

    def every(name: str) -> list[float | None]:
        return [r["cameras"][c][name] for r in rounds for c in moved]

    return {
        "cameras": cameras,
        "owners": owners,
        "moved_cameras": moved,
        "moves": len(rounds),
        "rounds": rounds,
        "instance_token_gone_s": _spread([r["instance_token_gone_s"] for r in rounds]),
        "token_gone_s": _spread(every("token_gone_s")),
        "survivor_api_s": _spread(every("survivor_api_s")),
        "one_token_s": _spread(every("one_token_s")),
        "back_s": _spread([r["back_s"] for r in rounds]),
        "tokens_per_camera_at_the_end": final_tokens,
        # from the watcher's first sight of the tokens, the kills and restarts included
        "most_tokens_of_a_camera_at_once": dict(watch.most),
    }


# -- the report -----------------------------------------------------------------------------


def _mm(figures: dict) -> str:
    """'median / max s' of a :func:`_spread`."""
    if figures["median"] is None:
        return "-"
    text = f"{figures['median']:.2f} / {figures['max']:.2f} s"
    return text + (f" ({figures['missing']} never)" if figures["missing"] else "")


def print_tables(document: dict) -> None:
    if "throughput" in document:
        part = document["throughput"]
        print(f"Jobs of {document['frames']} frames, {document['jobs']} per run:\n")
        print(
            "| configuration | instances x workers | jobs per hour | rounds | job time (median) |"
        )
        print("|---|---:|---:|---|---:|")
        for label, figures in part["summary"].items():
            rounds = ", ".join(f"{v:.0f}" for v in figures["jobs_per_hour_rounds"])
            print(
                f"| {label} | {figures['instances']} x {figures['workers_per_instance']} | "
                f"{figures['jobs_per_hour']:.0f} | {rounds} | {figures['job_s_median']:.2f} s |"
            )
        print()
        for name, ratio in part["ratios"].items():
            rounds = ", ".join(f"{v:.3f}" for v in part["ratios_by_round"][name])
            print(f"{name}: {ratio:.3f} (round by round: {rounds})")
        print()
    if "requeue" in document:
        print(
            "| lease | kills | lease left at the kill | kill to queued again "
            "| to running on the survivor | to succeeded | after the lease ran out "
            "| each job once more |"
        )
        print("|---:|---:|---:|---:|---:|---:|---:|---|")
        for r in document["requeue"]:
            print(
                f"| {r['lease_s']:g} s | {r['kills']} | {_mm(r['lease_left_s'])} | "
                f"{_mm(r['requeued_s'])} | {_mm(r['claimed_s'])} | {_mm(r['succeeded_s'])} | "
                f"{_mm(r['after_lease_s'])} | {'yes' if r['all_succeeded_once_more'] else 'NO'} |"
            )
        print("(median / max from the kill)\n")
    if "cameras" in document:
        c = document["cameras"]
        print(
            "| kills | instance token gone | tracker token gone "
            "| survivor's API waiting/running | exactly one token again "
            "| back on the restarted instance |"
        )
        print("|---:|---:|---:|---:|---:|---:|")
        print(
            f"| {c['moves']} | {_mm(c['instance_token_gone_s'])} | {_mm(c['token_gone_s'])} | "
            f"{_mm(c['survivor_api_s'])} | {_mm(c['one_token_s'])} | {_mm(c['back_s'])} |"
        )
        print(
            f"(median / max from the kill; the last from the restarted instance's start; "
            f"cameras {', '.join(c['cameras'])}, {', '.join(c['moved_cameras'])} on b; at most "
            f"{max(c['most_tokens_of_a_camera_at_once'].values())} tracker token(s) of a camera "
            "at once)"
        )


def _positive_floats(text: str) -> list[float]:
    values = [float(part) for part in text.split(",") if part.strip()]
    if not values or any(not v >= 1 for v in values):
        raise argparse.ArgumentTypeError(f"leases of at least 1 s, comma-separated: {text!r}")
    return values


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument(
        "--parts", default=",".join(PARTS), help=f"of {', '.join(PARTS)} (default: all)"
    )
    parser.add_argument("--workers", type=int, default=1, help="workers per instance (default 1)")
    parser.add_argument("--jobs", type=int, default=24, help="timed jobs per run (default 24)")
    parser.add_argument(
        "--frames", type=int, default=60, help="frames of each timed job (default 60)"
    )
    parser.add_argument(
        "--rounds", type=int, default=1, help="runs of each throughput configuration (default 1)"
    )
    parser.add_argument(
        "--leases",
        type=_positive_floats,
        default=[15.0, 3.0],
        help="VTRACK_JOB_LEASE_SECONDS values, comma-separated (default 15,3)",
    )
    parser.add_argument("--kills", type=int, default=5, help="kills per lease (default 5)")
    parser.add_argument(
        "--kill-frames", type=int, default=600, help="frames of a killed job (default 600)"
    )
    parser.add_argument(
        "--kill-at", type=int, default=20, help="frames read when the kill comes (default 20)"
    )
    parser.add_argument("--moves", type=int, default=5, help="kills for cameras (default 5)")
    parser.add_argument("--cameras", type=int, default=2, help="live streams (default 2)")
    parser.add_argument("--video", type=Path, default=DEFAULT_VIDEO, help="video to cut jobs from")
    parser.add_argument(
        "--out",
        type=Path,
        default=Path("scaleout.json"),
        help="JSON report (default scaleout.json)",
    )
    parser.add_argument("--json", action="store_true", help="print the JSON report, no tables")
    parser.add_argument(
        "--keep",
        action="store_true",
        help="keep the data folders and the instances' logs (the folder is printed)",
    )
    args = parser.parse_args(argv)
    parts = [part.strip() for part in args.parts.split(",") if part.strip()]
    if not parts or set(parts) - set(PARTS):
        parser.error(f"--parts: choose from {', '.join(PARTS)}, got {args.parts!r}")
    for name in ("workers", "jobs", "frames", "rounds", "kills", "kill_frames", "kill_at", "moves"):
        if getattr(args, name) < 1:
            parser.error(f"--{name.replace('_', '-')} must be at least 1")
    if args.cameras < 2:
        parser.error("--cameras must be at least 2 (one for each instance)")
    if args.kill_at >= args.kill_frames:
        parser.error("--kill-at must be below --kill-frames")

    started = datetime.now().astimezone()
    clock = time.monotonic()
    load_before = os.getloadavg()
    document: dict = {
        "date": started.isoformat(timespec="seconds"),
        "command": " ".join(["python", "benchmarks/scaleout.py", *(argv or sys.argv[1:])]),
        "video": args.video.name,
        "frames": args.frames,
        "jobs": args.jobs,
        "options": FAST_OPTIONS,
        "cpu_count": os.cpu_count(),
    }
    folder = Path(tempfile.mkdtemp(prefix="vtrack-scaleout-"))
    (folder / "runs").mkdir()
    # a SIGTERM ends the run as Ctrl-C does: the servers stop, the folders go
    signal.signal(signal.SIGTERM, signal.default_int_handler)
    try:
        with running_postgres() as postgres:
            with psycopg.connect(postgres.url) as connection:
                version = connection.execute("SHOW server_version").fetchone()
            document["postgresql"] = version[0] if version else None
            scratch = Scratch(postgres, folder / "runs")
            if "throughput" in parts:
                video = cut_video(args.video, folder / f"clip_{args.frames}.avi", args.frames)
                document["throughput"] = throughput(scratch, video, args)
            if "requeue" in parts:
                clip = folder / f"clip_{args.kill_frames}.avi"
                video = cut_video(args.video, clip, args.kill_frames)
                document["requeue"] = [
                    requeue_lease(scratch, video, lease, args) for lease in args.leases
                ]
            if "cameras" in parts:
                document["cameras"] = camera_moves(scratch, args)
    finally:
        if args.keep:
            print(f"data folders and logs kept in {folder}", file=sys.stderr)
        else:
            shutil.rmtree(folder, ignore_errors=True)
    document["seconds"] = round(time.monotonic() - clock, 1)
    document["load_average"] = {"before": load_before, "after": os.getloadavg()}
    args.out.write_text(json.dumps(finite(document), indent=1, allow_nan=False) + "\n")
    if args.json:
        print_json(document)
    else:
        print_tables(document)
        load = document["load_average"]
        print(
            f"\n{document['seconds']:.0f} s in all, {document['cpu_count']} cores, load average "
            f"{load['before'][0]:.1f} before, {load['after'][0]:.1f} after; the report: {args.out}"
        )
    return 0


if __name__ == "__main__":
    sys.exit(main())
