"""One log format for every line the service writes: time, level, source, message.

Worker processes add ``worker[pid]`` or ``stream[camera]`` before the source
(:mod:`service.jobs.runner`, :mod:`service.streams.worker`).
"""

from __future__ import annotations

import os
from typing import Any

LOG_FORMAT = "%(asctime)s %(levelname)s %(name)s: %(message)s"


def quiet_ffmpeg(level: str) -> None:
    """Keep OpenCV's FFmpeg out of the log unless its level is ``debug``.

    OpenCV's FFmpeg writes its decoder's complaints (``[h264 @ 0x...] error while decoding
    MB``) straight to stderr: outside the log's format and level, without a job id, and in
    the middle of the lines of other jobs. What they mean for a job (frames that did not
    decode, a video that ended early) the job's warnings say. At ``debug`` FFmpeg's errors
    stay, prefixed ``[OPENCV:FFMPEG:16]``. An ``OPENCV_FFMPEG_LOGLEVEL`` of the operator's own
    wins. OpenCV reads the variable when a process first opens a video, and worker
    processes inherit it: call before they start.
    """
    os.environ.setdefault("OPENCV_FFMPEG_LOGLEVEL", "16" if level == "debug" else "-8")


def uvicorn_log_config(level: str) -> dict[str, Any]:
    """A ``logging.config.dictConfig`` for uvicorn: its own lines (start-up, errors, each
    request) and the service's in :data:`LOG_FORMAT`, where uvicorn's default has no time."""
    return {
        "version": 1,
        "disable_existing_loggers": False,
        "formatters": {
            "default": {"format": LOG_FORMAT},
            "access": {
                "()": "uvicorn.logging.AccessFormatter",
                "fmt": '%(asctime)s %(levelname)s %(name)s: %(client_addr)s - "%(request_line)s" '
                "%(status_code)s",
                "use_colors": False,
            },
        },
        "handlers": {
            "default": {
                "formatter": "default",
                "class": "logging.StreamHandler",
                "stream": "ext://sys.stderr",
            },
            "access": {
                "formatter": "access",
                "class": "logging.StreamHandler",
                "stream": "ext://sys.stdout",
            },
        },
        "root": {"handlers": ["default"], "level": level.upper()},
        "loggers": {
            "uvicorn": {"handlers": ["default"], "level": level.upper(), "propagate": False},
            "uvicorn.access": {"handlers": ["access"], "level": "INFO", "propagate": False},
        },
    }
