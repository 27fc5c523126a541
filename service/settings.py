"""Service settings, read from ``VTRACK_*`` environment variables (docs/settings.md)."""

from __future__ import annotations

import difflib
import ipaddress
import os
import re
import socket
import sys
from collections.abc import Collection, Mapping
from pathlib import Path
from typing import Any, Literal

from pydantic import (
    BaseModel,
    ConfigDict,
    Field,
    SecretStr,
    ValidationError,
    field_validator,
    model_validator,
)
from pydantic_settings import BaseSettings, SettingsConfigDict, SettingsError

from api_schemas.common import error_message
from api_schemas.streams import PREFIX_PATTERN, StreamSpec
from service.models.catalog import DEFAULT_DETECTOR, DEFAULT_POSE, DEFAULT_REID
from service.models.resolve import (
    CNN_SETTING,
    MODEL_SETTINGS,
    POSE_SETTING,
    REID_SETTING,
    ModelSetting,
    check_model_setting,
    model_setting_path,
)
from service.streams.security import TlsFiles, ZenohSecurity, build_security
from service.streams.session import (
    DEFAULT_LISTEN,
    MESSAGE_MARGIN,
    ZenohOptions,
    ZenohUnavailable,
    endpoint_address,
    load_config_file,
    zenoh_endpoint,
)

LOG_LEVELS = ("critical", "error", "warning", "info", "debug")
"""The levels both Python's logging and uvicorn know."""


def _default_workers() -> int:
    return max(1, len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else 1)


_WITHOUT = {
    "retention_hours": "finished jobs kept until deleted, or give hours",
    "database_url": "the data folder's own SQLite database, or give a postgresql:// URL",
    "dpm_model": "no DPM (the embedded detector), or give the model file's path",
    "color_names": "the embedded colour naming, or give the w2c.mat path",
    "models_dir": "no CNN models folder (the embedded detector), or give the folder",
    "cnn_model": "the default model of VTRACK_MODELS_DIR, or give a model name or file",
    "pose_model": "the default pose model of VTRACK_MODELS_DIR, or give a model name or file",
    "reid_model": "the default re-identification model of VTRACK_MODELS_DIR, or give a model "
    "name or file",
    "zenoh_tls_certificate": "no TLS certificate, or give its PEM file",
    "zenoh_tls_private_key": "no TLS key, or give its PEM file",
    "zenoh_tls_root_ca": "no root CA, or give its PEM file",
    "zenoh_users_file": "no Zenoh authentication, or give the user:password file",
    "zenoh_user": "no Zenoh user name, or give one",
}
"""What an optional setting means when unset, for the message about an empty one."""


def ip_address(text: str) -> ipaddress.IPv4Address | ipaddress.IPv6Address | None:
    """``text`` as an IP address (an IPv6 one in brackets or not); None for a name."""
    try:
        return ipaddress.ip_address(text.strip("[]"))
    except ValueError:
        return None


def is_loopback(address: str) -> bool:
    """Whether a listening address is reachable from this machine only (a wildcard is an
    address; a host name is whatever it resolves to)."""
    ip = ip_address(address)
    return address == "localhost" or (ip is not None and ip.is_loopback)


class WebhookSetting(BaseModel):
    """A receiver of events: ``name`` (in metrics and logs), ``url`` and the ``secret`` that
    signs each body (unset: unsigned)."""

    model_config = ConfigDict(extra="forbid")

    name: str = Field(min_length=1, max_length=64, pattern=r"^[A-Za-z0-9_.-]+$")
    url: str = Field(pattern=r"^https?://", description="http:// or https:// address.")
    secret: SecretStr | None = None


