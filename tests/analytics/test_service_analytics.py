"""Zones and lines of upload jobs through the service: the results, the endpoint, the refusals,
and the job's summary at a webhook receiver on loopback."""

from __future__ import annotations

import io
import json

import pytest
from mcap.reader import make_reader

from devtools.testing import Server, free_port, wait_for
from tests.delivery.receivers import SECRET, Receiver
from tests.service.conftest import FAST_OPTIONS, error_of, metrics, submit, wait_for_state

ANALYTICS = {
    "coordinates": "normalized",
    # PETS people walk across the middle of the frame, and the whole frame is a zone: the
    # first frames already have events
    "lines": [{"name": "middle", "points": [[0.5, 0.0], [0.5, 1.0]]}],
    "zones": [{"name": "all", "polygon": [[0, 0], [1, 0], [1, 1], [0, 1]], "min_dwell": 1.0}],
}


@pytest.fixture(scope="module")
def receiver():
    receiver = Receiver(free_port())
    yield receiver
    receiver.close()


@pytest.fixture(scope="module")
def server(tmp_path_factory, receiver):
    url = f"http://127.0.0.1:{receiver.server.server_port}/hook"
    webhooks = json.dumps([{"name": "ops", "url": url, "secret": SECRET}])
    folder = tmp_path_factory.mktemp("analytics")
    server = Server(folder / "data", workers=1, webhooks=webhooks).start()
    yield server
    server.stop()


def test_a_job_reports_its_events_and_counts_and_tells_the_webhook(server, receiver, long_video):
    options = {**FAST_OPTIONS, "formats": ["json", "mcap"], "analytics": ANALYTICS}
    with server.client() as client:
        created = submit(client, long_video, options, filename="gate.avi")
        assert created.status_code == 202, created.text
        job_id = created.json()["id"]
        wait_for_state(client, job_id, ("succeeded",))

        analytics = client.get(f"/v1/jobs/{job_id}/analytics").json()
        events = analytics["events"]
        assert {e["type"] for e in events} >= {"zone_entered", "dwell"}
        entered = [e for e in events if e["type"] == "zone_entered"]
        assert analytics["counts"]["zones"]["all"]["entered"] == len(entered) > 0
        assert analytics["zones"][0]["polygon"] == [[0, 0], [480, 0], [480, 360], [0, 360]]
        times = [e["timestamp"] for e in events]
        assert times == sorted(times)
        only = client.get(f"/v1/jobs/{job_id}/analytics", params={"type": "dwell"}).json()
        assert only["events"] == [e for e in events if e["type"] == "dwell"]
        assert only["counts"] == analytics["counts"]
        # the same in the JSON result, and as a channel of the MCAP
        trajectories = client.get(f"/v1/jobs/{job_id}/result", params={"format": "json"}).json()
        assert trajectories["analytics"] == analytics
        mcap = client.get(f"/v1/jobs/{job_id}/result", params={"format": "mcap"}).content
        summary = make_reader(io.BytesIO(mcap)).get_summary()
        topics = {c.topic for c in summary.channels.values()}
        assert "/analytics/events" in topics
        counted = summary.statistics.channel_message_counts
        channel = next(i for i, c in summary.channels.items() if c.topic == "/analytics/events")
        assert counted[channel] == len(events)

        # the job's summary reached the webhook, signed, once
        wait_for(lambda: any(k == f"job:{job_id}" for k, _ in receiver.received), 30, "summary")
        (body,) = [b for k, b in receiver.received if k == f"job:{job_id}"]
        assert (body["type"], body["state"], body["filename"]) == (
            "job_finished",
            "succeeded",
            "gate.avi",
        )
        assert body["analytics"] == {**analytics["counts"]}
        assert body["results"]["json"] == f"/v1/jobs/{job_id}/result?format=json"
        assert receiver.bad_signatures == 0
        wait_for(
            lambda: metrics(client).get('vtrack_events_delivered_total{sink="ops"}', 0) >= 1,
            10,
            "the delivery in the metrics",
        )
        seen = metrics(client)
        assert seen['vtrack_events_dropped_total{sink="ops"}'] == 0


