"""The HTTP API against a real server on loopback: upload, follow, download, validate."""

from __future__ import annotations

import base64
import importlib.metadata
import io
import json
import re
import shutil
from concurrent.futures import ThreadPoolExecutor
from datetime import datetime

import av
import cv2
import jsonschema
import numpy as np
import pytest
from mcap.reader import make_reader

from api_schemas.streams import StreamState
from service.outputs.h264 import nal_unit_types
from tests.service.conftest import (
    FAST_OPTIONS,
    Server,
    error_of,
    metrics,
    schema_for,
    submit,
    wait_for,
    wait_for_frames,
    wait_for_state,
)

pytestmark = pytest.mark.slow


@pytest.fixture(scope="module")
def server(tmp_path_factory):
    server = Server(tmp_path_factory.mktemp("api") / "data", workers=2).start()
    yield server
    server.stop()


@pytest.fixture(scope="module")
def client(server):
    with server.client() as client:
        yield client


LABELS = {"camera": "entrance-2", "site": "store-042", "recorded": "2026-11-26T08:00:00+01:00"}


@pytest.fixture(scope="module")
def finished_job(client, pets_cut):
    """One job with every output, followed to its end through the event stream."""
    options = {"formats": ["json", "mcap", "mot", "mp4"], "labels": LABELS}
    response = submit(client, pets_cut, options)
    assert response.status_code == 202, response.text
    created = response.json()
    assert response.headers["location"] == created["status_url"]
    events = []
    with client.stream("GET", created["events_url"], timeout=120.0) as stream:
        assert stream.headers["content-type"].startswith("text/event-stream")
        name = None
        for line in stream.iter_lines():
            if line.startswith("event: "):
                name = line.removeprefix("event: ")
            elif line.startswith("data: "):
                events.append((name, json.loads(line.removeprefix("data: "))))
                if name == "end":
                    break
    status = client.get(created["status_url"]).json()
    return created, events, status


def test_events_stream_progress_to_the_end(finished_job):
    _created, events, status = finished_job
    names = [name for name, _ in events]
    assert names[-1] == "end" and set(names[:-1]) <= {"progress"}
    assert events[-1][1]["state"] == "succeeded", events[-1]
    for _, event in events:
        jsonschema.validate(event, schema_for("ProgressEvent"))
    done = [event["progress"]["frames_done"] for _, event in events]
    assert done == sorted(done) and done[-1] == 24
    assert any(event["state"] == "running" for _, event in events)
    # the time left, from the rate of the frames read so far; none once the job is done
    for _, event in events:
        progress = event["progress"]
        if event["state"] == "running" and 0 < progress["frames_done"] < 24:
            assert progress["eta_seconds"] > 0, event
    assert any(event["progress"]["eta_seconds"] for _, event in events)
    assert status["progress"]["eta_seconds"] is None
    assert status["options"]["preset"] is None  # a people job uses no correlation preset
    assert status["state"] == "succeeded" and status["progress"]["fraction"] == 1.0
    assert set(status["links"]["results"]) == {"json", "mcap", "mot", "mp4"}
    jsonschema.validate(status, schema_for("JobStatus"))


def _download(client, status, fmt):
    response = client.get(status["links"]["results"][fmt])
    assert response.status_code == 200, response.text
    return response


def _json_options(client, status: dict) -> dict:
    return _download(client, status, "json").json()["options"]