class Settings(BaseSettings):
    """Everything the service reads from its environment; tests build one directly."""

    model_config = SettingsConfigDict(env_prefix="VTRACK_", extra="ignore")

    data_dir: Path = Field(
        default=Path("vtrack-data"),
        description="Folder of the job database (jobs.sqlite3), uploads and results; with "
        "VTRACK_DATABASE_URL, a folder every instance reaches (a network file system mount).",
    )
    database_url: SecretStr | None = Field(
        default=None,
        description="postgresql://user:password@host:port/database: jobs in PostgreSQL, shared "
        "by every service instance given the same URL and data folder (scale-out); unset, "
        "jobs.sqlite3 of the data folder, for this service alone.",
    )
    job_lease_seconds: float = Field(
        default=15.0,
        ge=1,
        le=3600,
        description="With VTRACK_DATABASE_URL: how long an instance's claim on a running job "
        "holds unless renewed (every third of it); the jobs of an instance that died are "
        "queued again by the others this long after its last renewal.",
    )
    instance_name: str | None = Field(
        default=None,
        pattern=r"^[A-Za-z0-9][A-Za-z0-9_.\-]{0,63}$",
        description="This instance's name in /readyz, /metrics and the jobs it runs (default: "
        "the host name and process id).",
    )
    host: str = Field(default="127.0.0.1", description="Address `vtrack serve` binds.")
    port: int = Field(default=8000, ge=0, le=65535, description="Port `vtrack serve` binds.")
    workers: int = Field(
        default_factory=_default_workers,
        ge=1,
        le=64,
        description="Worker processes (jobs at once).",
    )
    max_upload_bytes: int = Field(
        default=2 * 1024**3, ge=1, description="Largest accepted upload in bytes (413 above)."
    )
    upload_idle_seconds: float = Field(
        default=60.0,
        gt=0,
        le=3600,
        description="Seconds an upload may send nothing before it is cut (408, nothing kept).",
    )
    body_idle_seconds: float = Field(
        default=10.0,
        gt=0,
        le=3600,
        description="Seconds a request body other than an upload's may send nothing before it "
        "is cut (408).",
    )
    header_seconds: float = Field(
        default=10.0,
        gt=0,
        le=3600,
        description="Seconds a connection may take to send a request's headers, from its "
        "opening or, on a kept-alive connection, from the request's first byte; slower ones "
        "are closed (408).",
    )
    max_connections: int = Field(
        default=256,
        ge=1,
        le=100_000,
        description="HTTP connections served at once; a request on one beyond gets 503 and its "
        "connection is closed.",
    )
    max_event_streams: int = Field(
        default=100,
        ge=1,
        le=10_000,
        description="Clients that may follow job events (/v1/jobs/{id}/events) at once (503 "
        "beyond).",
    )
    job_timeout: float = Field(
        default=4 * 3600.0, gt=0, description="Seconds a job may run before it is failed."
    )
    job_stall_timeout: float = Field(
        default=600.0,
        gt=0,
        description="Seconds a running job may go without reading a frame before it is "
        "failed and its worker replaced (a decoder that hangs, a stopped process).",
    )
    max_attempts: int = Field(
        default=3,
        ge=1,
        description="Times the service or its fork server may die (crash, kill -9, the OOM "
        "killer) while a job runs before the job is failed instead of started again; clean "
        "stops (SIGTERM) do not count.",
    )
    retention_hours: float | None = Field(
        default=None,
        gt=0,
        description="Finished jobs (succeeded, failed, cancelled) are deleted with their results "
        "this many hours after they finished; unset: kept until DELETE /v1/jobs/{id}.",
    )
    min_free_mb: float = Field(
        default=64,
        ge=0,
        description="Free space, in MB, the data folder's disk must have for /readyz to say "
        "ready: below it the service is full (an upload would not fit).",
    )
    housekeeping_interval: float = Field(
        default=60.0,
        ge=0.1,
        le=3600,
        description="Seconds between sweeps that remove finished jobs' uploads and expired jobs.",
    )
    allowed_hosts: list[str] = Field(
        default_factory=list,
        description="JSON list of host names a service listening on loopback answers to besides "
        "its addresses and localhost (those a proxy in front passes on).",
    )
    api_token: SecretStr | None = Field(
        default=None,
        description="When set, every endpoint but /healthz and /readyz needs "
        "'Authorization: Bearer <token>'.",
    )
    dpm_model: Path | None = Field(
        default=None,
        description="voc-release5 person model (.mat) for jobs with detector 'dpm'.",
    )
    color_names: Path | None = Field(
        default=None,
        description="van de Weijer w2c.mat Color Names table; default: the embedded model.",
    )
    models_dir: Path | None = Field(
        default=None,
        description="Folder of CNN model files as `vtrack models fetch --dir` lays them out: "
        "detector 'auto' runs the CNN when its model (VTRACK_CNN_MODEL) is there, and people "
        "jobs the pose and re-identification networks when theirs are (VTRACK_POSE_MODEL, "
        "VTRACK_REID_MODEL).",
    )
    cnn_model: str | None = Field(
        default=None,
        description="The CNN person detector's network: a model name of VTRACK_MODELS_DIR "
        f"(default: {DEFAULT_DETECTOR}) or the path of an OpenVINO .xml or an .onnx file.",
    )
    pose_model: str | None = Field(
        default=None,
        description="The body-keypoint network people jobs run when it is there (job option "
        f"tracker.pose): a model name of VTRACK_MODELS_DIR (default: {DEFAULT_POSE}) or the "
        "path of an OpenVINO .xml or an .onnx file.",
    )
    reid_model: str | None = Field(
        default=None,
        description="The re-identification network people jobs run when it is there (job "
        "option tracker.reid): a model name of VTRACK_MODELS_DIR (default: "
        f"{DEFAULT_REID}; also person-reidentification-retail-0277 and -0288) or the path of "
        "an OpenVINO .xml or an .onnx file.",
    )
    inference_threads: int = Field(
        default=0,
        ge=0,
        le=64,
        description="Threads of each CNN inference (the detector, the pose and the "
        "re-identification networks); 0: every core, as the other detectors use (two jobs at "
        "once on 2 cores ran faster with 2 threads each than with 1).",
    )
    poll_interval: float = Field(
        default=0.2, gt=0, le=5, description="Seconds an idle worker waits between job checks."
    )
    log_level: str = Field(
        default="info",
        description="Logging level of the service: critical, error, warning, info or debug.",
    )
    zenoh_enabled: bool = Field(
        default=True, description="Open a Zenoh session and serve live streams (/v1/streams)."
    )
    zenoh_mode: Literal["peer", "client"] = Field(
        default="peer",
        description="'peer': cameras and workers meet at the service's listen endpoint; "
        "'client': everything goes through the router(s) in VTRACK_ZENOH_CONNECT.",
    )
    zenoh_listen: list[str] = Field(
        default_factory=lambda: list(DEFAULT_LISTEN),
        description="JSON list of endpoints the service's Zenoh session listens on (peer mode).",
    )
    zenoh_connect: list[str] = Field(
        default_factory=list,
        description='JSON list of endpoints to connect to, e.g. ["tcp/zenoh:7447"] (a router).',
    )
    zenoh_config: Path | None = Field(
        default=None,
        description="A Zenoh JSON5 configuration file to start from (the settings above apply "
        "over it; multicast scouting stays as the file says).",
    )
    zenoh_tls_certificate: Path | None = Field(
        default=None,
        description="PEM certificate the service's Zenoh session presents on tls/ endpoints "
        "(`vtrack zenoh certificates` makes a local CA and certificates).",
    )
    zenoh_tls_private_key: Path | None = Field(
        default=None, description="PEM private key of VTRACK_ZENOH_TLS_CERTIFICATE."
    )
    zenoh_tls_root_ca: Path | None = Field(
        default=None,
        description="PEM certificate of the authority that signed the other side's "
        "certificates (the router's, or the clients' with VTRACK_ZENOH_TLS_CLIENT_AUTH).",
    )
    zenoh_tls_client_auth: bool = Field(
        default=False,
        description="Mutual TLS: accept only Zenoh clients whose certificate the root CA "
        "signed; without VTRACK_ZENOH_USERS_FILE their common names are the principals of "
        "VTRACK_ZENOH_CAMERAS and VTRACK_ZENOH_READERS.",
    )
    zenoh_user: str | None = Field(
        default=None,
        description="User name the service's Zenoh sessions present (user/password "
        "authentication; also what `vtrack publish` and `vtrack subscribe` present).",
    )
    zenoh_password: SecretStr | None = Field(
        default=None, description="Password of VTRACK_ZENOH_USER."
    )
    zenoh_users_file: Path | None = Field(
        default=None,
        description="Whom the service's Zenoh session accepts: one user:password per line. "
        "Turns authentication and access control on.",
    )
    zenoh_cameras: dict[str, list[str]] = Field(
        default_factory=dict,
        description="With authentication: which principal publishes which cameras' frames "
        'and detections, e.g. {"gate-cam": ["gate"], "gateway": ["*"]}; nobody else may.',
    )
    zenoh_readers: dict[str, list[str]] = Field(
        default_factory=dict,
        description="With authentication: which principal reads which cameras' tracks, e.g. "
        '{"dashboard": ["*"]}; nobody else may.',
    )
    zenoh_allow_open: bool = Field(
        default=False,
        description="Let Zenoh listen beyond loopback without authentication (anyone who "
        "reaches it can publish frames and read tracks): a warning at every start.",
    )
    zenoh_prefix: str = Field(
        default="vtrack",
        pattern=PREFIX_PATTERN,
        description="First chunk(s) of every key expression: <prefix>/cameras/<camera>/frames.",
    )
    streams: list[StreamSpec] = Field(
        default_factory=list,
        description="JSON list of streams started with the service, each like the body of "
        'POST /v1/streams, e.g. [{"camera": "gate"}].',
    )
    stream_frame_limit: int = Field(
        default=32 * 1024**2,
        ge=1024,
        description="Largest frame payload in bytes a stream accepts (larger ones are counted "
        "as malformed).",
    )
    webhooks: list[WebhookSetting] = Field(
        default_factory=list,
        description="JSON list of webhooks that receive the events of streams and the "
        'summaries of finished jobs, e.g. [{"name": "ops", "url": "https://ops.example/hook", '
        '"secret": "..."}]: HTTP POST of JSON, signed with HMAC-SHA256 of the secret.',
    )
    mqtt_url: SecretStr | None = Field(
        default=None,
        description="An MQTT broker that receives the same events (QoS 1): "
        "mqtt://[user:password@]host[:port], or mqtts:// for TLS.",
    )
    mqtt_topic_prefix: str = Field(
        default="vtrack",
        pattern=r"^[A-Za-z0-9_.-]+(/[A-Za-z0-9_.-]+)*$",
        description="First level(s) of the MQTT topics: <prefix>/cameras/<camera>/events/<type>.",
    )
    events_max_age_hours: float = Field(
        default=168,
        gt=0,
        description="Hours an event waits for a sink that is down before it is dropped (and "
        "counted in vtrack_events_dropped_total).",
    )

    @field_validator("webhooks")
    @classmethod
    def _webhooks_named_apart(cls, value: list[WebhookSetting]) -> list[WebhookSetting]:
        names = [hook.name for hook in value]
        if twice := sorted({name for name in names if names.count(name) > 1}):
            raise ValueError(f"each webhook needs a name of its own: {', '.join(twice)} repeats")
        if "mqtt" in names:
            raise ValueError("'mqtt' names the MQTT broker's events: give the webhook another")
        return value

    @field_validator("mqtt_url")
    @classmethod
    def _mqtt_address(cls, value: SecretStr | None) -> SecretStr | None:
        if value is not None and not re.match(r"^mqtts?://[^/]+$", value.get_secret_value()):
            raise ValueError("an MQTT broker's address is mqtt://[user:password@]host[:port]")
        return value

    @field_validator(
        "dpm_model",
        "color_names",
        "zenoh_config",
        "zenoh_tls_certificate",
        "zenoh_tls_private_key",
        "zenoh_tls_root_ca",
        "zenoh_users_file",
    )
    @classmethod
    def _existing_file(cls, value: Path | None) -> Path | None:
        if value is not None and not value.is_file():
            raise ValueError(f"{value} is not a file")
        return value

    @field_validator("models_dir")
    @classmethod
    def _existing_folder(cls, value: Path | None) -> Path | None:
        if value is not None and not value.is_dir():
            raise ValueError(f"{value} is not a folder (`vtrack models fetch --dir` makes one)")
        return value

    @model_validator(mode="after")
    def _networks_loadable(self) -> Settings:
        # A network that is not one stops the service when it starts, rather than failing
        # every job; a models folder without a default model is not an error (detector 'auto'
        # falls back to the embedded one, tracker.pose and tracker.reid to none, and /readyz
        # says so). The three settings are checked alike (the message names the setting).
        for setting in MODEL_SETTINGS:
            check_model_setting(setting, getattr(self, setting.field), self.models_dir)
        return self

    @field_validator("dpm_model", "color_names")
    @classmethod
    def _loadable(cls, value: Path | None, info) -> Path | None:
        # A file that is not a model stops the service when it starts, rather than failing
        # every job that needs it (the loads take well under a second). Imported here: the
        # detection package takes a third of a second to import, for every user of settings.
        if value is not None:
            from tracking.detection.dpm.model import load_dpm_model
            from tracking.features.colornames import load_w2c_table

            # their ValueError says what is wrong with the file; load_settings names the setting
            if info.field_name == "dpm_model":
                load_dpm_model(value)
            else:
                load_w2c_table(value)
        return value

    @field_validator("zenoh_config")
    @classmethod
    def _zenoh_readable(cls, value: Path | None) -> Path | None:
        if value is not None:
            try:
                load_config_file(value)
            except ZenohUnavailable as error:
                raise ValueError(str(error)) from None
        return value

    @field_validator("log_level")
    @classmethod
    def _known_level(cls, value: str) -> str:
        level = value.strip().lower()
        if level not in LOG_LEVELS:
            raise ValueError(f"must be one of {', '.join(LOG_LEVELS)}, got {value!r}")
        return level

    @field_validator("zenoh_listen", "zenoh_connect")
    @classmethod
    def _endpoints(cls, value: list[str]) -> list[str]:
        return [zenoh_endpoint(endpoint) for endpoint in value]

    @field_validator("zenoh_listen")
    @classmethod
    def _listens_somewhere(cls, value: list[str], info) -> list[str]:
        # With no endpoint Zenoh picks its own: a random port on every interface, exposing an
        # API without access control to the network, and one the cameras cannot know.
        if not value and info.data.get("zenoh_enabled") and info.data.get("zenoh_mode") == "peer":
            raise ValueError(
                'give at least one endpoint, e.g. ["tcp/127.0.0.1:7447"] (the default); '
                "VTRACK_ZENOH_ENABLED=false turns live streams off"
            )
        return value

    @field_validator(
        "retention_hours",
        "database_url",
        "dpm_model",
        "color_names",
        "models_dir",
        "cnn_model",
        "pose_model",
        "reid_model",
        "zenoh_tls_certificate",
        "zenoh_tls_private_key",
        "zenoh_tls_root_ca",
        "zenoh_users_file",
        "zenoh_user",
        mode="before",
    )
    @classmethod
    def _not_empty(cls, value: object, info) -> object:
        # An unset ${VAR} in a compose or unit file: say so, rather than "." is not a file or
        # that "" is no number, and do not take it as unset (the operator meant a value).
        if isinstance(value, str) and not value.strip():
            raise ValueError(f"is set but empty: unset it for {_WITHOUT[info.field_name]}")
        return value

    @field_validator("database_url")
    @classmethod
    def _postgres_url(cls, value: SecretStr | None) -> SecretStr | None:
        if value is not None and not value.get_secret_value().startswith(
            ("postgresql://", "postgres://")
        ):
            raise ValueError(
                "give a PostgreSQL URL, postgresql://user:password@host:5432/database, or unset "
                "it for the data folder's own SQLite database"
            )
        return value

    @field_validator("api_token")
    @classmethod
    def _token_given(cls, value: SecretStr | None) -> SecretStr | None:
        # An unset ${TOKEN} in a compose or unit file: no request could ever match it.
        if value is not None and not value.get_secret_value().strip():
            raise ValueError(
                "is set but empty, so no request could match it: unset it to serve without a "
                "token, or give the token clients send as 'Authorization: Bearer <token>'"
            )
        return value

    @model_validator(mode="after")
    def _zenoh_secure_or_said(self) -> Settings:
        # Each problem names its variables (load_settings passes such messages on as they are).
        if not self.zenoh_enabled:
            return self
        enforced = self.zenoh_security.enforced
        exposed = self.zenoh_exposed_endpoints
        if exposed and not enforced and not self.zenoh_allow_open:
            raise ValueError(
                f"VTRACK_ZENOH_LISTEN: {', '.join(exposed)} is beyond loopback, and without "
                "authentication anyone who reaches it can publish frames, read tracks and stop "
                "the tracking of a camera: give VTRACK_ZENOH_USERS_FILE or "
                "VTRACK_ZENOH_TLS_CLIENT_AUTH (docs/service.md, Security), listen on 127.0.0.1, "
                "or set VTRACK_ZENOH_ALLOW_OPEN=true to accept it"
            )
        return self

    @property
    def zenoh_security(self) -> ZenohSecurity:
        """TLS, credentials and access rules from the VTRACK_ZENOH_* settings (ValueError
        naming the variables for a combination that cannot work)."""
        password = self.zenoh_password.get_secret_value() if self.zenoh_password else None
        return build_security(
            prefix=self.zenoh_prefix,
            tls=TlsFiles(
                self.zenoh_tls_certificate,
                self.zenoh_tls_private_key,
                self.zenoh_tls_root_ca,
                self.zenoh_tls_client_auth,
            ),
            user=self.zenoh_user,
            password=password,
            users_file=self.zenoh_users_file,
            cameras=self.zenoh_cameras,
            readers=self.zenoh_readers,
            listen=self.zenoh_listen if self.zenoh_mode == "peer" else [],
        )

    @property
    def zenoh_exposed_endpoints(self) -> list[str]:
        """Listen endpoints beyond loopback (none when a Zenoh configuration file decides)."""
        if self.zenoh_config is not None or self.zenoh_mode != "peer":
            return []
        return [
            endpoint
            for endpoint in self.zenoh_listen
            if (address := endpoint_address(endpoint)) is not None and not is_loopback(address)
        ]

    @property
    def zenoh(self) -> ZenohOptions:
        return ZenohOptions(
            mode=self.zenoh_mode,
            listen=tuple(self.zenoh_listen),
            connect=tuple(self.zenoh_connect),
            config_file=self.zenoh_config,
            security=self.zenoh_security,
            # a sample this far over the frame limit is dropped by Zenoh before it is put
            # together in memory (smaller ones are counted as malformed by the stream)
            max_message_size=self.stream_frame_limit + MESSAGE_MARGIN,
        )

    def _network_path(self, setting: ModelSetting) -> Path | None:
        return model_setting_path(getattr(self, setting.field), self.models_dir, setting.default)

    @property
    def cnn_model_path(self) -> Path | None:
        """The CNN network file detectors 'cnn' and 'auto' run: VTRACK_CNN_MODEL as a model
        name in VTRACK_MODELS_DIR or as a path, else the default model in VTRACK_MODELS_DIR;
        None without either (it may not exist: see :attr:`cnn_model`)."""
        return self._network_path(CNN_SETTING)

    @property
    def pose_model_path(self) -> Path | None:
        """The body-keypoint network of tracker.pose, found as :attr:`cnn_model_path` is
        (VTRACK_POSE_MODEL, default human-pose-estimation-0001 of VTRACK_MODELS_DIR)."""
        return self._network_path(POSE_SETTING)

    @property
    def reid_model_path(self) -> Path | None:
        """The re-identification network of tracker.reid, found as :attr:`cnn_model_path` is
        (VTRACK_REID_MODEL, default person-reidentification-retail-0287 of
        VTRACK_MODELS_DIR)."""
        return self._network_path(REID_SETTING)

    @property
    def cnn_threads(self) -> int:
        """Inference threads per CNN: the setting, or every core (jobs side by side share them
        as the other detectors' threads do: measured faster than one thread each)."""
        return self.inference_threads or _default_workers()

    @property
    def streams_dir(self) -> Path:
        return self.data_dir / "streams"

    @property
    def database_path(self) -> Path:
        return self.data_dir / "jobs.sqlite3"

    @property
    def job_database(self) -> str | Path:
        """Where the jobs are: the PostgreSQL URL, or the data folder's SQLite file."""
        if self.database_url is not None:
            return self.database_url.get_secret_value()
        return self.database_path

    @property
    def instance(self) -> str:
        """This instance's name (VTRACK_INSTANCE_NAME, or host name and pid)."""
        return self.instance_name or f"{socket.gethostname()}-{os.getpid()}"


