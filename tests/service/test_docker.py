"""The Docker files, checked without a Docker engine (there is none on our machines).

The Dockerfile's install steps are replayed in a fresh virtual environment: its COPY steps
copy from the repository into a scratch build folder, its ``pip``/``python`` RUN steps run there
with the environment's interpreter, its ``vtrack`` RUN steps (the model fetch) with the installed
command through a shell, the build arguments given by the test: the model files come from the
shared reference copies as a mirror, since the machines running the tests have no internet access
(other RUN steps, such as creating the system user, need a container and are only checked for
presence). The installed ``vtrack`` must then start and pass the image's own HEALTHCHECK command.
The compose file must parse and name files that exist; the settings of its services must parse,
and its profile ``scaleout``'s two instances run, with their settings, on a PostgreSQL server of
the test's own and a router of the configuration the compose file's setup writes.
"""

from __future__ import annotations

import contextlib
import dataclasses
import fnmatch
import importlib.metadata
import json
import os
import re
import shlex
import shutil
import subprocess
import sys
import time
import venv
from pathlib import Path

import pytest
import yaml

from devtools.testing import free_port, try_get, wait_for
from tests.conftest import REPO_ROOT

DOCKER = REPO_ROOT / "docker"


def instructions(path: Path) -> list[tuple[str, str]]:
    """``(INSTRUCTION, arguments)`` of a Dockerfile, continuation lines joined."""
    steps, pending = [], ""
    for raw in path.read_text().splitlines():
        line = raw.strip()
        if not pending and (not line or line.startswith("#")):
            continue
        if line.endswith("\\"):
            pending += line[:-1] + " "
            continue
        line, pending = pending + line, ""
        keyword, _, rest = line.partition(" ")
        steps.append((keyword.upper(), rest.strip()))
    return steps


@pytest.fixture(scope="module")
def dockerfile():
    return instructions(DOCKER / "Dockerfile")


def test_dockerfile_shape(dockerfile):
    keywords = [k for k, _ in dockerfile]
    base = dict(dockerfile)["FROM"]
    assert base.startswith("python:3.11") and "slim" in base
    # A non-root user runs the service, with a health check, on the exposed port.
    user = [args for k, args in dockerfile if k == "USER"]
    assert user and user[-1] not in ("root", "0")
    assert keywords.index("USER") < keywords.index("CMD")
    assert "HEALTHCHECK" in keywords and "/healthz" in dict(dockerfile)["HEALTHCHECK"]
    assert dict(dockerfile)["EXPOSE"] == "8000"
    assert "vtrack" in dict(dockerfile)["CMD"]
    # The dependency layer comes before the sources are copied, so code changes reuse it.
    copies = [args.split()[0] for k, args in dockerfile if k == "COPY"]
    assert copies[0] == "pyproject.toml"
    first_source = keywords.index("COPY", keywords.index("COPY") + 1)
    pip_steps = [i for i, (k, a) in enumerate(dockerfile) if k == "RUN" and "pip install" in a]
    assert pip_steps[0] < first_source < pip_steps[-1]
    # Models and the Color Names table are mounted, not baked in.
    volumes = dict(dockerfile)["VOLUME"]
    assert "/models" in volumes and "/data" in volumes
    for source in copies:
        assert (REPO_ROOT / source).exists(), f"COPY names {source}, which is not in the repo"


def _ignored(path: str, patterns: list[str]) -> bool:
    """Whether a .dockerignore with ``patterns`` (no ``!`` exceptions) keeps ``path`` (relative,
    with /) out of the build context: a pattern matching the path or a folder above it, ``**``
    standing for any number of folders."""

    def match(parts: list[str], pattern: list[str]) -> bool:
        if not pattern:
            return not parts
        if pattern[0] == "**":
            return any(match(parts[i:], pattern[1:]) for i in range(len(parts) + 1))
        return (
            bool(parts)
            and fnmatch.fnmatchcase(parts[0], pattern[0])
            and match(parts[1:], pattern[1:])
        )

    parts = path.split("/")
    return any(
        match(parts[:n], p.strip("/").split("/"))
        for p in patterns
        for n in range(1, len(parts) + 1)
    )