def test_json_result_matches_the_schema(client, finished_job):
    _, _, status = finished_job
    response = _download(client, status, "json")
    assert response.headers["content-type"] == "application/json"
    document = response.json()
    jsonschema.validate(document, schema_for("Trajectories"))
    assert document["job_id"] == status["id"] and document["mode"] == "people"
    # what a pipeline needs to join and trace the result, without the job (deleted by then)
    assert document["vtrack_version"] == importlib.metadata.version("visual-tracking")
    # the options as given, but for the detector: the one that ran ('auto' without a CNN model
    # in this service: the embedded one), and the pose and re-identification networks: none
    ran = {
        **status["options"],
        "detector": {**status["options"]["detector"], "name": "default"},
        "tracker": {**status["options"]["tracker"], "pose": False, "reid": False},
    }
    assert status["options"]["detector"]["name"] == "auto"
    assert document["options"] == ran and status["options"]["labels"] == LABELS
    assert document["warnings"] == status["warnings"]
    assert document["video"]["frames_read"] == 24 and document["frames_processed"] == 24
    assert (document["video"]["width"], document["video"]["height"]) == (480, 360)
    assert document["tracks"], "nobody was tracked in 2.4 s of PETS09-S2L1"
    for track in document["tracks"]:
        stamps = [point["timestamp"] for point in track["frames"]]
        assert stamps == sorted(stamps)
        for point in track["frames"]:
            # Capture times come from the video position (10 fps), not the clock.
            assert point["timestamp"] == pytest.approx(point["frame_index"] / 10.0)
            assert [p["name"] for p in point["parts"]] == document["part_names"]


def test_the_json_result_comes_compressed_to_clients_that_take_gzip(client, finished_job):
    # an hour of video is hundreds of MB of JSON, which compresses about 7 to 1
    url = finished_job[2]["links"]["results"]["json"]
    plain = client.get(url, headers={"Accept-Encoding": "identity"})
    packed = client.get(url, headers={"Accept-Encoding": "br;q=1.0, gzip;q=0.8"})
    assert plain.status_code == packed.status_code == 200
    assert "content-encoding" not in plain.headers
    assert packed.headers["content-encoding"] == "gzip"
    assert plain.headers["vary"] == packed.headers["vary"] == "Accept-Encoding"
    assert packed.json() == plain.json()  # httpx undoes the gzip, as browsers do
    assert int(packed.headers["content-length"]) * 4 < int(plain.headers["content-length"])
    assert packed.headers["etag"] != plain.headers["etag"]  # two representations
    refused = client.get(url, headers={"Accept-Encoding": "gzip;q=0, *"})
    assert "content-encoding" not in refused.headers
    again = client.get(
        url, headers={"Accept-Encoding": "gzip", "If-None-Match": packed.headers["etag"]}
    )
    assert again.status_code == 304 and again.headers["vary"] == "Accept-Encoding"


def test_mot_result_lists_the_json_boxes_in_mot_pixels(client, finished_job):
    _, _, status = finished_job
    text = _download(client, status, "mot").text
    rows = np.array([[float(v) for v in line.split(",")] for line in text.splitlines()])
    assert rows.shape[1] == 10
    assert np.all(rows[:, 7:] == -1) and np.all(rows[:, 0] >= 1)
    trajectories = _download(client, status, "json").json()
    expected = sorted(
        # MOTChallenge counts frames and pixels from 1; the JSON from 0.
        (p["frame_index"] + 1, t["track_id"], p["box"]["x"] + 1, p["box"]["y"] + 1)
        for t in trajectories["tracks"]
        for p in t["frames"]
    )
    got = sorted((int(r[0]), int(r[1]), r[2], r[3]) for r in rows)
    assert len(got) == len(expected)
    for (f1, i1, x1, y1), (f2, i2, x2, y2) in zip(got, expected, strict=True):
        assert (f1, i1) == (f2, i2)
        assert x1 == pytest.approx(x2, abs=0.01) and y1 == pytest.approx(y2, abs=0.01)


