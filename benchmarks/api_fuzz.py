"""The API contract under generated requests: schemathesis against a real service on loopback.

    python benchmarks/api_fuzz.py [--examples N] [--seed N] [--phases LIST] [--workers N]
                                  [--out FILE] [--json]

Starts ``vtrack serve`` with an API token (a temporary data folder, Zenoh on a free loopback
port), gives it three real jobs of a small generated video (each with every result) and two
live streams, then runs schemathesis's engine (as ``st run`` does) over every operation of
its ``/openapi.json``: the examples, coverage, fuzzing (up to ``--examples`` generated requests
per operation, valid and invalid) and stateful phases, each answer checked by every one of
schemathesis's default checks. The path parameters of generated valid requests name those jobs
and streams half the time, so that the answers of a found job, a downloaded result, a live
event stream are checked as well as 404s. Reports the requests sent (per operation and phase,
and the statuses answered), the failures per check (0: the contract is kept) and the failures
dropped as no breach (:data:`EXPECTED`), each with why and the answers behind it.

``tests/service/test_openapi_contract.py`` runs the same set-up and hooks
(:func:`fuzzed_service`, :func:`add_hooks`) with a few dozen requests per operation in the
test suite; this is its longer run.
"""

from __future__ import annotations

import argparse
import collections
import json
import os
import sys
import tempfile
import threading
import time
import zlib
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import cv2
import jsonschema_rs
import numpy as np
import schemathesis
from schemathesis.config import SchemathesisConfig
from schemathesis.generation.value import GeneratedValue
from schemathesis.specs.openapi.schemas import OpenApiSchema

# Run as a script, benchmarks/ comes first on sys.path and this file would shadow the service
# package.
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from devtools.testing import Server, wait_for

try:  # run as a script: benchmarks/ is on sys.path
    from _report import print_json
except ImportError:  # python -m benchmarks.<name> from the repository root
    from benchmarks._report import print_json

TOKEN = "api-fuzz-token"
HEADERS = {"Authorization": f"Bearer {TOKEN}"}
PHASES = ("examples", "coverage", "fuzzing", "stateful")
LIVE_STREAMS = 4
"""Streams the generated requests may leave running at once: each runs a worker process, so
the oldest are deleted beyond this (the stateful phase reads a stream just created)."""


def write_video(path: Path, frames: int = 8) -> Path:
    """A small MJPEG AVI (64x48, 10 fps) of a grey square crossing a dark frame: a video every
    job accepts and tracks in a fraction of a second."""
    writer = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*"MJPG"), 10.0, (64, 48))
    try:
        for index in range(frames):
            image = np.full((48, 64, 3), 30, np.uint8)
            image[12:36, 4 + 6 * index : 16 + 6 * index] = 160
            writer.write(image)
    finally:
        writer.release()
    return path


@dataclass
class Service:
    """The service under test and what it holds before the generated requests come."""

    server: Server
    jobs: list[str]
    """Succeeded jobs with every result: the generated reads name them."""
    jobs_to_delete: list[str]
    """Succeeded jobs the generated DELETEs name (the reads' jobs stay)."""
    streams: list[str]
    """Live streams (no camera sends them frames): the generated reads name them."""
    streams_to_delete: list[str]
    """Live streams the generated DELETEs name."""