def test_dockerignore_keeps_environments_and_caches_out_but_not_what_the_image_copies(dockerfile):
    """The compose build sends the repository as context: without .dockerignore that is the
    .venv (about 1 GB), .git, and host __pycache__ folders with numba caches that COPY would put
    into the image."""
    lines = (REPO_ROOT / ".dockerignore").read_text().splitlines()
    patterns = [line.strip() for line in lines if line.strip() and not line.startswith("#")]
    assert not [p for p in patterns if p.startswith("!")]  # _ignored does not read exceptions
    for path in [".venv/bin/python", ".venv-mot/pyvenv.cfg", ".git/HEAD",
                 "tracking/features/__pycache__/hog._bilinear_weights-206.py311.nbi",
                 "service/__pycache__/app.cpython-311.pyc", "docker/models/w2c.mat",
                 "benchmarks/results/run.json", "vtrack-data/jobs.sqlite"]:  # fmt: skip
        assert _ignored(path, patterns), path
    copied = [args.split()[0] for k, args in dockerfile if k == "COPY"]
    sources = [
        p.relative_to(REPO_ROOT).as_posix()
        for source in copied
        for p in (
            [REPO_ROOT / source]
            if (REPO_ROOT / source).is_file()
            else (REPO_ROOT / source).rglob("*")
        )
        if p.is_file() and "__pycache__" not in p.parts
    ]
    assert any(s.startswith("tracking/detection/dpm/cascades/") for s in sources)
    assert [s for s in sources if _ignored(s, patterns)] == []


def _replay(
    dockerfile, build: Path, env_dir: Path, build_args: dict[str, str] | None = None
) -> dict[str, str]:
    """Run the Dockerfile's COPY and pip/python/vtrack RUN steps in ``build`` with
    ``env_dir``, under its ENV settings (``/app`` read as ``build``) and its ARGs (``build_args``
    for ``--build-arg``); returns the ENV settings."""
    venv.EnvBuilder(with_pip=True, clear=True).create(env_dir)
    bindir = env_dir / "bin"
    replayed = 0
    settings: dict[str, str] = {}
    arguments: dict[str, str] = {}  # the build's alone, not the image's environment
    for keyword, args in dockerfile:
        if keyword == "ARG":
            name, _, default = args.partition("=")
            arguments[name] = (build_args or {}).get(name, default)
        elif keyword == "ENV":
            for pair in shlex.split(args):
                name, _, value = pair.partition("=")
                settings[name] = value.replace("/app", str(build), 1)
        elif keyword == "COPY":
            source, target = args.split()
            destination = (build / target).resolve()
            if (REPO_ROOT / source).is_dir():
                shutil.copytree(REPO_ROOT / source, destination, dirs_exist_ok=True)
            else:
                destination.parent.mkdir(parents=True, exist_ok=True)
                shutil.copy2(REPO_ROOT / source, destination if target != "./" else build)
        elif keyword == "RUN":
            command = shlex.split(args)
            if command[0] == "vtrack":  # in the build's shell: it expands the ARGs and ENVs
                command = ["sh", "-c", args]
                path = f"{bindir}{os.pathsep}{os.environ.get('PATH', '')}"
            elif command[0] in ("pip", "python"):
                command[0] = str(bindir / command[0])
                path = os.environ.get("PATH", "")
            else:
                continue
            result = subprocess.run(
                command,
                cwd=build,
                capture_output=True,
                text=True,
                env={**os.environ, **settings, **arguments, "PATH": path},
            )
            assert result.returncode == 0, f"RUN {args}\n{result.stdout}\n{result.stderr}"
            replayed += 1
    assert replayed >= 3
    return settings


_SHIPPED_CASCADES = (
    "from tracking.detection.dpm.detector import KNOWN_CASCADES; "
    "from tracking.detection.dpm.cascade import load_cascade; "
    "assert all(load_cascade(p) for p in KNOWN_CASCADES.values())"
)


