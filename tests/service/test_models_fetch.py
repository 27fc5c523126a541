"""``vtrack models fetch`` and the model catalog: real files fetched from a real HTTP server on
loopback, which serves the shared reference copies as a mirror (or damaged copies of them, or
cuts its connections short), so every check of the download runs on real bytes and sockets.

Only models whose catalog checksums equal the shared copies can be fetched from them: all seven
do (tested below); the success cases use the small ones (person-detection-0202, the default, and
person-reidentification-retail-0288).
"""

from __future__ import annotations

import functools
import hashlib
import http.server
import json
import os
import re
import shlex
import shutil
import subprocess
import sys
import threading
from collections.abc import Iterator
from pathlib import Path
from types import MappingProxyType

import pytest

from devtools.testing import free_port
from service.models import (
    CATALOG,
    DEFAULT_DETECTOR,
    DEFAULT_MODELS,
    DEFAULT_POSE,
    DEFAULT_REID,
    OMZ_HUMAN_RIGHTS_NOTICE,
    ModelFetchError,
    UnknownModelError,
    fetch_models,
    file_state,
    model_path,
    model_state,
)
from tests.conftest import REPO_ROOT
from tests.service.test_docker import instructions

DETECTOR = CATALOG[DEFAULT_DETECTOR]
WEIGHTS = next(f for f in DETECTOR.files if f.path.endswith(".bin"))
SMALL = "person-reidentification-retail-0288"  # 1 MB