def start_service(folder: Path, workers: int = 1) -> Service:
    """``vtrack serve`` with :data:`TOKEN`, its data in ``folder``, with three succeeded jobs of
    a small video (every result) and two live streams."""
    server = Server(folder / "data", workers=workers, log_level="warning", api_token=TOKEN)
    server.start()
    try:
        video = write_video(folder / "crossing.avi")
        with server.client() as client:
            ids = []
            for _ in range(3):
                files = {"video": (video.name, video.read_bytes(), "video/x-msvideo")}
                response = client.post("/v1/jobs", files=files)
                if response.status_code != 202:
                    raise RuntimeError(f"the upload was refused: {response.text}")
                ids.append(response.json()["id"])
            for job_id in ids:

                def finished(job_id: str = job_id) -> dict | None:
                    status = client.get(f"/v1/jobs/{job_id}").json()
                    return status if status["state"] not in ("queued", "running") else None

                status = wait_for(finished, 120, f"job {job_id}", interval=0.1)
                if status["state"] != "succeeded":
                    raise RuntimeError(f"job {job_id} {status['state']}: {status['error']}")
            for camera in ("contract", "contract-deleted"):
                response = client.post("/v1/streams", json={"camera": camera})
                if response.status_code != 201:
                    raise RuntimeError(f"the stream was refused: {response.text}")
    except BaseException:
        server.stop()
        raise
    return Service(
        server,
        jobs=ids[:2],
        jobs_to_delete=ids[2:],
        streams=["contract"],
        streams_to_delete=["contract-deleted"],
    )


def fuzz_config(examples: int, seed: int | None, phases: tuple[str, ...] = PHASES) -> dict:
    """schemathesis's configuration (as its ``schemathesis.toml`` would hold it)."""
    return {
        "headers": HEADERS,
        "seed": seed,
        # an event stream is read to its first event: a queued or running job's never ends
        "max-stream-events": 1,
        "request-timeout": 30,
        "generation": {"max-examples": examples, "database": "none"},
        "phases": {name: {"enabled": name in phases} for name in PHASES},
        "operations": [
            {
                # schemathesis 4.32.5's coverage phase crashes on this body ("Unsupported
                # type: 'Binary'"): it checks its candidates, the video part's bytes included,
                # against the options' if/then rules with jsonschema-rs. The fuzzing phase
                # generates the upload's bodies, positive and negative, all the same.
                "include-name": "POST /v1/jobs",
                "phases": {"coverage": {"enabled": False}},
            }
        ],
    }


@dataclass
class Tally:
    """What the hooks saw: requests by operation and phase, failures dropped and why."""

    requests: collections.Counter[tuple[str, str]] = field(default_factory=collections.Counter)
    statuses: collections.Counter[tuple[str, int]] = field(default_factory=collections.Counter)
    seconds: collections.Counter[str] = field(default_factory=collections.Counter)
    dropped: collections.Counter[str] = field(default_factory=collections.Counter)
    answers: dict[str, collections.Counter[str]] = field(
        default_factory=lambda: collections.defaultdict(collections.Counter)
    )
    """The answers behind the dropped failures, by reason: operation, status and the start of
    their ``detail`` (what made the service refuse, to read in the report)."""
    lock: threading.Lock = field(default_factory=threading.Lock)


def _payload(response: Any) -> dict:
    try:
        body = json.loads(response.content)
    except ValueError:
        return {}
    return body if isinstance(body, dict) else {}


# Failures that are no breach of the contract, each with why (mostly rules JSON Schema cannot
# state, which the schema therefore does not); each is recognised narrowly (an operation, a
# check, the answer and its words), and anything else fails.
EXPECTED = {
    "a generated file is no video": (
        "POST /v1/jobs answers 415 to schema-valid options with a video part of generated "
        "bytes (or none): a schema can say 'binary', not 'a video this service decodes'"
    ),
    "a frame too small": (
        "POST /v1/jobs answers 422 to a generated image (a 1x1 PNG decodes as a video of one "
        "frame) that is too small to track: a property of the video, not of the request"
    ),
    "a model the service lacks": (
        "a 422 for options that name a detector, a network or a model file this service has "
        "no model for: what it has is its configuration, which no schema knows"
    ),
    "tracker times that contradict": (
        "a 422 for tracker times out of order (max_missing above occluded_max_missing, each "
        "given or the tracker's default): JSON Schema compares no two numbers"
    ),
    "end before start": (
        "POST /v1/jobs refuses an end at or before start (422, `errors` naming it): JSON "
        "Schema compares no two numbers; the field's description says it"
    ),
    "zones or lines the geometry refuses": (
        "a 422 for zones or lines JSON Schema cannot tell apart from good ones: names that "
        "repeat between zones and lines, a zone whose edges cross or that has no area, a zone or "
        "line wholly outside the video's frame (`errors` naming the field)"
    ),
    "generated as valid, refused by the schema": (
        "schemathesis generated as schema-valid a body that the document's schema refuses (its "
        "generation does not keep every if/then/else rule), and the service refused it too"
    ),
    "deleting a running resource stops it first": (
        "DELETE of a running stream stops it (200) and of an unfinished job cancels it "
        "(200/202), keeping its record for a second DELETE (204): the documented two steps"
    ),
}

