"""The probes' answers: ``/healthz`` (the process answers) and ``/readyz`` (it can take jobs)."""

from __future__ import annotations

from typing import Literal

from pydantic import BaseModel, Field

from api_schemas.jobs import JobState
from api_schemas.streams import StreamState


class Health(BaseModel):
    """``GET /healthz``: the process answers."""

    status: Literal["ok"]


class DefaultDetector(BaseModel):
    """What a job's detector 'auto' runs now (a models folder can be filled while it runs)."""

    name: str = Field(description="'cnn' when the service has a CNN model, else 'default'.")
    model: str | None = Field(description="The CNN's model; null for the embedded detector.")
    warning: str | None = Field(
        description="What jobs lose with it, and how to install the CNN's model; null with it."
    )


class NetworkModel(BaseModel):
    """A network the service has the model of."""

    model: str


class Readiness(BaseModel):
    """``GET /readyz``: whether the service can take jobs (200) or not yet (503), and what it
    runs. Open without the token, for orchestrators and load balancers."""

    status: Literal["ready", "starting", "unwritable", "full"] = Field(
        description="'ready' (200); 'starting': no worker process is ready yet; 'unwritable': "
        "the data folder cannot be written; 'full': its disk has less free space than "
        "VTRACK_MIN_FREE_MB."
    )
    instance: str = Field(
        description="This instance's name (VTRACK_INSTANCE_NAME): instances that share a job "
        "database (VTRACK_DATABASE_URL) answer for the same jobs."
    )
    jobs_here: int = Field(
        ge=0,
        description="Running jobs this instance's workers run (of jobs.running, which "
        "counts every instance's on a shared database).",
    )
    workers: int = Field(ge=0, description="Job worker processes configured.")
    workers_ready: int = Field(ge=0, description="Job worker processes ready for a job.")
    jobs: dict[JobState, int] = Field(description="Jobs per state.")
    streams: dict[StreamState, int] = Field(description="Live streams per state (states held).")
    zenoh: str = Field(description="'ok', or why live streams are unavailable.")
    detector: DefaultDetector
    pose: NetworkModel | None = Field(
        description="The pose network people jobs run unless they say otherwise; null: none."
    )
    reid: NetworkModel | None = Field(
        description="The re-identification network people jobs run unless they say otherwise; "
        "null: none."
    )
    detail: str | None = Field(
        default=None, description="Unless ready: why, and what to do (absent when ready)."
    )