def sha256(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def files_in(folder: Path) -> list[str]:
    """Every file under ``folder`` (temporary ones included), relative, sorted."""
    return sorted(p.relative_to(folder).as_posix() for p in folder.rglob("*") if not p.is_dir())


class _Server(http.server.ThreadingHTTPServer):
    """A loopback server that serves ``folder`` and records the paths asked for."""

    daemon_threads = True

    def __init__(self, folder: Path, handler: type[http.server.BaseHTTPRequestHandler]) -> None:
        self.folder = folder
        self.requests: list[str] = []
        self.release = threading.Event()  # lets a handler that holds its answer finish
        super().__init__(("127.0.0.1", 0), functools.partial(handler, directory=str(folder)))

    @property
    def url(self) -> str:
        return f"http://127.0.0.1:{self.server_address[1]}"


class _Files(http.server.SimpleHTTPRequestHandler):
    """The folder's files, as a static web server (or OMZ's storage) serves them."""

    server: _Server

    def do_GET(self) -> None:
        self.server.requests.append(self.path)
        super().do_GET()

    def log_message(self, format: str, *args: object) -> None:  # no lines in the test output
        pass


class _Dropping(_Files):
    """Announces a file's full length, sends half of it and closes the connection."""

    def do_GET(self) -> None:
        self.server.requests.append(self.path)
        data = (self.server.folder / self.path.lstrip("/")).read_bytes()
        self.send_response(200)
        self.send_header("Content-Length", str(len(data)))
        self.end_headers()
        self.wfile.write(data[: len(data) // 2])
        self.wfile.flush()
        self.after_half()
        self.close_connection = True

    def after_half(self) -> None:
        """What the server does once half the file is sent: here, close at once."""


class _Redirecting(_Files):
    """Sends every request on to ``self.server.elsewhere`` (a 302, as storage services do)."""

    def do_GET(self) -> None:
        self.server.requests.append(self.path)
        self.send_response(302)
        self.send_header("Location", f"{self.server.elsewhere}{self.path}")
        self.send_header("Content-Length", "0")
        self.end_headers()


class _Silent(_Dropping):
    """Sends half of a file, then nothing more (until the test ends)."""

    def after_half(self) -> None:
        self.server.release.wait(30)


@pytest.fixture
def serve() -> Iterator:
    """``serve(folder, handler=_Files)``: a running server on 127.0.0.1, stopped afterwards."""
    servers: list[_Server] = []

    def start(folder: Path, handler: type = _Files) -> _Server:
        server = _Server(folder, handler)
        threading.Thread(target=server.serve_forever, daemon=True).start()
        servers.append(server)
        return server

    yield start
    for server in servers:
        server.release.set()
        server.shutdown()
        server.server_close()


@pytest.fixture
def mirror(shared_data, serve) -> _Server:
    """The shared reference copies, served as a mirror laid out like a models folder."""
    return serve(shared_data / "models")


@pytest.fixture
def damaged_mirror(shared_data, tmp_path) -> Path:
    """A mirror folder whose copy of the default detector's weights has one byte changed (the
    graph is a link to the shared copy)."""
    folder = tmp_path / "damaged"
    source = shared_data / "models" / DETECTOR.graph
    graph = folder / DETECTOR.graph
    graph.parent.mkdir(parents=True)
    graph.symlink_to(source)
    data = bytearray((shared_data / "models" / WEIGHTS.path).read_bytes())
    data[len(data) // 3] ^= 0x01
    (folder / WEIGHTS.path).write_bytes(bytes(data))
    return folder


def vtrack(*args: object, env: dict[str, str] | None = None, cwd: Path | None = None):
    """``vtrack ARGS`` as a user runs it, a subprocess; ``VTRACK_MODELS_DIR`` only if given."""
    environment = {k: v for k, v in os.environ.items() if k != "VTRACK_MODELS_DIR"}
    environment["PYTHONPATH"] = str(REPO_ROOT)  # the checkout, whatever ``cwd`` is
    return subprocess.run(
        [sys.executable, "-m", "service.cli", *map(str, args)],
        capture_output=True,
        text=True,
        timeout=120,
        env={**environment, **(env or {})},
        cwd=cwd,
    )


# --- the catalog ---------------------------------------------------------------------------


def test_catalog_checksums_are_those_of_the_reference_copies(shared_data):
    for model in CATALOG.values():
        for file in model.files:
            assert file_state(shared_data / "models" / file.path, file) == "present", file.path
            assert file.url.startswith("https://storage.openvinotoolkit.org/repositories/")
            assert file.url.endswith(f"/models_bin/{file.url.split('/models_bin/')[1]}")
            assert file.url.endswith(file.path)
        assert model.graph.endswith(".xml") and model.graph.startswith(f"{model.name}/")
        assert model.task in ("person-detection", "pose", "reidentification")
        assert model_state(shared_data / "models", model.name) == "present"
    assert DEFAULT_DETECTOR == "person-detection-0202" and DEFAULT_DETECTOR in CATALOG
    assert CATALOG["human-pose-estimation-0001"].graph.split("/")[1] == "FP16-INT8"
    assert isinstance(CATALOG, MappingProxyType)
    with pytest.raises(TypeError):
        CATALOG["mine"] = DETECTOR  # type: ignore[index]


def test_model_path_names_the_known_models_for_an_unknown_one(tmp_path):
    assert model_path(tmp_path, DEFAULT_DETECTOR) == tmp_path / DETECTOR.graph
    for kind in (KeyError, ValueError):
        with pytest.raises(kind) as caught:
            model_path(tmp_path, "person-detection-9999")
        assert isinstance(caught.value, UnknownModelError)
        assert str(caught.value).startswith("unknown model 'person-detection-9999'")
        assert all(name in str(caught.value) for name in CATALOG)


def test_the_runtime_does_not_import_the_download():
    sources = (REPO_ROOT / "tracking").rglob("*.py")
    assert not [p for p in sources if "service.models" in p.read_text() or "urllib" in p.name]


# --- fetching ------------------------------------------------------------------------------


def test_fetches_the_default_detector_verified_then_leaves_it_alone(mirror, tmp_path):
    target = tmp_path / "models"
    reported = []
    results = fetch_models([DEFAULT_DETECTOR], target, mirror=mirror.url, progress=reported.append)
    assert reported == results
    assert [(r.file.path, r.action) for r in results] == [
        (WEIGHTS.path, "downloaded"),  # the weights first: the graph appears once they are in
        (DETECTOR.graph, "downloaded"),
    ]
    for result in results:
        assert result.path == target / result.file.path
        assert sha256(result.path) == result.file.sha256
        assert result.received == result.file.size
        assert result.url == f"{mirror.url}/{result.file.path}"
    assert files_in(target) == sorted(f.path for f in DETECTOR.files)  # no temporary file
    assert sorted(mirror.requests) == sorted(f"/{f.path}" for f in DETECTOR.files)
    # the files stay readable by others (an image's service user; not tempfile's 0600)
    umask = os.umask(0)
    os.umask(umask)
    assert (target / WEIGHTS.path).stat().st_mode & 0o777 == 0o666 & ~umask

    again = fetch_models([DEFAULT_DETECTOR], target, mirror=mirror.url)
    assert [r.action for r in again] == ["present", "present"]
    assert [r.received for r in again] == [0, 0]
    assert len(mirror.requests) == 2  # nothing asked for again


def test_a_damaged_copy_in_the_folder_is_replaced(mirror, tmp_path):
    target = tmp_path / "models"
    fetch_models([DEFAULT_DETECTOR], target, mirror=mirror.url)
    weights = target / WEIGHTS.path
    data = bytearray(weights.read_bytes())
    data[100] ^= 0xFF  # same size, other bytes
    weights.write_bytes(bytes(data))
    assert model_state(target, DEFAULT_DETECTOR) == "corrupt"
    results = fetch_models([DEFAULT_DETECTOR], target, mirror=mirror.url)
    assert [r.action for r in results] == ["replaced", "present"]
    assert sha256(weights) == WEIGHTS.sha256
    assert mirror.requests.count(f"/{WEIGHTS.path}") == 2
    assert files_in(target) == sorted(f.path for f in DETECTOR.files)


def test_a_checksum_mismatch_leaves_no_file_behind(damaged_mirror, serve, tmp_path):
    server = serve(damaged_mirror)
    target = tmp_path / "models"
    with pytest.raises(ModelFetchError) as caught:
        fetch_models([DEFAULT_DETECTOR], target, mirror=server.url)
    message = str(caught.value)
    assert message.startswith(f"{WEIGHTS.path} from {server.url}/{WEIGHTS.path}: sha256 mismatch")
    assert f"expected {WEIGHTS.sha256}" in message
    assert f"got {sha256(damaged_mirror / WEIGHTS.path)}" in message
    assert f"{WEIGHTS.size} bytes" in message
    assert files_in(target) == []  # neither the file, nor its temporary, nor the graph after it
    assert server.requests == [f"/{WEIGHTS.path}"]  # stopped at the first failure


def test_a_failed_download_leaves_a_copy_already_there_as_it_was(damaged_mirror, serve, tmp_path):
    target = tmp_path / "models"
    weights = target / WEIGHTS.path
    weights.parent.mkdir(parents=True)
    weights.write_bytes(b"an older, truncated download")
    with pytest.raises(ModelFetchError, match="sha256 mismatch"):
        fetch_models([DEFAULT_DETECTOR], target, mirror=serve(damaged_mirror).url)
    assert files_in(target) == [WEIGHTS.path]
    assert weights.read_bytes() == b"an older, truncated download"


def test_a_dropped_connection_leaves_no_file_behind(shared_data, serve, tmp_path):
    server = serve(shared_data / "models", _Dropping)
    target = tmp_path / "models"
    with pytest.raises(ModelFetchError) as caught:
        fetch_models([DEFAULT_DETECTOR], target, mirror=server.url)
    half = WEIGHTS.size // 2
    assert str(caught.value) == (
        f"{WEIGHTS.path} from {server.url}/{WEIGHTS.path}: the connection closed after "
        f"{half} of {WEIGHTS.size} bytes"
    )
    assert files_in(target) == []


def test_a_silent_server_times_out_and_leaves_no_file_behind(shared_data, serve, tmp_path):
    server = serve(shared_data / "models", _Silent)
    target = tmp_path / "models"
    with pytest.raises(ModelFetchError) as caught:
        fetch_models([DEFAULT_DETECTOR], target, mirror=server.url, timeout=2.0)
    # the server sends half and then nothing; on a loaded machine the client may have read
    # less than that when its wait runs out
    received = re.search(r"broke after (\d+) of (\d+) bytes", str(caught.value))
    assert received is not None, str(caught.value)
    assert 0 < int(received[1]) <= WEIGHTS.size // 2 and int(received[2]) == WEIGHTS.size
    assert "no data within 2 s (timed out)" in str(caught.value)
    assert files_in(target) == []


def test_http_errors_refusals_and_wrong_sizes_are_said(shared_data, serve, tmp_path):
    target = tmp_path / "models"
    empty = tmp_path / "empty"
    empty.mkdir()
    with pytest.raises(ModelFetchError) as caught:
        fetch_models([DEFAULT_DETECTOR], target, mirror=serve(empty).url)
    assert caught.value.problem == "HTTP 404 File not found"
    assert caught.value.path == WEIGHTS.path
    assert caught.value.url.endswith(f"/{WEIGHTS.path}")

    nobody = f"http://127.0.0.1:{free_port()}"
    with pytest.raises(ModelFetchError, match="cannot connect: Connection refused"):
        fetch_models([DEFAULT_DETECTOR], target, mirror=nobody)

    short = tmp_path / "short"
    (short / WEIGHTS.path).parent.mkdir(parents=True)
    (short / WEIGHTS.path).write_bytes((shared_data / "models" / WEIGHTS.path).read_bytes()[:1000])
    with pytest.raises(ModelFetchError, match=f"announces 1000 bytes, expected {WEIGHTS.size}"):
        fetch_models([DEFAULT_DETECTOR], target, mirror=serve(short).url)
    assert files_in(target) == []


def test_redirects_are_followed(mirror, shared_data, serve, tmp_path):
    front = serve(shared_data / "models", _Redirecting)
    front.elsewhere = mirror.url
    results = fetch_models([SMALL], tmp_path, mirror=front.url)
    assert [r.action for r in results] == ["downloaded", "downloaded"]
    assert results[0].url.startswith(front.url)  # where it was asked for
    assert len(front.requests) == len(mirror.requests) == 2
    assert model_state(tmp_path, SMALL) == "present"


def test_a_folder_serves_as_a_mirror(shared_data, tmp_path):
    results = fetch_models([SMALL, SMALL], tmp_path, mirror=str(shared_data / "models"))
    assert [r.action for r in results] == ["downloaded", "downloaded"]  # the name once
    assert results[0].url.startswith("file:///")
    assert model_state(tmp_path, SMALL) == "present"
    with pytest.raises(ValueError, match="neither a folder nor a URL"):
        fetch_models([SMALL], tmp_path, mirror=str(tmp_path / "nowhere"))
    with pytest.raises(UnknownModelError):  # every name checked before anything is fetched
        fetch_models([DEFAULT_DETECTOR, "bogus"], tmp_path, mirror=str(shared_data / "models"))
    assert not (tmp_path / DEFAULT_DETECTOR).exists()


# --- the command line ----------------------------------------------------------------------


def test_vtrack_models_fetch_from_a_mirror(mirror, tmp_path):
    target = tmp_path / "models"
    result = vtrack("models", "fetch", "--mirror", mirror.url, "--dir", target)
    assert result.returncode == 0, result.stderr
    assert result.stderr == ""
    lines = result.stdout.splitlines()
    assert "Apache-2.0" in lines[0]
    assert OMZ_HUMAN_RIGHTS_NOTICE in " ".join(result.stdout.split())  # quoted whole, wrapped
    assert result.stdout.count("human right.") == 1
    # no names: the three networks a job runs by default, each file downloaded
    assert f"{WEIGHTS.path}: downloaded {WEIGHTS.size} bytes" in lines
    assert f"{DETECTOR.graph}: downloaded {(target / DETECTOR.graph).stat().st_size} bytes" in lines
    found = f"the service finds them with VTRACK_MODELS_DIR={target}"
    assert lines[-1] == f"models in {target}; {found}"
    assert [model_state(target, name) for name in DEFAULT_MODELS] == ["present"] * 3
    files = sum(len(CATALOG[name].files) for name in DEFAULT_MODELS)
    assert len(mirror.requests) == files

    (target / WEIGHTS.path).write_bytes(b"damaged")
    again = vtrack("models", "fetch", "--mirror", mirror.url, env={"VTRACK_MODELS_DIR": target})
    assert again.returncode == 0, again.stderr
    assert f"{WEIGHTS.path}: replaced a corrupt copy (downloaded {WEIGHTS.size} bytes)" in (
        again.stdout.splitlines()
    )
    assert again.stdout.count("already present (size and sha256 verified)") == files - 1
    assert len(mirror.requests) == files + 1


def test_vtrack_models_fetch_refuses_an_unknown_name_before_fetching(tmp_path):
    result = vtrack("models", "fetch", "bogus", cwd=tmp_path)
    assert result.returncode == 2
    assert result.stderr.splitlines() == [
        f"vtrack: unknown model 'bogus': the catalog has {', '.join(CATALOG)}"
    ]
    assert result.stdout == ""
    assert list(tmp_path.iterdir()) == []  # not even ./models

    both = vtrack("models", "fetch", "--all", SMALL, cwd=tmp_path)
    assert (both.returncode, both.stderr) == (2, "vtrack: give model names or --all, not both\n")


def test_vtrack_models_fetch_says_a_failed_download_in_one_line(damaged_mirror, serve, tmp_path):
    server = serve(damaged_mirror)
    result = vtrack("models", "fetch", "--mirror", server.url, "--dir", tmp_path / "models")
    assert result.returncode == 1
    (line,) = result.stderr.splitlines()  # no traceback
    assert line.startswith(f"vtrack: {WEIGHTS.path} from {server.url}/{WEIGHTS.path}: sha256")
    assert files_in(tmp_path / "models") == []


def test_vtrack_models_list_shows_what_the_folder_holds(shared_data, tmp_path):
    target = tmp_path / "models"
    fetch_models([DEFAULT_DETECTOR, SMALL], target, mirror=str(shared_data / "models"))
    damaged = CATALOG["person-detection-0200"].files[1]
    (target / damaged.path).parent.mkdir(parents=True)
    shutil.copyfile(shared_data / "models" / damaged.path, target / damaged.path)
    (target / damaged.path).write_bytes((target / damaged.path).read_bytes()[:-1])

    result = vtrack("models", "list", cwd=tmp_path)  # ./models by default
    assert result.returncode == 0, result.stderr
    rows = {line.split()[0]: line.split()[1:] for line in result.stdout.splitlines()[:-1]}
    assert list(rows) == list(CATALOG)
    assert rows[DEFAULT_DETECTOR] == [
        *("person-detection", "3.8", "MB", "present"),
        *("(default", "detector)"),
    ]
    assert rows[SMALL] == ["reidentification", "1.0", "MB", "present"]
    assert rows["person-detection-0200"][-1] == "corrupt"
    assert rows["human-pose-estimation-0001"] == [
        "pose",
        "4.6",
        "MB",
        "missing",
        "(default",
        "pose)",
    ]
    assert result.stdout.splitlines()[-1] == f"2 of 7 present and verified in {target}"

    elsewhere = vtrack("models", "list", env={"VTRACK_MODELS_DIR": tmp_path / "none"})
    assert elsewhere.stdout.count(" missing") == len(CATALOG)
    assert elsewhere.stdout.endswith(f"in {tmp_path / 'none'} (no such folder)\n")


# --- the image -----------------------------------------------------------------------------


def test_the_image_build_fetches_the_default_networks_outside_the_models_volume(mirror, tmp_path):
    steps = instructions(REPO_ROOT / "docker" / "Dockerfile")
    (index,) = [i for i, (k, a) in enumerate(steps) if k == "RUN" and "vtrack models fetch" in a]
    settings = {}
    for keyword, args in steps[:index]:  # the settings the step runs under
        if keyword == "ENV":
            settings.update(pair.split("=", 1) for pair in shlex.split(args))
    models_dir = settings["VTRACK_MODELS_DIR"]
    volumes = json.loads(dict(steps)["VOLUME"])
    assert not [v for v in volumes if (models_dir + "/").startswith(v.rstrip("/") + "/")]
    assert ("ARG", "VTRACK_MODELS_MIRROR=") in steps[:index]
    # The step as the build's shell runs it, with the build argument naming the loopback mirror
    # and the image's folder moved into tmp_path (the build itself downloads from OMZ).
    bindir = Path(sys.executable).parent
    environment = {
        **os.environ,
        "PATH": f"{bindir}{os.pathsep}{os.environ.get('PATH', '')}",
        "VTRACK_MODELS_DIR": str(tmp_path / models_dir.lstrip("/")),
        "VTRACK_MODELS_MIRROR": mirror.url,
    }
    result = subprocess.run(
        ["sh", "-c", steps[index][1]], env=environment, capture_output=True, text=True, timeout=120
    )
    assert result.returncode == 0, result.stderr
    # the detector, the pose and the re-identification networks jobs run by default
    for name in (DEFAULT_DETECTOR, DEFAULT_POSE, DEFAULT_REID):
        assert model_state(tmp_path / models_dir.lstrip("/"), name) == "present", name
    assert len(mirror.requests) == 6