_MISSING_MODEL = (
    "model, and this service has none",
    "names a file of the service's models folder",
    "which is not there",
    "is neither a model name",
)


def refusal_reason(label: str, status: int, body: dict) -> str | None:
    """The :data:`EXPECTED` reason of a schema-valid request's refusal, or None."""
    detail = str(body.get("detail", ""))
    errors = body.get("errors")
    if label == "POST /v1/jobs" and status == 415:
        return "a generated file is no video"
    if status != 422:
        return None
    if errors is None:  # a refusal past the schema, saying why in words
        if label == "POST /v1/jobs" and "is too small to track" in detail:
            return "a frame too small"
        if any(words in detail for words in _MISSING_MODEL):
            return "a model the service lacks"
        if detail.startswith("tracker options are inconsistent: need 0 <= max_missing"):
            return "tracker times that contradict"
        return None
    after_start = [e for e in errors if e.get("loc") == ["options"] and "after start" in e["msg"]]
    if label == "POST /v1/jobs" and errors and after_start == errors:
        return "end before start"
    geometry = [e for e in errors if e.get("loc", [])[1:2] == ["analytics"] and _geometry(e)]
    if errors and geometry == errors:
        return "zones or lines the geometry refuses"
    return None


def _geometry(error: dict) -> bool:
    """Whether a check of ``analytics`` is one JSON Schema cannot state: names that repeat,
    a zone whose edges cross or that has no area, a zone or a line outside the frame."""
    words = ("names must differ", "edges", "no area", "wholly outside")
    return any(w in str(error.get("msg", "")) for w in words)


def _schema_refuses(case: Any) -> bool:
    """Whether the document's own schema refuses the body of ``case`` (for an upload, its
    options part: the video part is bytes, which a JSON Schema validator cannot take)."""
    document = case.operation.schema.raw_schema
    operation = document["paths"][case.operation.path][case.operation.method]
    content = operation.get("requestBody", {}).get("content", {})
    media = content.get(case.media_type or "", {})
    schema, body = media.get("schema"), case.body
    if schema is None or not isinstance(body, dict):
        return False
    if case.media_type == "multipart/form-data":
        schema = schema.get("properties", {}).get("options")
        if schema is None or "options" not in body:
            return False
        body = body["options"]
    # jsonschema-rs, schemathesis's own validator (Draft 2020-12, as OpenAPI 3.1's schemas)
    validator = jsonschema_rs.Draft202012Validator({**schema, "components": document["components"]})
    return not validator.is_valid(body)


def _why_expected(failure: Any, case: Any, response: Any) -> str | None:
    """The key of :data:`EXPECTED` that explains ``failure``, or None: a breach."""
    label = case.operation.label
    kind = type(failure).__name__
    body = _payload(response)
    if kind == "RejectedPositiveData" and label in ("POST /v1/jobs", "POST /v1/streams"):
        if response.status_code == 422 and _schema_refuses(case):
            return "generated as valid, refused by the schema"
        return refusal_reason(label, response.status_code, body)
    if kind == "UseAfterFree" and response.status_code == 200:
        state = body.get("state")
        if (label == "GET /v1/streams/{stream_id}" and state == "stopped") or (
            label == "GET /v1/jobs/{job_id}" and state in ("cancelled", "running")
        ):
            return "deleting a running resource stops it first"
    return None


