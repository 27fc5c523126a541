"""Every bad request gets its status, its error type and a sentence saying what to do; tokens;
limits. The tests check the type (and where a check failed); one test per type reads its whole
sentence.

One server for the module, configured strictly: a bearer token, a 400 kB upload limit and a
one-second job time limit.
"""

from __future__ import annotations

import json
import socket
from itertools import islice

import av
import pytest

from service.frames import open_frames
from tests.service.conftest import (
    PETS_VIDEO,
    Server,
    error_of,
    mux_silence,
    submit,
    wait_for,
    wait_for_state,
    write_gray,
    write_stamped,
)

pytestmark = pytest.mark.slow

TOKEN = "s3cret-token"
LIMIT = 400_000


@pytest.fixture(scope="module")
def server(tmp_path_factory):
    server = Server(
        tmp_path_factory.mktemp("strict") / "data",
        workers=1,
        api_token=TOKEN,
        max_upload_bytes=LIMIT,
        job_timeout=1.0,
    ).start()
    yield server
    server.stop()


@pytest.fixture(scope="module")
def client(server):
    with server.client() as client:
        yield client


def _write(path, data):
    path.write_bytes(data)
    return path


def _unfinished_mp4(folder, video):
    """An MP4 cut before its index, which writers add last: a recording that was not finished."""
    frames = list(islice(open_frames(video), 10))
    stamps = range(0, 100 * len(frames), 100)
    whole = write_stamped(frames, stamps, folder / "whole.mp4").read_bytes()
    assert whole.rfind(b"moov") > len(whole) * 0.8  # the index is at the end
    return _write(folder / "VID_0001.mp4", whole[: len(whole) * 4 // 5])


def _voice_memo(folder, video):
    """An M4A holding one second of sound and no picture."""
    path = folder / "memo.m4a"
    with av.open(str(path), "w") as out:
        mux_silence(out, 1.0)
    return path


def _checks(*failed: tuple[list, str]) -> list[tuple[list, str]]:
    """The failed checks (location, type) of a validation error, as :func:`test_bad_upload`
    expects them in ``errors``."""
    return sorted(failed)


@pytest.mark.parametrize(
    ("make_video", "options", "type", "what"),
    [
        # Bytes that no decoder reads as video.
        (
            lambda d, v: _write(d / "junk.avi", b"\x00not a video" * 500),
            None,
            "invalid_video",
            None,
        ),
        # A text file with a video's name.
        (lambda d, v: _write(d / "notes.mp4", b"hello\n" * 100), None, "invalid_video", None),
        # An empty video part.
        (lambda d, v: _write(d / "empty.avi", b""), None, "invalid_video", "is empty"),
        # Only the first 2 kB of a real video: the header without a frame.
        (lambda d, v: _write(d / "head.avi", v.read_bytes()[:2048]), None, "invalid_video", None),
        # before: the same words as for junk, for a phone recording and for sound
        (_unfinished_mp4, None, "invalid_video", "no 'moov' box"),
        (_voice_memo, None, "invalid_video", "no video track (its tracks: audio)"),
        # before: accepted, then failed with "frame is empty or too small: shape (400, 2, 3)"
        (lambda d, v: write_gray(d / "strip.mp4", 2, 400), None, "invalid_options", "2x400"),
        # before: "succeeded" without a word, nobody could be found in it
        (
            lambda d, v: write_gray(d / "thumb.mp4", 16, 8),
            {"mode": "single_target", "first_box": {"x": 2, "y": 2, "w": 4, "h": 4}},
            "invalid_options",
            "16x8",
        ),
        # A misspelt option.
        (
            lambda d, v: v,
            {"formats": ["json"], "frame_stp": 2},
            "validation_error",
            _checks((["options", "frame_stp"], "extra_forbidden")),
        ),
        # An unknown nested option.
        (
            lambda d, v: v,
            {"tracker": {"particle": 10}},
            "validation_error",
            _checks((["options", "tracker", "particle"], "extra_forbidden")),
        ),
        # A value out of range.
        (
            lambda d, v: v,
            {"tracker": {"particles": 1}},
            "validation_error",
            _checks((["options", "tracker", "particles"], "greater_than_equal")),
        ),
        # Wrong types are not converted: a flag is no number, a string no upscale, NaN no time.
        (
            lambda d, v: v,
            {"frame_step": True},
            "validation_error",
            _checks((["options", "frame_step"], "int_type")),
        ),
        (
            lambda d, v: v,
            {"fill_gaps": True},
            "validation_error",
            _checks((["options", "fill_gaps"], "float_type")),
        ),
        (
            lambda d, v: v,
            {"detector": {"upscale": "2"}},
            "validation_error",
            _checks((["options", "detector", "upscale"], "float_type")),
        ),
        (
            lambda d, v: v,
            {"fill_gaps": float("nan")},
            "validation_error",
            _checks((["options", "fill_gaps"], "finite_number")),
        ),
        # An unknown output format.
        (
            lambda d, v: v,
            {"formats": ["avi"]},
            "validation_error",
            _checks((["options", "formats", 0], "enum")),
        ),
        # Single-target mode without its first box (a rule across options: located at them).
        (
            lambda d, v: v,
            {"mode": "single_target"},
            "validation_error",
            _checks((["options"], "value_error")),
        ),
        # A first box outside the 480x360 frame (before: "first_box: box 900,10,20,40 ...").
        (
            lambda d, v: v,
            {"mode": "single_target", "first_box": {"x": 900, "y": 10, "w": 20, "h": 40}},
            "invalid_options",
            "first_box 900,10,20,40",
        ),
        # An unknown correlation preset.
        (
            lambda d, v: v,
            {"mode": "single_target", "first_box": {"x": 9, "y": 9, "w": 9, "h": 9}, "preset": "x"},
            "invalid_options",
            "preset",
        ),
        # Gaps filled longer than the option allows, and for a single target (never dropped).
        (
            lambda d, v: v,
            {"fill_gaps": 30},
            "validation_error",
            _checks((["options", "fill_gaps"], "less_than_equal")),
        ),
        (
            lambda d, v: v,
            {
                "mode": "single_target",
                "first_box": {"x": 9, "y": 9, "w": 9, "h": 9},
                "fill_gaps": 1,
            },
            "validation_error",
            _checks((["options", "fill_gaps"], "value_error")),
        ),
        # an option of the other mode, which was ignored
        (
            lambda d, v: v,
            {"preset": "rcsk_cn"},
            "validation_error",
            _checks((["options", "preset"], "value_error")),
        ),
        # The DPM detector on a service without a model.
        (lambda d, v: v, {"detector": {"name": "dpm"}}, "invalid_options", "VTRACK_DPM_MODEL"),
        # A DPM option for the embedded detector, which would ignore it.
        (
            lambda d, v: v,
            {"detector": {"levels_per_octave": 5}},
            "validation_error",
            _checks((["options", "detector", "levels_per_octave"], "value_error")),
        ),
    ],
)
def test_bad_upload(server, client, tmp_path, pets_short, make_video, options, type, what):
    """Each refusal has its type; a validation error locates each failed check, any other
    names what was wrong (one test per type reads its whole sentence)."""
    response = submit(client, make_video(tmp_path, pets_short), options)
    body = error_of(response, type)
    if type == "validation_error":
        assert sorted((e["loc"], e["type"]) for e in body["errors"]) == what, body
    elif what is not None:
        assert what in body["detail"], body
    # the operator's log says why, as the client was told (before: the access line only)
    refusal = f"POST /v1/jobs from 127.0.0.1 refused ({response.status_code}): "
    said = [line for line in server.log().splitlines() if refusal in line]
    assert any(line.endswith(body["detail"]) for line in said), said[-3:]


def test_a_rule_across_options_is_stated_plainly(client, pets_short):
    response = submit(client, pets_short, {"mode": "single_target"})
    detail = error_of(response, "validation_error")["detail"]
    assert detail.startswith("invalid job options: mode 'single_target' needs first_box"), detail


def test_bad_options_list_each_failed_check_for_programs(client, pets_short):
    response = submit(client, pets_short, {"frame_step": 0, "tracker": {"particles": 1}})
    body = error_of(response, "validation_error")
    # was: the sentence only, though ErrorResponse promises the checks
    assert sorted((e["loc"], e["type"]) for e in body["errors"]) == [
        (["options", "frame_step"], "greater_than_equal"),
        (["options", "tracker", "particles"], "greater_than_equal"),
    ]
    assert all(e["msg"].startswith("Input should be") for e in body["errors"])


def test_a_body_without_the_token_is_refused_before_it_is_read(server):
    # before: FastAPI read (and parsed) a JSON body of any size before the token was checked:
    # 2 GB of memory for one request of 1 GB without a token
    with socket.create_connection(("127.0.0.1", server.port), timeout=10) as connection:
        connection.sendall(
            b"POST /v1/streams HTTP/1.1\r\nHost: 127.0.0.1\r\nContent-Type: application/json"
            b"\r\nContent-Length: 1000000000\r\n\r\n" + b'{"camera": "big", "x": "AAAA'
        )
        answer = connection.recv(4096).decode()
    assert answer.startswith("HTTP/1.1 401"), answer


def test_web_pages_of_other_sites_are_refused(client, server, pets_short):
    # before: a page in the operator's browser could post jobs to a service on loopback
    # (a form needs no permission) and, through a name of its own pointed at 127.0.0.1 (DNS
    # rebinding), list, download and delete them
    rebound = client.get("/v1/jobs", headers={"Host": f"attacker.example:{server.port}"})
    assert "'attacker.example'" in error_of(rebound, "forbidden")["detail"]
    assert client.get("/v1/jobs", headers={"Host": f"localhost:{server.port}"}).status_code == 200
    files = {"video": ("v.avi", pets_short.read_bytes(), "video/x-msvideo")}
    forged = client.post("/v1/jobs", files=files, headers={"Origin": "http://evil.example"})
    # the family's whole sentence, once
    assert error_of(forged, "forbidden")["detail"] == (
        "a request from a web page of http://evil.example may not change anything here "
        "(cross-site): send it from a program, or from this service's own pages"
    )
    # the service's own pages (the docs' "Try it out") and programs (no Origin) may
    own = client.delete("/v1/jobs/nope", headers={"Origin": server.url})
    error_of(own, "not_found")
    error_of(client.get("/healthz", headers={"Host": "attacker.example"}), "forbidden")


def test_a_body_over_the_limit_is_refused_with_the_token(client):
    response = client.post("/v1/streams", json={"camera": "big", "x": "A" * 100_000})
    # the family's whole sentence, once
    assert error_of(response, "payload_too_large")["detail"] == (
        "the request body is over 64 KiB, more than any request here but an upload needs"
    )
    refused = client.post("/v1/streams", json={"camera": "big", "x": "A"})
    checks = error_of(refused, "validation_error")["errors"]  # read, as before
    assert [(e["loc"], e["type"]) for e in checks] == [(["body", "x"], "extra_forbidden")]


def test_a_query_parameter_a_route_does_not_take_is_refused(client):
    # before: a misspelt filter listed every job, 200
    response = client.get("/v1/jobs", params={"stat": "succeeded", "limit": 5})
    body = error_of(response, "validation_error")
    # the family's whole sentence, once
    assert body["detail"] == (
        "invalid request: query.stat: not a query parameter of this route (it takes before, "
        "finished_after, limit, state)"
    )
    assert body["errors"] == [
        {"loc": ["query", "stat"], "msg": body["detail"][29:], "type": "extra_forbidden"}
    ]
    missing = client.get("/v1/jobs/0123/result", params={"fromat": "mot"})
    assert error_of(missing, "validation_error")["errors"][0]["loc"] == ["query", "fromat"]
    error_of(client.get("/v1/streams", params={"x": "1"}), "validation_error")
    assert client.get("/v1/jobs", params={"state": "succeeded"}).status_code == 200


def test_an_enlargement_beyond_8k_is_refused_with_the_largest_that_fits(client, tmp_path):
    # before: a 4K video at detector.upscale 4 was queued, and took about 25 s and 3.6 GB of
    # its worker's memory per frame
    uhd = write_gray(tmp_path / "uhd.mp4", 3840, 2160)
    response = submit(client, uhd, {"detector": {"upscale": 4}})
    # the family's whole sentence, once
    assert error_of(response, "invalid_options")["detail"] == (
        "detector.upscale 4 enlarges frames of 3840x2160 to 15360x8640, beyond the 7680x4320 "
        "the detector takes: use at most 2, or leave it unset to let the detector choose"
    )


def test_options_that_are_not_json(client, pets_short):
    files = {"video": ("v.avi", pets_short.read_bytes())}
    response = client.post("/v1/jobs", files=files, data={"options": "{frame_step: 2"})
    assert error_of(response, "validation_error")["errors"][0]["type"] == "json_invalid"


def test_missing_video_part(client):
    response = client.post("/v1/jobs", files={"options": (None, json.dumps({"frame_step": 1}))})
    assert "'video'" in error_of(response, "invalid_upload")["detail"]


def test_a_file_name_sent_instead_of_the_file_is_named(client, pets_short):
    """``curl -F video=clip.mp4`` (no @) sends the name as a text field: was a 415 saying the
    "uploaded file" is not a video."""
    response = client.post("/v1/jobs", files={"video": (None, str(pets_short))})
    # the family's whole sentence, once
    assert error_of(response, "invalid_upload")["detail"] == (
        "the 'video' part is a text field, not a file (it has neither a file name nor a "
        "content type): send the file itself, e.g. with curl -F video=@clip.mp4 (the @ makes "
        "curl send the file's bytes)"
    )
    # a file part without a file name is still a file (some clients send no name): it goes
    # on to be decoded (these bytes are no video, so nothing is queued or kept)
    unnamed = client.post("/v1/jobs", files={"video": (None, b"\x00" * 4096, "video/mp4")})
    # the family's whole sentence, once
    assert error_of(unnamed, "invalid_video")["detail"] == (
        "the uploaded file is not a video this service can decode: no frame could be read from "
        "it; send a video file such as MP4 (H.264) or AVI (MJPEG)"
    )


def test_unexpected_part(client, pets_short):
    files = {"video": ("v.avi", pets_short.read_bytes()), "movie": ("m.avi", b"x")}
    response = client.post("/v1/jobs", files=files)
    assert "'movie'" in error_of(response, "invalid_upload")["detail"]


def test_body_that_is_not_multipart(client, pets_short):
    response = client.post(
        "/v1/jobs", content=pets_short.read_bytes(), headers={"Content-Type": "video/x-msvideo"}
    )
    # the family's whole sentence, once
    assert error_of(response, "unsupported_media")["detail"] == (
        "send the upload as multipart/form-data with the video in a 'video' file part (got "
        "Content-Type 'video/x-msvideo')"
    )


def test_too_large_upload_with_a_declared_length(client, pets_cut):
    assert pets_cut.stat().st_size > LIMIT
    response = submit(client, pets_cut)
    error_of(response, "payload_too_large")


def test_too_large_upload_streamed_without_a_length(client, server, pets_cut):
    # A chunked body: the limit is enforced while receiving, and the partial file is removed.
    boundary = "vtrack-test-boundary"

    def body():
        yield (
            f'--{boundary}\r\nContent-Disposition: form-data; name="video"; filename="big.avi"'
            "\r\nContent-Type: video/x-msvideo\r\n\r\n"
        ).encode()
        data = pets_cut.read_bytes()
        for start in range(0, len(data), 65536):
            yield data[start : start + 65536]
        yield f"\r\n--{boundary}--\r\n".encode()

    response = client.post(
        "/v1/jobs",
        content=body(),
        headers={"Content-Type": f"multipart/form-data; boundary={boundary}"},
    )
    error_of(response, "payload_too_large")
    assert not any((server.data_dir / "uploads").iterdir())


def _half_an_upload(token: str | None = None) -> bytes:
    """An upload's request as a client sends it, cut halfway through the video's bytes."""
    boundary = "vtrack-test-boundary"
    head = (
        f'--{boundary}\r\nContent-Disposition: form-data; name="video"; filename="cut.avi"'
        "\r\nContent-Type: video/x-msvideo\r\n\r\n"
    ).encode() + bytes(100_000)
    authorization = f"Authorization: Bearer {token}\r\n" if token else ""
    request = (
        f"POST /v1/jobs HTTP/1.1\r\nHost: 127.0.0.1\r\n{authorization}"
        f"Content-Length: {len(head) + 200_000}\r\n"
        f"Content-Type: multipart/form-data; boundary={boundary}\r\n\r\n"
    ).encode()
    return request + head


def test_an_abandoned_upload_is_logged_in_one_line_and_nothing_is_kept(client, server):
    # A client that closes its connection halfway through the body (a camera gateway that
    # crashed, a user's Ctrl-C): a warning, not a server error with its traceback.
    with socket.create_connection(("127.0.0.1", server.port)) as connection:
        connection.sendall(_half_an_upload(TOKEN))
        wait_for(lambda: any((server.data_dir / "uploads").glob("*.receiving")), 10, "the upload")
    wait_for(lambda: "upload abandoned by the client" in server.log(), 10, "the log line")
    assert not any((server.data_dir / "uploads").iterdir())
    assert "Traceback" not in server.log() and "ClientDisconnect" not in server.log()
    assert client.get("/healthz").status_code == 200


def test_a_stalled_upload_is_cut_and_nothing_is_kept(tmp_path):
    # before: a client that stopped sending held its connection and its partial file (300 MB
    # each in the security walkthrough) for as long as it liked
    server = Server(tmp_path / "data", workers=1, upload_idle_seconds=1.0).start()
    try:
        with socket.create_connection(("127.0.0.1", server.port), timeout=20) as connection:
            connection.sendall(_half_an_upload())
            answer = ""
            while not answer.endswith("}"):  # the head and the body may come apart
                answer += connection.recv(4096).decode()
        assert answer.startswith("HTTP/1.1 408"), answer
        assert json.loads(answer.partition("\r\n\r\n")[2])["type"] == "timeout"
        assert "1 s (VTRACK_UPLOAD_IDLE_SECONDS)" in answer
        assert not any((server.data_dir / "uploads").iterdir())
    finally:
        server.stop()


def test_unknown_job(client):
    for path in ("/v1/jobs/nope", "/v1/jobs/nope/result", "/v1/jobs/nope/events"):
        response = client.get(path)
        # the family's whole sentence, once
        assert error_of(response, "not_found")["detail"] == (
            "no job 'nope': it never existed or was deleted (GET /v1/jobs lists the jobs)"
        )
    error_of(client.delete("/v1/jobs/nope"), "not_found")
    error_of(client.get("/v1/nothing"), "not_found")  # a path that is none: the framework's 404


def test_unknown_result_format(client):
    response = client.get("/v1/jobs/nope/result", params={"format": "avi"})
    assert error_of(response, "validation_error")["errors"][0]["loc"] == ["query", "format"]


@pytest.mark.parametrize(
    ("method", "path"),
    [
        ("GET", "/v1/jobs"),
        ("POST", "/v1/jobs"),
        ("GET", "/v1/jobs/some-id"),
        ("GET", "/v1/jobs/some-id/result"),
        ("GET", "/v1/jobs/some-id/events"),
        ("DELETE", "/v1/jobs/some-id"),
        ("GET", "/metrics"),
        ("GET", "/docs"),
        ("GET", "/redoc"),
        ("GET", "/openapi.json"),
        ("GET", "/v1/streams"),
        ("POST", "/v1/streams"),
        ("DELETE", "/v1/streams/gate"),
    ],
)
@pytest.mark.parametrize(
    ("header", "reason"),
    [
        # the family's whole sentence, once
        (
            None,
            "this service needs a token: send the header 'Authorization: Bearer <token>' with "
            "the token it was configured with (VTRACK_API_TOKEN)",
        ),
        # the three below were all told to send a token
        ("Bearer wrong-token", "not the one"),
        ("Basic dXNlcjpwYXNz", "(it has the scheme 'Basic')"),
        ("Bearer", "(it has the scheme 'Bearer' and no token)"),
    ],
)
def test_endpoints_need_the_token(server, method, path, header, reason):
    with server.client(token="") as anonymous:
        headers = {"Authorization": header} if header else {}
        response = anonymous.request(method, path, headers=headers)
    assert response.headers["www-authenticate"] == "Bearer"
    detail = error_of(response, "unauthorized")["detail"]
    assert detail == reason if header is None else reason in detail


def test_documentation_opens_with_the_token(client):
    assert client.get("/docs").status_code == 200
    assert client.get("/openapi.json").json()["info"]["title"] == "visual-tracking"


def test_health_needs_no_token(server):
    with server.client(token="") as anonymous:
        assert anonymous.get("/healthz").status_code == 200
        assert anonymous.get("/readyz").status_code == 200
        # uptime monitors probe with HEAD
        assert anonymous.head("/healthz").status_code == 200
        assert anonymous.head("/readyz").status_code == 200
        # the docs pages' generic scripts are open; the schema they render is not
        assert anonymous.get("/docs-assets/swagger-ui-bundle.js").status_code == 200


def test_job_over_the_time_limit_fails_and_the_service_goes_on(client, pets_short):
    # Detection on frames enlarged 4x costs about half a second per frame even on an idle
    # machine: 8 frames take several seconds, well over the one-second limit (at 2x they can
    # finish within it when nothing else runs).
    response = submit(client, pets_short, {"formats": ["json"], "detector": {"upscale": 4.0}})
    assert response.status_code == 202, response.text
    status = wait_for_state(client, response.json()["id"], ("succeeded", "failed"), timeout=60)
    assert status["state"] == "failed"
    assert "exceeded the time limit of 1 s" in status["error"]

    def replaced():
        metrics = client.get("/metrics").text
        return "vtrack_workers_replaced_total 1.0" in metrics and client.get("/readyz").is_success

    wait_for(replaced, 30, "a new worker after the time limit")


def test_a_full_data_folder_is_reported_and_the_service_goes_on(make_server, shared_data, tmp_path):
    # The service and its workers may write no file beyond 2 MB (ulimit -f): a write that would
    # need more fails with EFBIG, as a write to a full disk fails with ENOSPC.
    server = make_server(workers=1, file_size_limit=2_000_000)
    video = shared_data / PETS_VIDEO  # 3.1 MB
    start = _write(tmp_path / "start.avi", video.read_bytes()[:400_000])  # its first 10 s
    with server.client() as client:
        refused = submit(client, video, {"formats": ["json"]})
        error_of(refused, "insufficient_storage")
        assert list((server.data_dir / "uploads").iterdir()) == [], "the partial upload stays"

        # 100 frames as JPEG in an MCAP need about 3.5 MB (the detector on the frames as they
        # are, not enlarged: a quarter of the work)
        options = {"formats": ["mcap"], "mcap_images": "jpeg", "detector": {"upscale": 1.0}}
        job = submit(client, start, options)
        assert job.status_code == 202, job.text
        failed = wait_for_state(client, job.json()["id"], ("succeeded", "failed"))
        assert failed["state"] == "failed"
        assert "largest file" in failed["error"] and "submit the job again" in failed["error"]
        left = (server.data_dir / "results" / failed["id"]).rglob("*")
        assert [p for p in left if p.is_file()] == [], "the partial results stay"

        # the service goes on: a job whose results fit succeeds, on the same worker
        job = submit(client, start, {"formats": ["json"], "end": 1})
        done = wait_for_state(client, job.json()["id"], ("succeeded", "failed"))
        assert done["state"] == "succeeded", done["error"]
        assert "vtrack_workers_replaced_total 0.0" in client.get("/metrics").text


def test_a_json_body_that_is_not_utf8_gets_a_422_saying_so(client):
    # before: 400 "There was an error parsing the body", neither what nor how to fix it
    response = client.post(
        "/v1/streams",
        content=b'{"camera": "\xff\xfe"}',
        headers={"Content-Type": "application/json"},
    )
    body = error_of(response, "validation_error")
    assert "byte 12 is 0xff" in body["detail"]
    assert body["errors"] == [{"loc": ["body"], "msg": body["detail"], "type": "unicode_decode"}]


@pytest.mark.parametrize(
    ("method", "path", "allowed"),
    [
        ("PUT", "/v1/jobs", "GET, POST"),
        ("PATCH", "/v1/streams/gate", "GET, DELETE"),
        ("POST", "/healthz", "GET, HEAD"),
    ],
)
def test_a_method_not_allowed_names_every_method_of_the_path(client, method, path, allowed):
    # before: Allow named the methods of the first route that matched ("POST" of /v1/jobs)
    response = client.request(method, path)
    assert response.headers["allow"] == allowed
    # the family's whole sentence
    assert error_of(response, "method_not_allowed")["detail"] == (
        f"{method} is not allowed on {path}: use {allowed}"
    )