@pytest.mark.slow
@pytest.mark.timeout(900)
def test_dockerfile_install_steps_give_a_working_service(dockerfile, tmp_path, shared_data):
    from service.models import DEFAULT_DETECTOR, DEFAULT_POSE, DEFAULT_REID, model_state

    build, env_dir = tmp_path / "app", tmp_path / "env"
    build.mkdir()
    mirror = {"VTRACK_MODELS_MIRROR": str(shared_data / "models")}  # no internet here
    image_env = _replay(dockerfile, build, env_dir, build_args=mirror)
    # the default networks in the image, verified, inside the build (not a mounted volume)
    models_dir = Path(image_env["VTRACK_MODELS_DIR"])
    assert models_dir.is_relative_to(build)
    for name in (DEFAULT_DETECTOR, DEFAULT_POSE, DEFAULT_REID):
        assert model_state(models_dir, name) == "present", name
    bindir = env_dir / "bin"
    elsewhere = tmp_path / "elsewhere"  # not the build folder: import the installed package
    elsewhere.mkdir()
    clean_env = {k: v for k, v in os.environ.items() if not k.startswith("VTRACK_")}
    clean_env.pop("PYTHONPATH", None)
    clean_env.update(image_env)
    # The kernels the build compiled are those the service runs: none compiles again (was:
    # the warm-up compiled the sources in the build folder, the service the installed copy).
    cache = Path(image_env["NUMBA_CACHE_DIR"])
    compiled = sorted(cache.rglob("*.nbi"))
    assert compiled
    warm = [str(bindir / "python"), "-c", "from tracking.warmup import warm_up; warm_up()"]
    subprocess.run(warm, cwd=elsewhere, env=clean_env, check=True, capture_output=True)
    assert sorted(cache.rglob("*.nbi")) == compiled
    for command in (
        [str(bindir / "vtrack"), "--help"],
        [str(bindir / "python"), "-c", "import service.app, api_schemas, tracking.pipeline"],
        # package data: the DPM cascade thresholds shipped for the INRIA person model
        [str(bindir / "python"), "-c", _SHIPPED_CASCADES],
    ):
        result = subprocess.run(
            command, cwd=elsewhere, capture_output=True, text=True, env=clean_env
        )
        assert result.returncode == 0, result.stderr
    # Start the installed service and run the image's HEALTHCHECK command against it.
    port = free_port()
    env = {**clean_env, "VTRACK_PORT": str(port), "VTRACK_DATA_DIR": str(tmp_path / "data")}
    server = subprocess.Popen(
        [str(bindir / "vtrack"), "serve", "--workers", "1"],
        cwd=elsewhere,
        env=env,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
    )
    try:

        def up():
            response = try_get(f"http://127.0.0.1:{port}/readyz")
            return response is not None and response.status_code == 200

        wait_for(up, 60, "the installed service")
        # jobs run the image's networks
        ready = json.loads(try_get(f"http://127.0.0.1:{port}/readyz").text)
        assert ready["detector"]["model"] == DEFAULT_DETECTOR
        assert (ready["pose"], ready["reid"]) == ({"model": DEFAULT_POSE}, {"model": DEFAULT_REID})
        healthcheck = json.loads(dict(dockerfile)["HEALTHCHECK"].split("CMD", 1)[1])
        healthcheck[0] = str(bindir / healthcheck[0])
        assert subprocess.run(healthcheck, env=env, cwd=elsewhere).returncode == 0
    finally:
        server.terminate()
        server.wait(timeout=30)


PKI = "/etc/vtrack/zenoh"
"""Where the compose file's services see the certificates volume."""
SCALEOUT = ("vtrack-a", "vtrack-b")
"""The service instances of the compose file's profile ``scaleout``, on one PostgreSQL."""

_VARIABLE = re.compile(r"\$(?:\$|\{(\w+)(?:(:?-)([^}]*))?\}|(\w+))")


def _interpolate(text: str, environ: dict[str, str]) -> str:
    """Compose's interpolation of a value with the shell's ``environ``: ``${NAME}``,
    ``$NAME``, ``${NAME:-default}`` (unset or empty), ``${NAME-default}`` (unset), ``$$``."""

    def value(match: re.Match[str]) -> str:
        if match.group(0) == "$$":
            return "$"
        given = environ.get(match.group(1) or match.group(4))
        operator, default = match.group(2), match.group(3)
        if (operator == ":-" and not given) or (operator == "-" and given is None):
            return default
        return given or ""

    return _VARIABLE.sub(value, text)