class StreamJanitor:
    """Deletes the streams the generated requests start, beyond the newest ``keep``."""

    def __init__(self, server: Server, keep: int) -> None:
        self.server, self.keep = server, keep
        self.started: collections.deque[str] = collections.deque()
        self.lock = threading.Lock()

    def started_one(self, stream_id: str) -> None:
        with self.lock:
            self.started.append(stream_id)
            surplus = [self.started.popleft() for _ in range(len(self.started) - self.keep)]
        for old in surplus:
            self.remove(old)

    def remove(self, stream_id: str) -> None:
        # the first DELETE stops the stream (its worker ends), the second deletes it
        with self.server.client(timeout=60) as client:
            for _ in range(2):
                if client.delete(f"/v1/streams/{stream_id}").status_code not in (200, 204):
                    break

    def remove_all(self) -> None:
        with self.lock:
            left, self.started = list(self.started), collections.deque()
        for stream_id in left:
            self.remove(stream_id)


@dataclass
class Run:
    """What the hooks of :func:`add_hooks` work with: the service (known once it runs), the
    janitor of its streams, and the tally."""

    service: Service | None = None
    janitor: StreamJanitor | None = None
    tally: Tally = field(default_factory=Tally)

    def real_ids(self, method: str) -> dict[str, list[str]]:
        """The real jobs and streams that generated path parameters of ``method`` name."""
        service = self.service
        if service is None:
            return {}
        if method == "delete":
            return {"job_id": service.jobs_to_delete, "stream_id": service.streams_to_delete}
        return {"job_id": service.jobs, "stream_id": service.streams}


def add_hooks(schema: OpenApiSchema, run: Run) -> OpenApiSchema:
    """``schema`` with this run's hooks: the generated path parameters (but those of negative
    cases) name the real jobs and streams half the time, the requests are counted, the streams
    the requests start are deleted beyond a few, and the :data:`EXPECTED` failures dropped."""

    @schema.hook
    def before_generate_path_parameters(context: Any, strategy: Any) -> Any:
        operation = context.operation
        if operation is None or "_id}" not in operation.path:
            return strategy

        def named(drawn: dict) -> dict:
            # half the drawn values, chosen by the value itself: the same case each time
            for name, choices in run.real_ids(operation.method).items():
                value = drawn.get(name)
                if isinstance(value, str) and choices and zlib.crc32(value.encode()) % 2:
                    drawn = {**drawn, name: choices[zlib.crc32(value.encode()) % len(choices)]}
            return drawn

        def swapped(drawn: Any) -> Any:
            if isinstance(drawn, GeneratedValue):  # a negative case keeps what makes it so
                return drawn if drawn.meta is not None else drawn.map_value(named)
            return named(drawn) if isinstance(drawn, dict) else drawn

        return strategy.map(swapped)

    @schema.hook
    def after_call(context: Any, case: Any, response: Any) -> None:
        tally = run.tally
        phase = case.meta.phase.name.value if case.meta is not None else "explicit"
        with tally.lock:
            tally.requests[case.operation.label, phase] += 1
            tally.statuses[case.operation.label, response.status_code] += 1
            tally.seconds[case.operation.label] += response.elapsed
        if case.operation.label == "POST /v1/streams" and response.status_code == 201:
            stream_id = _payload(response).get("id")
            known = run.real_ids("get").get("stream_id", []) + run.real_ids("delete").get(
                "stream_id", []
            )
            if stream_id and stream_id not in known and run.janitor is not None:
                run.janitor.started_one(stream_id)

    @schema.hook
    def filter_failure(context: Any, failure: Any, case: Any, response: Any) -> bool:
        reason = _why_expected(failure, case, response)
        if reason is None:
            return True
        detail = str(_payload(response).get("detail", ""))
        answer = f"{case.operation.label} {response.status_code}: {detail[:60]}"
        with run.tally.lock:
            run.tally.dropped[reason] += 1
            run.tally.answers[reason][answer] += 1
        return False

    return schema