def _mcap_messages(data: bytes) -> tuple[dict[str, str], dict[str, list]]:
    """Schema name per topic, and per topic (log time, publish time, document) of every
    message, each validated against its channel's stored JSON Schema."""
    reader = make_reader(io.BytesIO(data))
    summary = reader.get_summary()
    topics = {c.topic: c for c in summary.channels.values()}
    for channel in topics.values():
        assert channel.message_encoding == "json"
        assert summary.schemas[channel.schema_id].encoding == "jsonschema"
    counts = summary.statistics.channel_message_counts
    assert {
        channel.topic: counts[cid] for cid, channel in summary.channels.items()
    } == dict.fromkeys(topics, 24)
    schemas = {
        topic: json.loads(summary.schemas[channel.schema_id].data)
        for topic, channel in topics.items()
    }
    by_topic: dict[str, list] = {topic: [] for topic in topics}
    for _schema, channel, message in reader.iter_messages():
        document = json.loads(message.data)
        jsonschema.validate(document, schemas[channel.topic])
        by_topic[channel.topic].append((message.log_time, message.publish_time, document))
    names = {topic: summary.schemas[channel.schema_id].name for topic, channel in topics.items()}
    return names, by_topic


def test_mcap_result_has_images_annotations_and_tracks_at_the_same_times(client, finished_job):
    _, _, status = finished_job
    download = _download(client, status, "mcap")
    assert download.headers["content-type"] == "application/vnd.mcap"
    names, by_topic = _mcap_messages(download.content)
    assert names == {
        "/camera/image": "foxglove.CompressedVideo",
        "/camera/annotations": "foxglove.ImageAnnotations",
        "/tracks": "vtrack.FrameTracks",
    }
    images, annotations, tracks = (
        by_topic["/camera/image"],
        by_topic["/camera/annotations"],
        by_topic["/tracks"],
    )
    # The capture time of frame i at 10 fps, in every place a time is written.
    expected = [round(i * 1e8) for i in range(24)]
    for rows in (images, annotations, tracks):
        assert [log for log, _, _ in rows] == expected
        assert [publish for _, publish, _ in rows] == expected
    for (_, _, image), (_, _, annotation), (_, _, frame) in zip(
        images, annotations, tracks, strict=True
    ):
        stamp = image["timestamp"]
        assert image["format"] == "h264" and image["frame_id"] == "camera"
        assert all(p["timestamp"] == stamp for p in annotation["points"])
        assert all(t["timestamp"] == stamp for t in annotation["texts"])
        loops = [p for p in annotation["points"] if p["type"] == 2]
        assert len(loops) == len(frame["tracks"])
        assert sorted(t["text"] for t in annotation["texts"]) == sorted(
            str(t["track_id"]) for t in frame["tracks"]
        )
        for loop, track in zip(loops, frame["tracks"], strict=True):
            box = track["box"]
            # the track's box is written to 0.01 px, the drawing at full precision
            assert loop["points"][0] == pytest.approx({"x": box["x"], "y": box["y"]}, abs=0.0051)
            assert loop["points"][2] == pytest.approx(
                {"x": box["x"] + box["w"], "y": box["y"] + box["h"]}, abs=0.0101
            )
    assert any(frame["tracks"] for _, _, frame in tracks)
    metadata = next(make_reader(io.BytesIO(download.content)).iter_metadata()).metadata
    assert metadata["vtrack_version"] == importlib.metadata.version("visual-tracking")
    assert json.loads(metadata["options"]) == _json_options(client, status)
    assert any(p["type"] == 1 for _, _, a in annotations for p in a["points"])  # parts