def _compose(**environ: str) -> dict:
    """The compose file as ``docker compose`` reads it with ``environ`` in the shell: its
    values interpolated (anchors and merge keys resolved first, as the YAML parser does)."""

    def interpolated(node: object) -> object:
        if isinstance(node, dict):
            return {key: interpolated(value) for key, value in node.items()}
        if isinstance(node, list):
            return [interpolated(value) for value in node]
        return _interpolate(node, environ) if isinstance(node, str) else node

    return interpolated(yaml.safe_load((DOCKER / "compose.yaml").read_text()))


def test_compose_interpolation_reads_as_compose_does():
    text = "a: ${X:-d} b: ${Y-d} c: ${X} d: $X e: $$X f: ${Z:-}"
    assert _interpolate(text, {"X": "1", "Y": ""}) == "a: 1 b:  c: 1 d: 1 e: $X f: "
    assert _interpolate(text, {"X": ""}) == "a: d b: d c:  d:  e: $X f: "


def test_compose_file_parses_and_names_files_that_exist(dockerfile):
    compose = yaml.safe_load((DOCKER / "compose.yaml").read_text())
    services = compose["services"]
    assert set(services) == {"vtrack", "zenoh", "zenoh-setup", "postgres", *SCALEOUT}
    # `docker compose up` (no profile) runs the single service and its router, as before
    for name in ("vtrack", "zenoh", "zenoh-setup"):
        assert "profiles" not in services[name], name
    service = services["vtrack"]
    context = (DOCKER / service["build"]["context"]).resolve()
    assert context == REPO_ROOT.resolve()
    assert (context / service["build"]["dockerfile"]).is_file()
    assert service["ports"] == ["8000:8000"]
    assert "zenoh" in service["depends_on"]
    for name, spec in services.items():
        for volume in spec.get("volumes", []):
            source = volume.split(":")[0]
            if source.startswith("."):
                assert (DOCKER / source).exists(), f"{name} mounts {source}, which does not exist"
            else:
                assert source in compose["volumes"], f"{name} mounts unknown volume {source}"
    for name in ("vtrack", *SCALEOUT):
        for key, value in services[name]["environment"].items():
            assert key.startswith("VTRACK_") and isinstance(value, str), (name, key)
    zenoh = services["zenoh"]
    assert zenoh["image"].startswith("eclipse/zenoh:")
    assert zenoh["command"] == ["-c", f"{PKI}/router.json5"]
    assert f"zenoh-pki:{PKI}:ro" in zenoh["volumes"]
    assert zenoh["depends_on"]["zenoh-setup"]["condition"] == "service_completed_successfully"
    assert zenoh["ports"] == ["7447:7447"]
    # the service and the setup that writes the router's rules read the same Zenoh settings
    setup = services["zenoh-setup"]
    assert setup["environment"].items() <= service["environment"].items()
    assert setup["image"] == service["image"]