class InvalidSettings(ValueError):
    """Settings that cannot be used; ``problems`` holds one line per setting, each naming it as
    the user gave it."""

    def __init__(self, problems: list[str]) -> None:
        super().__init__("; ".join(problems))
        self.problems = problems


def load_settings(options: dict[str, Any] | None = None) -> Settings:
    """The settings from the environment with command-line ``options`` (field name -> value)
    over them. A ``VTRACK_*`` variable that is no setting is named on stderr
    (:func:`unknown_variables`) and ignored.

    Raises
    ------
    InvalidSettings
        A value of the wrong type or range, a model file that is not one, a list variable
        that is not JSON...: each problem names its option (``--port``) or variable
        (``VTRACK_PORT``).
    """
    options = options or {}
    for line in unknown_variables(os.environ):
        print(f"vtrack: {line}", file=sys.stderr)
    try:
        settings = Settings(**options)
    except ValidationError as error:
        raise InvalidSettings([_problem(item, options) for item in error.errors()]) from None
    except SettingsError as error:  # a list or object variable that is not JSON
        found = re.search(r'field "(\w+)"', str(error))
        name = f"VTRACK_{found.group(1).upper()}" if found else "a VTRACK_* variable"
        example = '["tcp/zenoh:7447"] or [{"camera": "gate"}]'
        problem = f"{name} is not valid JSON ({error.__cause__}); lists are JSON, e.g. {example}"
        raise InvalidSettings([problem]) from None
    return settings