def test_mcap_video_follows_foxglove_compressed_video(client, finished_job, pets_cut):
    # Foxglove decodes message by message: Annex B, exactly one picture per message, SPS (7)
    # and PPS (8) with every key frame (IDR, 5), no B-frames; it starts at a key frame to seek.
    _, _, status = finished_job
    _, by_topic = _mcap_messages(_download(client, status, "mcap").content)
    units = [base64.b64decode(image["data"]) for _, _, image in by_topic["/camera/image"]]
    assert all(unit.startswith((b"\x00\x00\x00\x01", b"\x00\x00\x01")) for unit in units)
    keys = [i for i, unit in enumerate(units) if 5 in nal_unit_types(unit)]
    assert keys == [0, 10, 20]  # a key frame a second at 10 fps
    assert all({7, 8} <= set(nal_unit_types(units[i])) for i in keys)
    capture = cv2.VideoCapture(str(pets_cut))
    sources = [cv2.cvtColor(capture.read()[1], cv2.COLOR_BGR2RGB) for _ in range(24)]
    capture.release()
    decoder = av.CodecContext.create("h264", "r")  # a player that seeks to 1.0 s
    for index in range(10, 24):
        pictures = decoder.decode(av.Packet(units[index]))
        assert len(pictures) == 1, f"message {index} gave {len(pictures)} pictures"
        assert int(pictures[0].pict_type) != 3  # AV_PICTURE_TYPE_B
        image = pictures[0].to_ndarray(format="rgb24")
        assert image.shape == (360, 480, 3)
        error = np.abs(image.astype(int) - sources[index].astype(int)).mean()
        assert error < 6, (index, error)  # the frame, up to compression


def test_mcap_images_can_be_jpeg(client, pets_cut):
    # for tools that read foxglove.CompressedImage only
    response = submit(client, pets_cut, {"formats": ["mcap"], "mcap_images": "jpeg"})
    assert response.status_code == 202, response.text
    status = wait_for_state(client, response.json()["id"], ("succeeded", "failed"))
    assert status["state"] == "succeeded", status
    names, by_topic = _mcap_messages(_download(client, status, "mcap").content)
    assert names["/camera/image"] == "foxglove.CompressedImage"
    for _, _, image in by_topic["/camera/image"]:
        decoded = cv2.imdecode(
            np.frombuffer(base64.b64decode(image["data"]), np.uint8), cv2.IMREAD_COLOR
        )
        assert image["format"] == "jpeg" and decoded.shape == (360, 480, 3)


def test_mp4_result_decodes(client, finished_job, tmp_path):
    _, _, status = finished_job
    response = _download(client, status, "mp4")
    assert response.headers["content-type"] == "video/mp4"
    path = tmp_path / "annotated.mp4"
    path.write_bytes(response.content)
    capture = cv2.VideoCapture(str(path))
    frames = []
    while True:
        ok, frame = capture.read()
        if not ok:
            break
        frames.append(frame)
    capture.release()
    assert len(frames) == 24 and frames[0].shape == (360, 480, 3)
    with av.open(str(path)) as container:  # H.264: what a browser plays
        assert container.streams.video[0].codec_context.name == "h264"


def test_mp4_result_plays_in_a_browser_tab_and_seeks(client, finished_job):
    _, _, status = finished_job
    url = status["links"]["results"]["mp4"]
    whole = client.get(url)
    assert whole.headers["content-disposition"].startswith("inline")  # shown, not saved
    assert whole.headers["accept-ranges"] == "bytes"
    size = len(whole.content)
    part = client.get(url, headers={"Range": "bytes=1000-1999"})
    assert part.status_code == 206
    assert part.headers["content-range"] == f"bytes 1000-1999/{size}"
    assert part.content == whole.content[1000:2000]
    beyond = client.get(url, headers={"Range": f"bytes={size}-"})
    # range errors answer as the API's others: an ErrorResponse (they were plain text, the
    # 416 empty); the family's whole sentence, once
    assert beyond.headers["content-range"] == f"bytes */{size}"
    assert error_of(beyond, "range_not_satisfiable")["detail"] == (
        f"Range 'bytes={size}-' starts beyond the end of the file ({size} bytes; Content-Range "
        "gives the size)"
    )
    for bad, reason in (("bytes=abc", "no range in it"), ("bytes=5-2", "start must be less")):
        refused = error_of(client.get(url, headers={"Range": bad}), "invalid_range")
        assert reason in refused["detail"]
    assert error_of(client.get(url, headers={"Range": "bytes=abc"}), "invalid_range")["detail"] == (
        "Range 'bytes=abc' cannot be served (no range in it): ask for bytes=START-END, "
        "bytes=START- or bytes=-LENGTH"
    )
    # a unit other than bytes is ignored, as RFC 9110 says (it was a 400): the whole file
    other = client.get(url, headers={"Range": "items=0-1"})
    assert other.status_code == 200 and other.content == whole.content
    # a client that has the file (its ETag) is told so without the body
    etag = whole.headers["etag"]
    for tags in (etag, f'"other", {etag}', f"W/{etag}", "*"):
        cached = client.get(url, headers={"If-None-Match": tags})
        assert cached.status_code == 304 and cached.content == b""
        assert cached.headers["etag"] == etag
    assert client.get(url, headers={"If-None-Match": '"other"'}).content == whole.content
    # a player or download manager asks HEAD first: the size, no body
    head = client.head(url)
    assert head.status_code == 200 and head.content == b""
    assert head.headers["content-length"] == str(size)
    assert (
        client.get(status["links"]["results"]["json"])
        .headers["content-disposition"]
        .startswith("attachment")
    )


