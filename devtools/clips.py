"""Short clips of a video, for the tests' and the service benchmarks' jobs."""

from __future__ import annotations

from pathlib import Path

import cv2


def cut_video(source: Path, target: Path, frames: int, start: int = 0) -> Path:
    """``frames`` frames of ``source`` from frame ``start`` as an MJPG AVI at its rate: every
    frame a key frame, so that a job's time is the tracking's."""
    capture = cv2.VideoCapture(str(source))
    fps = capture.get(cv2.CAP_PROP_FPS) or 10.0
    writer = None
    try:
        for index in range(start + frames):
            ok, frame = capture.read()
            if not ok:
                raise RuntimeError(f"{source} has fewer than {start + frames} frames")
            if index < start:
                continue
            if writer is None:
                size = (frame.shape[1], frame.shape[0])
                writer = cv2.VideoWriter(str(target), cv2.VideoWriter_fourcc(*"MJPG"), fps, size)
            writer.write(frame)
    finally:
        capture.release()
        if writer is not None:
            writer.release()
    return target