def _compose_setup(folder: Path, **granted: str) -> dict[str, str]:
    """Run the compose file's zenoh-setup command here, with ``folder`` for the certificates
    volume and ``granted`` settings over its environment (as the operator edits them); the
    environment it ran with."""
    setup = yaml.safe_load((DOCKER / "compose.yaml").read_text())["services"]["zenoh-setup"]
    env = {k: v.replace(PKI, str(folder)) for k, v in setup["environment"].items()}
    env.update({f"VTRACK_{k.upper()}": v for k, v in granted.items()})
    script = setup["command"][-1].replace(PKI, str(folder))
    vtrack = f"{shlex.quote(str(Path(sys.executable)))} -m service.cli"
    clean = {k: v for k, v in os.environ.items() if not k.startswith("VTRACK_")}
    result = subprocess.run(
        ["sh", "-c", script.replace("vtrack ", f"{vtrack} ")],
        cwd=REPO_ROOT,
        env=clean | env,
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert result.returncode == 0, result.stderr
    return env


def test_compose_environment_names_real_settings():
    from service.settings import Settings

    compose = yaml.safe_load((DOCKER / "compose.yaml").read_text())
    known = {f"VTRACK_{name.upper()}" for name in Settings.model_fields}
    text = (DOCKER / "compose.yaml").read_text()
    named = {word.strip(":") for word in text.split() if word.startswith("VTRACK_")}
    assert named <= known, named - known
    for name in ("vtrack", *SCALEOUT):
        assert set(compose["services"][name]["environment"]) <= known, name


def test_compose_environment_parses_and_reaches_the_router(monkeypatch, tmp_path):
    from service.settings import Settings

    compose = yaml.safe_load((DOCKER / "compose.yaml").read_text())
    _compose_setup(tmp_path)  # the certificates the settings name
    for key, value in compose["services"]["vtrack"]["environment"].items():
        monkeypatch.setenv(key, value.replace(PKI, str(tmp_path)))
    settings = Settings()
    router = compose["services"]["zenoh"]["ports"][0].split(":")[1]
    assert settings.zenoh.connect == (f"tls/zenoh:{router}",)
    assert settings.zenoh.mode == "client" and settings.zenoh.security.tls.client_auth


def _data_volume(spec: dict) -> str:
    """The volume a compose service mounts at ``/data``."""
    (source,) = [v.split(":")[0] for v in spec["volumes"] if v.split(":")[1] == "/data"]
    return source


def test_compose_scaleout_profile_runs_two_instances_on_one_database_and_volume():
    compose = _compose()
    services = compose["services"]
    single, postgres = services["vtrack"], services["postgres"]
    instances = [services[name] for name in SCALEOUT]
    for spec in (postgres, *instances):
        assert spec["profiles"] == ["scaleout"]
    # the single service's image, its settings and the router's (x-zenoh)
    setup = services["zenoh-setup"]
    for spec in instances:
        assert (spec["build"], spec["image"]) == (single["build"], single["image"])
        assert single["environment"].items() < spec["environment"].items()
        assert setup["environment"].items() <= spec["environment"].items()
        assert spec["restart"] == single["restart"]
        assert spec["stop_grace_period"] == single["stop_grace_period"]
    # one data volume for both, not the single service's; certificates and models as it has
    shared = {_data_volume(spec) for spec in instances}
    assert len(shared) == 1 and shared != {_data_volume(single)}
    assert shared <= set(compose["volumes"])
    for spec in instances:
        others = {v for v in spec["volumes"] if v.split(":")[1] != "/data"}
        assert others == {v for v in single["volumes"] if v.split(":")[1] != "/data"}
    # names of their own, host ports of their own, the service's port inside
    names = [spec["environment"]["VTRACK_INSTANCE_NAME"] for spec in instances]
    assert len(set(names)) == len(names)
    ports = [port for spec in (single, *instances) for port in spec["ports"]]
    assert len({port.split(":")[0] for port in ports}) == len(ports)
    assert {port.split(":")[1] for port in ports} == {"8000"}
    # started once PostgreSQL is ready (its health check) and the router has started
    healthcheck = postgres["healthcheck"]["test"]
    assert healthcheck[0] == "CMD" and healthcheck[1] == "pg_isready"
    for spec in instances:
        assert spec["depends_on"]["postgres"]["condition"] == "service_healthy"
        assert "zenoh" in spec["depends_on"]
    # PostgreSQL 16 (the tests' server's major version, test_compose_scaleout_instances_...),
    # its data in a named volume, not published on the host
    assert postgres["image"] == "postgres:16"
    (data,) = postgres["volumes"]
    assert data.split(":")[0] in compose["volumes"]
    assert data.split(":")[1] == "/var/lib/postgresql/data"
    assert "ports" not in postgres


@pytest.mark.parametrize("shell", [{}, {"POSTGRES_PASSWORD": "s3cret"}])
def test_compose_scaleout_database_url_has_the_postgres_service_credentials(shell):
    from urllib.parse import urlsplit

    services = _compose(**shell)["services"]
    database = services["postgres"]["environment"]
    user, password = database["POSTGRES_USER"], database["POSTGRES_PASSWORD"]
    # a default to change (the comments say how), or the shell's
    assert password == shell.get("POSTGRES_PASSWORD", "change-me")
    healthcheck = services["postgres"]["healthcheck"]["test"]
    assert healthcheck[healthcheck.index("-U") + 1] == user
    assert healthcheck[healthcheck.index("-d") + 1] == database["POSTGRES_DB"]
    for name in SCALEOUT:
        url = urlsplit(services[name]["environment"]["VTRACK_DATABASE_URL"])
        assert url.scheme == "postgresql"
        assert (url.username, url.password) == (user, password)
        assert (url.hostname, url.port) == ("postgres", 5432)  # the service's name and port
        assert url.path == f"/{database['POSTGRES_DB']}"


def _service_environment(name: str, folder: Path, **overrides: str) -> dict[str, str]:
    """The environment of the compose file's service ``name``, the certificates volume read as
    ``folder`` (where _compose_setup made them), ``overrides`` (settings by name) over it."""
    environment = _compose()["services"][name]["environment"]
    env = {key: value.replace(PKI, str(folder)) for key, value in environment.items()}
    env.update({f"VTRACK_{key.upper()}": value for key, value in overrides.items()})
    return env


def test_compose_scaleout_environment_parses(monkeypatch, tmp_path):
    from service.settings import Settings

    _compose_setup(tmp_path)  # the certificates the settings name
    for key, value in _service_environment("vtrack", tmp_path).items():
        monkeypatch.setenv(key, value)
    alone = Settings()
    seen = set()
    for name in SCALEOUT:
        for key, value in _service_environment(name, tmp_path).items():
            monkeypatch.setenv(key, value)
        settings = Settings()
        assert settings.instance == settings.instance_name == name
        assert str(settings.job_database).startswith("postgresql://vtrack:")
        assert settings.zenoh == alone.zenoh  # on the single service's Zenoh network
        seen.add(settings.instance)
    assert len(seen) == len(SCALEOUT)


def test_compose_router_is_of_the_release_line_the_project_installs():
    # before: eclipse/zenoh:1.0.0 beside a client that pip resolved to 1.10
    import tomllib

    from packaging.requirements import Requirement

    image = yaml.safe_load((DOCKER / "compose.yaml").read_text())["services"]["zenoh"]["image"]
    router = image.removeprefix("eclipse/zenoh:")
    project = tomllib.loads((REPO_ROOT / "pyproject.toml").read_text())["project"]
    (spec,) = [
        Requirement(r).specifier
        for r in project["dependencies"]
        if Requirement(r).name == "eclipse-zenoh"
    ]
    major, minor, _ = map(int, router.split("."))
    assert spec.contains(router) and not spec.contains(f"{major}.{minor + 1}.0")
    assert importlib.metadata.version("eclipse-zenoh").split(".")[:2] == [str(major), str(minor)]


def test_the_compose_router_relays_a_granted_camera_and_no_one_else(tmp_path, monkeypatch):
    # The router's configuration is what zenoh-setup writes from the compose settings, with a
    # camera granted as the compose file's comment says; the router runs in a router of the
    # eclipse-zenoh package of that release, the service as compose runs it (a client).
    import zenoh

    from service.settings import Settings
    from service.streams.security import TlsFiles, ZenohSecurity
    from service.streams.session import ZenohOptions, ZenohUnavailable, open_session

    certificates = [sys.executable, "-m", "service.cli", "zenoh", "certificates"]
    certificates += [str(tmp_path), "--client", "gate-cam", "--client", "intruder"]
    subprocess.run(certificates, cwd=REPO_ROOT, check=True, capture_output=True, timeout=60)
    env = _compose_setup(tmp_path, zenoh_cameras='{"gate-cam": ["door"]}')
    router_endpoint = f"tls/127.0.0.1:{free_port()}"
    config = zenoh.Config.from_file(str(tmp_path / "router.json5"))
    config.insert_json5("listen/endpoints", json.dumps([router_endpoint]))
    for key, value in env.items():
        monkeypatch.setenv(key, value)
    service = Settings().zenoh
    service = dataclasses.replace(service, connect=(router_endpoint,))

    def camera(name: str | None) -> ZenohOptions:
        files = TlsFiles(
            tmp_path / f"{name}.pem" if name else None,
            tmp_path / f"{name}.key" if name else None,
            tmp_path / "ca.pem",
            client_auth=name is not None,
        )
        return ZenohOptions("client", (), (router_endpoint,), security=ZenohSecurity(files))

    received: list[bytes] = []
    with contextlib.ExitStack() as stack:
        stack.callback(zenoh.open(config).close)
        hub = open_session(service.hub_config())
        stack.callback(hub.close)
        with pytest.raises(ZenohUnavailable):  # no client certificate
            open_session(camera(None).member_config())
        member = open_session(camera("gate-cam").member_config())
        stack.callback(member.close)
        intruder = open_session(camera("intruder").member_config())
        stack.callback(intruder.close)
        subscriber = hub.declare_subscriber(
            "vtrack/cameras/door/frames", lambda sample: received.append(sample.payload.to_bytes())
        )
        stack.callback(subscriber.undeclare)

        def delivered() -> bool:
            intruder.put("vtrack/cameras/door/frames", b"forged")
            member.put("vtrack/cameras/door/frames", b"frame")
            return bool(received)

        wait_for(delivered, 10, "a camera's frame relayed by the router", interval=0.2)
        # a pause, not a condition: what is checked is that the intruder's frames never come,
        # though they were sent as often as the member's that came
        time.sleep(0.5)
        assert set(received) == {b"frame"}  # the intruder's certificate is good, its right none


@pytest.fixture
def postgres_server():
    """A PostgreSQL server of the test's own (tests/postgres.py)."""
    from tests.postgres import running_postgres

    with running_postgres() as server:
        yield server


@pytest.mark.scaleout
def test_compose_scaleout_instances_answer_and_share_the_streams_and_cameras(
    postgres_server, tmp_path
):
    """The profile's two instances as compose runs them, on a PostgreSQL server with the
    postgres service's user, password and database (its host and port the test server's), and
    a router of the configuration zenoh-setup writes (its endpoint on loopback): each answers
    /readyz with its name, and of two streams created through one, each tracks the camera that
    hashes to it: they share the streams table, and see each other's liveliness tokens through
    the router (with a router each, both track both cameras)."""
    import psycopg
    import zenoh

    from devtools.testing import Server
    from service.streams.manager import _owner_of

    compose = _compose()
    database = compose["services"]["postgres"]["environment"]
    with psycopg.connect(postgres_server.url, autocommit=True) as connection:
        # the image's POSTGRES_USER is a superuser, the owner of POSTGRES_DB
        (version,) = connection.execute("SHOW server_version_num").fetchone()
        user, password = database["POSTGRES_USER"], database["POSTGRES_PASSWORD"]
        connection.execute(f"CREATE ROLE {user} LOGIN SUPERUSER PASSWORD '{password}'")
        connection.execute(f"ALTER DATABASE {database['POSTGRES_DB']} OWNER TO {user}")
    assert compose["services"]["postgres"]["image"] == f"postgres:{int(version) // 10000}"
    pki = tmp_path / "pki"
    pki.mkdir()
    _compose_setup(pki)
    here = f"@127.0.0.1:{postgres_server.port}/"  # the test server's, for "@postgres:5432/"
    router = f"tls/127.0.0.1:{free_port()}"
    config = zenoh.Config.from_file(str(pki / "router.json5"))
    config.insert_json5("listen/endpoints", json.dumps([router]))
    servers = {}
    with contextlib.ExitStack() as stack:
        stack.callback(zenoh.open(config).close)
        for name in SCALEOUT:
            env = _service_environment(name, pki, zenoh_connect=json.dumps([router]))
            settings = {key.removeprefix("VTRACK_").lower(): value for key, value in env.items()}
            settings["database_url"] = settings["database_url"].replace("@postgres:5432/", here)
            servers[name] = Server(tmp_path / "data", name=name, **settings)
            stack.callback(servers[name].stop)
            servers[name].start()
        for name, server in servers.items():
            ready = try_get(f"{server.url}/readyz").json()
            assert (ready["instance"], ready["zenoh"]) == (name, "ok"), server.log_tail()
        cameras = [f"cam{index}" for index in range(20)]
        owners = {camera: _owner_of(camera, list(SCALEOUT)) for camera in cameras}
        chosen = [next(c for c in cameras if owners[c] == name) for name in SCALEOUT]
        with servers[SCALEOUT[0]].client() as client:
            for camera in chosen:
                response = client.post("/v1/streams", json={"camera": camera})
                assert response.status_code == 201, response.text

        def tracked_by_owners_alone() -> bool:
            for camera in chosen:
                tracking = set()
                for name, server in servers.items():
                    with server.client() as client:
                        status = client.get(f"/v1/streams/{camera}").json()
                    if status.get("state") in ("waiting", "running"):
                        tracking.add(name)
                if tracking != {owners[camera]}:
                    return False
            return True

        wait_for(tracked_by_owners_alone, 60, "each camera tracked by its owner alone", 0.5)