def test_three_uploads_at_once(client, pets_short):
    with ThreadPoolExecutor(3) as pool:
        responses = list(pool.map(lambda _: submit(client, pets_short, FAST_OPTIONS), range(3)))
    assert [r.status_code for r in responses] == [202, 202, 202], [r.text for r in responses]
    ids = [r.json()["id"] for r in responses]
    assert len(set(ids)) == 3
    for job_id in ids:
        status = wait_for_state(client, job_id, ("succeeded", "failed"))
        assert status["state"] == "succeeded", status
        document = client.get(f"/v1/jobs/{job_id}/result").json()
        assert document["job_id"] == job_id and document["frames_processed"] == 8
    listed = {job["id"] for job in client.get("/v1/jobs").json()["jobs"]}
    assert set(ids) <= listed
    assert {
        j["id"] for j in client.get("/v1/jobs", params={"state": "succeeded"}).json()["jobs"]
    } >= set(ids)


def test_jobs_are_listed_a_page_at_a_time(client, pets_short):
    ids = [submit(client, pets_short, FAST_OPTIONS).json()["id"] for _ in range(3)]
    for job_id in ids:  # beside the other tests' jobs
        assert wait_for_state(client, job_id, ("succeeded", "failed"))["state"] == "succeeded"
    listed = client.get("/v1/jobs", params={"limit": 1000}).json()
    everything = [job["id"] for job in listed["jobs"]]
    paged, url, pages = [], "/v1/jobs?limit=2", 0
    while url is not None:
        page = client.get(url).json()
        assert 1 <= len(page["jobs"]) <= 2
        paged += [job["id"] for job in page["jobs"]]
        url, pages = page["next"], pages + 1
    assert paged == everything and pages == (len(everything) + 1) // 2  # newest first, once each
    first = client.get("/v1/jobs", params={"limit": 1, "state": "succeeded"}).json()
    second = client.get(first["next"]).json()  # the filter carries over
    assert "state=succeeded" in first["next"] and second["jobs"][0]["state"] == "succeeded"
    assert second["jobs"][0]["id"] != first["jobs"][0]["id"]
    # new results since a time: the jobs finished after it, a page at a time as well (the
    # module's other jobs may finish meanwhile: only this test's are known)
    finished = {j["id"]: datetime.fromisoformat(j["finished_at"]) for j in listed["jobs"]}
    earliest, *later = sorted(ids, key=finished.get)
    since = finished[earliest]
    # typed into the URL by hand, the offset's + is read as a space
    url, paged = f"/v1/jobs?limit=1&finished_after={since.isoformat()}", []
    while url is not None:
        page = client.get(url).json()
        assert len(page["jobs"]) <= 1
        paged += page["jobs"]
        url = page["next"]
    assert all(datetime.fromisoformat(job["finished_at"]) > since for job in paged)
    found = {job["id"] for job in paged}
    assert set(later) <= found and earliest not in found
    naive = client.get("/v1/jobs", params={"finished_after": "2026-11-26T08:00:00"})
    assert error_of(naive, "validation_error")["errors"][0]["loc"] == ["query", "finished_after"]
    gone = client.get("/v1/jobs", params={"before": "no-such-job"})
    assert "'no-such-job' to page from" in error_of(gone, "not_found")["detail"]


