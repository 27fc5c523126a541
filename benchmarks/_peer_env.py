"""The separate virtual environment the OpenCV peer trackers run in.

OpenCV's KCF and CSRT live in ``opencv-contrib-python-headless``, which cannot be installed next
to the project's ``opencv-python-headless`` (both provide the ``cv2`` package). The benchmark
therefore keeps a second environment at ``<repo>/.venv-peers`` with the contrib build of exactly
the OpenCV version installed here, and runs ``benchmarks/peers/opencv_trackers.py`` with its
interpreter. The environment is created once and reused while its requirements stay the same.

:func:`ensure_env` does the same for any pinned set of requirements (``benchmarks/_mot_env.py``
builds the environment of the multi-object-tracking peers and TrackEval with it).
"""

from __future__ import annotations

import importlib.metadata
import json
import logging
import os
import subprocess
import sys
from pathlib import Path

try:  # run as a script: benchmarks/ is on sys.path
    from _paths import REPO_ROOT
except ImportError:  # python -m benchmarks.<name> from the repository root
    from benchmarks._paths import REPO_ROOT

logger = logging.getLogger(__name__)

DEFAULT_PEER_ENV = REPO_ROOT / ".venv-peers"
MARKER_FILE = "vtrack-peer-env.json"
PIP_TIMEOUT_SECONDS = 900.0

_CHECK_SNIPPET = (
    "import cv2, numpy; cv2.TrackerKCF.create; cv2.TrackerCSRT.create; print(cv2.__version__)"
)


class PeerEnvError(RuntimeError):
    """The peer environment could not be created or does not work."""


def peer_requirements() -> list[str]:
    """Pinned requirements: the contrib build of this environment's OpenCV, and its NumPy.

    Raises
    ------
    PeerEnvError
        If ``opencv-python-headless`` is not installed in the running environment.
    """
    try:
        opencv = importlib.metadata.version("opencv-python-headless")
    except importlib.metadata.PackageNotFoundError as exc:
        raise PeerEnvError(
            "opencv-python-headless is not installed here, so the OpenCV version to pin for the "
            "peer environment is unknown"
        ) from exc
    numpy = importlib.metadata.version("numpy")
    return [f"opencv-contrib-python-headless=={opencv}", f"numpy=={numpy}"]


def env_python(env_dir: Path) -> Path:
    """The interpreter of the virtual environment at ``env_dir``."""
    if os.name == "nt":
        return env_dir / "Scripts" / "python.exe"
    return env_dir / "bin" / "python"


def _run(command: list[str], timeout: float) -> subprocess.CompletedProcess[str]:
    return subprocess.run(command, capture_output=True, text=True, timeout=timeout, check=False)


def _works(python: Path, check_snippet: str = _CHECK_SNIPPET) -> bool:
    if not python.is_file():
        return False
    try:
        return _run([str(python), "-c", check_snippet], timeout=120.0).returncode == 0
    except (OSError, subprocess.TimeoutExpired):
        return False


def _tail(text: str, lines: int = 15) -> str:
    return "\n".join(text.strip().splitlines()[-lines:])


def ensure_env(env_dir: Path, requirements: list[str], check_snippet: str, purpose: str) -> Path:
    """Create the virtual environment at ``env_dir`` if needed and return its interpreter.

    An existing environment is reused when its marker file lists the same ``requirements`` and
    its interpreter runs ``check_snippet``; otherwise it is rebuilt (``venv --clear``, with this
    interpreter's Python) and the requirements are installed with pip. A folder that is not
    empty and holds no marker file is not an environment this function made, and is refused.

    Parameters
    ----------
    env_dir:
        Folder of the environment (``<repo>/.venv-*``, ignored by git).
    requirements:
        Pinned pip requirements, e.g. ``["trackers==2.6.1"]``.
    check_snippet:
        Python code that exits with 0 only when the environment works.
    purpose:
        What the environment is for, in messages ("the peer environment").

    Raises
    ------
    PeerEnvError
        If the environment cannot be created or pip cannot install the requirements (for
        example without network access; the message carries pip's last lines), or if
        ``env_dir`` holds something else.
    """
    python = env_python(env_dir)
    marker = env_dir / MARKER_FILE
    try:
        recorded = json.loads(marker.read_text())
    except (OSError, ValueError):
        recorded = None
    if recorded == {"requirements": requirements} and _works(python, check_snippet):
        return python

    # venv --clear empties the folder: only one this function made (it holds the marker,
    # written before pip runs) or an empty one, never e.g. the project's own .venv
    if not marker.is_file() and env_dir.exists() and any(env_dir.iterdir()):
        raise PeerEnvError(
            f"{env_dir} is not empty and is not {purpose} made by the benchmarks (no "
            f"{MARKER_FILE} in it); it is left alone: remove it or choose another folder"
        )
    logger.info("creating %s %s with %s", purpose, env_dir, " ".join(requirements))
    try:
        created = _run([sys.executable, "-m", "venv", "--clear", str(env_dir)], timeout=300.0)
        if created.returncode != 0:
            raise PeerEnvError(
                f"could not create a virtual environment at {env_dir}:\n{_tail(created.stderr)}"
            )
        marker.write_text(json.dumps({"creating": requirements}))
        installed = _run(
            [
                str(python),
                "-m",
                "pip",
                "install",
                "--disable-pip-version-check",
                "--no-input",
                "--quiet",
                *requirements,
            ],
            timeout=PIP_TIMEOUT_SECONDS,
        )
    except subprocess.TimeoutExpired as exc:
        raise PeerEnvError(f"creating {purpose} took over {exc.timeout:.0f} s") from exc
    except OSError as exc:
        raise PeerEnvError(f"could not run {exc.filename}: {exc.strerror}") from exc
    if installed.returncode != 0:
        raise PeerEnvError(
            f"pip could not install {' '.join(requirements)} into {env_dir} (no network, or no "
            f"wheel for this platform?):\n{_tail(installed.stderr or installed.stdout)}"
        )
    if not _works(python, check_snippet):
        raise PeerEnvError(f"{purpose} at {env_dir} does not pass its check: {check_snippet}")
    marker.write_text(json.dumps({"requirements": requirements}))
    return python


def ensure_peer_env(env_dir: Path = DEFAULT_PEER_ENV) -> Path:
    """Create the OpenCV peer environment if needed and return its Python interpreter.

    An existing environment is reused when its marker file lists the same requirements and it
    imports ``cv2`` with KCF and CSRT; otherwise it is rebuilt (see :func:`ensure_env`).

    Raises
    ------
    PeerEnvError
        If the environment cannot be created or pip cannot install the requirements (for
        example without network access); the message carries pip's last lines.
    """
    return ensure_env(env_dir, peer_requirements(), _CHECK_SNIPPET, "the peer environment")
