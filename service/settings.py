"""Service settings, read from ``VTRACK_*`` environment variables (documented in the README)."""

from __future__ import annotations

import os
from pathlib import Path

from pydantic import Field, SecretStr, field_validator
from pydantic_settings import BaseSettings, SettingsConfigDict


def _default_workers() -> int:
    return max(1, len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else 1)


class Settings(BaseSettings):
    """Everything the service reads from its environment; tests build one directly."""

    model_config = SettingsConfigDict(env_prefix="VTRACK_", extra="ignore")

    data_dir: Path = Field(
        default=Path("vtrack-data"),
        description="Folder of the job database (jobs.sqlite3), uploads and results.",
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
    job_timeout: float = Field(
        default=4 * 3600.0, gt=0, description="Seconds a job may run before it is failed."
    )
    max_attempts: int = Field(
        default=3,
        ge=1,
        description="Times a job is started (again after a service restart) before it is failed.",
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
    poll_interval: float = Field(
        default=0.2, gt=0, le=5, description="Seconds an idle worker waits between job checks."
    )
    log_level: str = Field(default="info", description="Logging level of the service.")

    @field_validator("dpm_model", "color_names")
    @classmethod
    def _existing_file(cls, value: Path | None, info) -> Path | None:
        if value is not None and not value.is_file():
            variable = f"VTRACK_{info.field_name.upper()}"
            raise ValueError(f"{variable} names {value}, which is not a file")
        return value

    @property
    def database_path(self) -> Path:
        return self.data_dir / "jobs.sqlite3"

    @property
    def uploads_dir(self) -> Path:
        return self.data_dir / "uploads"

    @property
    def results_dir(self) -> Path:
        return self.data_dir / "results"