def test_unfinished_job_has_no_result_yet_and_can_be_cancelled_then_deleted(client, long_video):
    job_id = submit(client, long_video, FAST_OPTIONS).json()["id"]
    early = client.get(f"/v1/jobs/{job_id}/result", params={"format": "json"})
    # the family's whole sentence, once (the state and count of frames of the moment)
    assert re.fullmatch(
        rf"job {job_id} is (queued|running) \(\d+ of (\d+|\?) frames\): results are served "
        rf"once it has succeeded; poll /v1/jobs/{job_id}",
        error_of(early, "conflict")["detail"],
    ), early.text
    cancel = client.delete(f"/v1/jobs/{job_id}")
    assert cancel.status_code in (200, 202), cancel.text
    status = wait_for_state(client, job_id, ("cancelled", "succeeded", "failed"), timeout=60)
    assert status["state"] == "cancelled", status
    gone = client.get(f"/v1/jobs/{job_id}/result")
    assert error_of(gone, "conflict")["detail"].startswith(f"job {job_id} cancelled")
    assert client.delete(f"/v1/jobs/{job_id}").status_code == 204
    error_of(client.get(f"/v1/jobs/{job_id}"), "not_found")


def test_truncated_video_is_accepted_and_tracked_as_far_as_it_decodes(
    server, client, pets_cut, tmp_path
):
    data = pets_cut.read_bytes()
    truncated = tmp_path / "truncated.avi"
    truncated.write_bytes(data[: len(data) // 2])
    response = submit(client, truncated, FAST_OPTIONS)
    assert response.status_code == 202, response.text
    status = wait_for_state(client, response.json()["id"], ("succeeded", "failed"))
    assert status["state"] == "succeeded", status
    read = status["progress"]["frames_done"]
    assert 0 < read < 24 and status["progress"]["frames_total"] == read
    assert any(f"ended after {read} of the 24 frames" in w for w in status["warnings"])
    # FFmpeg's complaints about the cut frame stay out of the log (before: "[mjpeg @ 0x...]
    # overread 8", a line without time, level or job)
    assert not re.search(r"\[\w+ @ 0x[0-9a-f]+\]|FFMPEG", server.log())
    # the job's warning says it in the log instead
    assert f"job {status['id']}: warning: the video ended after {read} of the 24" in server.log()


def test_metrics_count_jobs_by_state_and_frames(server, client, finished_job):
    values = metrics(client)
    assert values['vtrack_jobs{state="succeeded"}'] >= 1
    assert values["vtrack_frames_processed_total"] >= 24
    assert values["vtrack_job_processing_seconds_count"] >= 1
    assert values["vtrack_workers_alive"] == 2
    # the disk's free space, as statvfs gives it to an unprivileged user, for alerts
    assert 0 < values["vtrack_data_free_bytes"] < shutil.disk_usage(server.data_dir).total


@pytest.mark.parametrize("page", ["/docs", "/redoc"])
def test_docs_pages_need_no_internet(client, page):
    """Every script, stylesheet and icon of the docs pages comes from the service itself: a
    site without internet access (FastAPI's defaults load them from a CDN) sees the docs."""
    html = client.get(page).text
    links = re.findall(r'(?:src|href)="([^"]+)"', html)
    assert links, html
    for link in links:
        assert link.startswith("/"), f"{page} loads {link} from outside the service"
        response = client.get(link)
        assert response.status_code == 200, link
        assert len(response.content) > 1000, link
    # the schema is OpenAPI 3.1, which Swagger UI renders from version 5 on
    assert client.get("/openapi.json").json()["openapi"].startswith("3.1")
    if page == "/docs":
        assert "3.1.0" in client.get("/docs-assets/swagger-ui-bundle.js").text


def test_openapi_describes_results_and_only_the_errors_a_route_gives(client):
    spec = client.get("/openapi.json").json()
    result = spec["paths"]["/v1/jobs/{job_id}/result"]["get"]["responses"]
    # a client generator gets a type for the JSON result (was: a 200 without content)
    assert result["200"]["content"]["application/json"]["schema"] == {
        "$ref": "#/components/schemas/Trajectories"
    }
    assert {"video/mp4", "application/vnd.mcap"} <= set(result["200"]["content"])
    assert "Trajectories" in spec["components"]["schemas"]
    # upload errors belong to the upload (were listed on every route)
    assert {"413", "415", "507"} <= set(spec["paths"]["/v1/jobs"]["post"]["responses"])
    assert not {"413", "415", "507"} & set(result)
    assert "401" in spec["paths"]["/metrics"]["get"]["responses"]
    # a download's own answers, each saying when it comes
    assert "without that format" in result["404"]["description"]
    assert {"304", "400", "409", "416"} <= set(result)
    recording = spec["paths"]["/v1/streams/{stream_id}/recordings/{name}"]["get"]["responses"]
    assert {"304", "400", "404", "416"} <= set(recording)


def test_metrics_list_every_stream_state_even_at_zero(client):
    # was: only the states some stream was in, so a series vanished when its count fell to 0
    text = client.get("/metrics").text
    for state in StreamState:
        assert re.search(rf'^vtrack_streams{{state="{state.value}"}} \d', text, re.M), state


def test_docs_and_openapi_are_served(client):
    assert client.get("/docs").status_code == 200
    spec = client.get("/openapi.json").json()
    assert {"/v1/jobs", "/v1/jobs/{job_id}", "/v1/jobs/{job_id}/result"} <= set(spec["paths"])
    body = spec["paths"]["/v1/jobs"]["post"]["requestBody"]["content"]["multipart/form-data"]
    assert body["schema"]["required"] == ["video"]


def _follows(client, job_id) -> bool:
    """Whether following the job's events is accepted now (the stream is closed at once)."""
    with client.stream("GET", f"/v1/jobs/{job_id}/events") as events:
        return events.status_code == 200


def test_a_queued_job_says_how_many_start_before_it(make_server, long_video, pets_short):
    # before: a queued job said nothing of its wait (a third upload to a busy service)
    server = make_server(workers=1, max_event_streams=1)
    with server.client() as client:
        first = submit(client, long_video, FAST_OPTIONS).json()["id"]
        wait_for_frames(client, first, 1)
        second, third = (submit(client, pets_short, FAST_OPTIONS).json()["id"] for _ in range(2))

        def ahead(job_id):
            return client.get(f"/v1/jobs/{job_id}").json()["progress"]["queued_ahead"]

        assert (ahead(first), ahead(second), ahead(third)) == (None, 0, 1)
        jobs = client.get("/v1/jobs").json()["jobs"]
        listed = {j["id"]: j["progress"]["queued_ahead"] for j in jobs}
        assert listed == {first: None, second: 0, third: 1}

        # followers of job events are limited (before: 1200 of them stalled the service)
        with client.stream("GET", f"/v1/jobs/{third}/events") as events:
            lines = events.iter_lines()  # kept: a dropped iterator closes the response
            assert next(lines) == "event: progress"
            refused = client.get(f"/v1/jobs/{first}/events")
            assert refused.headers["retry-after"] == "5"
            assert error_of(refused, "busy")["detail"].startswith("1 clients follow job events")
        wait_for(lambda: _follows(client, first), 10, "the place of the follower that left")
        assert client.delete(f"/v1/jobs/{second}").json()["state"] == "cancelled"
        assert ahead(third) == 0
        for job_id in (first, third):
            client.delete(f"/v1/jobs/{job_id}")