def load_schema(run: Run, config: dict) -> OpenApiSchema:
    """The ``/openapi.json`` of the run's service as schemathesis loads it, with
    :func:`add_hooks`."""
    assert run.service is not None
    schema = schemathesis.openapi.from_url(
        f"{run.service.server.url}/openapi.json",
        config=SchemathesisConfig.from_dict(config),
        headers=HEADERS,
    )
    return add_hooks(schema, run)


@contextmanager
def fuzzed_service(folder: Path, workers: int = 1) -> Iterator[tuple[Service, StreamJanitor]]:
    """:func:`start_service` in ``folder``, stopped (its streams deleted first) on leaving."""
    service = start_service(folder, workers)
    janitor = StreamJanitor(service.server, LIVE_STREAMS)
    try:
        yield service, janitor
    finally:
        try:
            janitor.remove_all()
        finally:
            service.server.stop()


def _failures(events: Iterator[Any], on_event: Callable[[Any], None]) -> dict[str, set]:
    """Distinct failures per check name, from the engine's events."""
    from schemathesis.engine import Status
    from schemathesis.engine import events as engine_events

    found: dict[str, set] = collections.defaultdict(set)
    for event in events:
        on_event(event)
        if isinstance(event, engine_events.ScenarioFinished):
            for nodes in event.recorder.checks.values():
                for node in nodes:
                    if node.status == Status.FAILURE and node.failure_info is not None:
                        failure = node.failure_info.failure
                        found[node.name].add(
                            (
                                event.recorder.label,
                                failure.title,
                                failure.message[:300],
                                node.failure_info.code_sample[:1500],
                            )
                        )
        elif isinstance(event, engine_events.NonFatalError):
            found["error"].add((event.label, event.info.title, str(event.info)[:300], ""))
        elif isinstance(event, engine_events.FatalError):
            exception = event.exception
            found["error"].add(("engine", type(exception).__name__, str(exception), ""))
    return found


def run(examples: int, seed: int, phases: tuple[str, ...], workers: int) -> dict:
    """Fuzz a fresh service; the report."""
    from schemathesis.engine import events as engine_events

    run, timings = Run(), {}

    scenario_seconds: collections.Counter[str] = collections.Counter()
    scenario_status: dict[str, str] = {}

    def on_event(event: Any) -> None:
        if isinstance(event, engine_events.PhaseFinished):
            timings[event.phase.name.value] = round(time.perf_counter() - started, 1)
        elif isinstance(event, engine_events.ScenarioFinished) and event.label:
            scenario = f"{event.phase.value} {event.label}"
            scenario_seconds[scenario] += event.elapsed_time
            scenario_status[scenario] = event.status.value + (
                f" ({event.skip_reason})" if event.skip_reason else ""
            )

    with (
        tempfile.TemporaryDirectory(prefix="vtrack-fuzz-") as scratch,
        fuzzed_service(Path(scratch), workers) as (run.service, run.janitor),
    ):
        schema = load_schema(run, fuzz_config(examples, seed, phases))
        operations = [result.ok().label for result in schema.get_all_operations()]
        started = time.perf_counter()
        failures = _failures(schemathesis.engine.from_schema(schema).execute(), on_event)
        elapsed = time.perf_counter() - started
    tally = run.tally
    per_operation: dict[str, dict[str, int]] = collections.defaultdict(dict)
    for (label, phase), count in sorted(tally.requests.items()):
        per_operation[label][phase] = count
    statuses: dict[str, dict[str, int]] = collections.defaultdict(dict)
    for (label, status), count in sorted(tally.statuses.items()):
        statuses[label][str(status)] = count
    return {
        "examples_per_operation": examples,
        "seed": seed,
        "phases": list(phases),
        "operations": len(operations),
        "requests": sum(tally.requests.values()),
        "requests_per_operation": {k: per_operation[k] for k in operations if k in per_operation},
        "statuses_per_operation": {k: statuses[k] for k in operations if k in statuses},
        "answer_seconds_per_operation": {
            k: round(tally.seconds[k], 2) for k in operations if k in tally.seconds
        },
        "failures": sum(len(found) for found in failures.values()),
        "failures_by_check": {name: len(found) for name, found in sorted(failures.items())},
        "failure_details": {
            name: sorted(" | ".join(part for part in item if part) for item in found)
            for name, found in sorted(failures.items())
        },
        "expected_failures_dropped": dict(sorted(tally.dropped.items())),
        "expected_because": {key: EXPECTED[key] for key in sorted(tally.dropped)},
        "expected_answers": {
            key: dict(tally.answers[key].most_common()) for key in sorted(tally.dropped)
        },
        "seconds": round(elapsed, 1),
        "phase_finished_at_s": timings,
        "scenario_seconds": {k: round(v, 1) for k, v in scenario_seconds.most_common()},
        "scenario_status": dict(sorted(scenario_status.items())),
        "schemathesis": schemathesis.__version__,
        "cpu_count": os.cpu_count(),
    }