KNOWN_EXTRA_VARIABLES = frozenset({"VTRACK_SHARED_DATA"})
"""``VTRACK_*`` variables that are not settings but are known: the tests' data folder."""


def unknown_variables(environ: Mapping[str, str]) -> list[str]:
    """A line for each ``VTRACK_*`` variable in ``environ`` that is no setting (a misspelt one
    would otherwise be ignored without a word), with the setting it may have meant."""
    known = {f"VTRACK_{name.upper()}" for name in Settings.model_fields}
    lines = []
    for name in sorted(environ):
        if name.startswith("VTRACK_") and name not in known | KNOWN_EXTRA_VARIABLES:
            # compared without the prefix, which every name shares
            close = difflib.get_close_matches(name[7:].lower(), Settings.model_fields, n=1)
            hint = f" (did you mean VTRACK_{close[0].upper()}?)" if close else ""
            lines.append(f"ignoring {name}: not a setting{hint}")
    return lines


def _problem(item: Any, options: Collection[str]) -> str:
    loc = item["loc"]
    if not loc:  # a check of several settings: its message names them
        return error_message(item)
    field = str(loc[0]) if loc else ""
    name = f"--{field.replace('_', '-')}" if field in options else f"VTRACK_{field.upper()}"
    # the place inside a list or object setting: VTRACK_STREAMS[0].camera
    name += "".join(f"[{part}]" if isinstance(part, int) else f".{part}" for part in loc[1:])
    return f"{name}: {error_message(item)}"