def test_a_job_without_zones_has_no_analytics(server, pets_cut):
    with server.client() as client:
        job_id = submit(client, pets_cut, FAST_OPTIONS).json()["id"]
        wait_for_state(client, job_id, ("succeeded",))
        error_of(client.get(f"/v1/jobs/{job_id}/analytics"), "not_found")


@pytest.mark.parametrize(
    ("analytics", "type", "loc"),
    [
        # a bow tie: its edges cross
        (
            {"zones": [{"name": "z", "polygon": [[0, 0], [100, 100], [100, 0], [0, 100]]}]},
            "invalid_options",
            ["options", "analytics", "zones", 0, "polygon"],
        ),
        # wholly outside the 480x360 frame
        (
            {"zones": [{"name": "z", "polygon": [[600, 0], [700, 0], [700, 100]]}]},
            "invalid_options",
            ["options", "analytics", "zones", 0, "polygon"],
        ),
        (
            {"lines": [{"name": "l", "points": [[900, 10], [950, 10]]}]},
            "invalid_options",
            ["options", "analytics", "lines", 0, "points"],
        ),
        # a line of zero length: the schema's own check
        (
            {"lines": [{"name": "l", "points": [[10, 10], [10, 10]]}]},
            "validation_error",
            ["options", "analytics", "lines", 0],
        ),
        (
            {"coordinates": "normalized", "lines": [{"name": "l", "points": [[0, 0], [2, 1]]}]},
            "validation_error",
            ["options", "analytics"],
        ),
    ],
)
def test_zones_and_lines_that_cannot_be_watched_are_refused_naming_the_field(
    server, pets_cut, analytics, type, loc
):
    with server.client() as client:
        response = submit(client, pets_cut, {**FAST_OPTIONS, "analytics": analytics})
    body = error_of(response, type)
    assert [error["loc"] for error in body["errors"]] == [loc], body


def test_vtrack_analyze_writes_the_analytics_beside_the_results(pets_cut, tmp_path):
    import subprocess
    import sys

    from api_schemas.analytics import AnalyticsResult

    options = {"analytics": ANALYTICS, "detector": {"name": "default"}}
    command = [sys.executable, "-m", "service.cli", "analyze", str(pets_cut), "--quiet"]
    command += ["--format", "json", "--options", json.dumps(options), "--out-dir", str(tmp_path)]
    done = subprocess.run(command, capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr
    listed = dict(line.split("\t") for line in done.stdout.splitlines())
    assert listed["analytics"] == str(tmp_path / "analytics.json")
    saved = AnalyticsResult.model_validate_json((tmp_path / "analytics.json").read_text())
    assert saved.counts.zones["all"].entered == sum(e.type == "zone_entered" for e in saved.events)


def test_the_annotated_video_draws_the_zones_and_lines(pets_cut, tmp_path):
    import cv2
    import numpy as np

    from api_schemas.jobs import JobOptions
    from service.analysis import analyze
    from service.outputs.zones import LINE_RGB, ZONE_RGB

    def first_frame(analytics: dict | None, folder: str) -> np.ndarray:
        options = JobOptions.model_validate(
            {**FAST_OPTIONS, "formats": ["mp4"], "analytics": analytics}
        )
        result = analyze(pets_cut, options, tmp_path / folder)
        capture = cv2.VideoCapture(str(result.files["mp4"]))
        ok, frame = capture.read()
        capture.release()
        assert ok
        return cv2.cvtColor(frame, cv2.COLOR_BGR2RGB).astype(float)

    drawn = first_frame(
        {
            "lines": [{"name": "middle", "points": [[240, 20], [240, 340]]}],
            "zones": [{"name": "box", "polygon": [[40, 40], [120, 40], [120, 120], [40, 120]]}],
        },
        "drawn",
    )
    plain = first_frame(None, "plain")
    # the line's column and the zone's top edge take their colours (H.264 blurs them a little)
    for where, colour in (((slice(100, 300), 240), LINE_RGB), ((40, slice(60, 100)), ZONE_RGB)):
        assert np.abs(drawn[where] - colour).mean() < 40 < np.abs(plain[where] - colour).mean()