def arguments(argv: list[str] | None = None) -> argparse.Namespace:
    """The command line's arguments, checked (``phases`` a tuple of names)."""
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument(
        "--examples",
        type=int,
        default=1000,
        help="most generated requests per operation in the fuzzing phase (default 1000)",
    )
    parser.add_argument("--seed", type=int, default=78, help="the generation's seed (default 78)")
    parser.add_argument(
        "--phases",
        default=",".join(PHASES),
        help=f"comma-separated phases to run (default: all, {','.join(PHASES)})",
    )
    parser.add_argument(
        "--workers", type=int, default=1, help="job worker processes of the server (default 1)"
    )
    parser.add_argument("--out", type=Path, help="also write the JSON report to this file")
    parser.add_argument("--json", action="store_true", help="print one JSON object")
    args = parser.parse_args(argv)
    if args.examples < 1:
        parser.error(f"--examples must be at least 1, got {args.examples}")
    args.phases = tuple(p.strip() for p in args.phases.split(",") if p.strip())
    if not args.phases or set(args.phases) - set(PHASES):
        parser.error(f"--phases: choose from {', '.join(PHASES)}, got {','.join(args.phases)!r}")
    return args


def main(argv: list[str] | None = None) -> int:
    args = arguments(argv)
    phases = args.phases
    report = run(args.examples, args.seed, phases, args.workers)
    if args.out is not None:
        args.out.parent.mkdir(parents=True, exist_ok=True)
        args.out.write_text(json.dumps(report, indent=1) + "\n")
    if args.json:
        print_json(report, indent=None)
    else:
        print(
            f"schemathesis {report['schemathesis']}, seed {report['seed']}, up to "
            f"{report['examples_per_operation']} generated requests per operation, phases "
            f"{', '.join(report['phases'])}"
        )
        print(f"{report['operations']} operations, {report['requests']} requests in "
              f"{report['seconds']} s")  # fmt: skip
        for label, phases_sent in report["requests_per_operation"].items():
            sent = ", ".join(f"{phase} {count}" for phase, count in phases_sent.items())
            print(f"  {label:<46}{sum(phases_sent.values()):>6}  ({sent})")
        print(f"failures: {report['failures']}")
        for name, count in report["failures_by_check"].items():
            print(f"  {name}: {count}")
            for detail in report["failure_details"][name]:
                print(f"    {detail}")
        print("expected failures dropped:")
        for reason, count in report["expected_failures_dropped"].items():
            print(f"  {count:>5}  {reason}: {EXPECTED[reason]}")
    return 1 if report["failures"] else 0


if __name__ == "__main__":
    sys.exit(main())
