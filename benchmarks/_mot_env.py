"""The separate virtual environment of the multi-object-tracking peers and of TrackEval.

Roboflow's ``trackers`` (SORT, ByteTrack, OC-SORT, BoT-SORT on ``supervision.Detections``) and
``trackeval`` (HOTA, CLEAR MOT, identity metrics; the PyPI release of Luiten's TrackEval) both
require ``opencv-python``, whose ``cv2`` (OpenCV 5) would shadow the project's
``opencv-python-headless`` 4.x, which keeps the HOG people detector. They therefore live in
``<repo>/.venv-mot`` (ignored by git, like every ``.venv*``), created once by
:func:`ensure_mot_env` and reused while :data:`MOT_REQUIREMENTS` stay the same.
``benchmarks/mot.py`` runs ``benchmarks/peers/mot_trackers.py`` and
``benchmarks/peers/trackeval_score.py`` with its interpreter.

The pins are the versions the benchmark was verified with (Python 3.11): the trackers and the
evaluator exactly, and the numerical libraries whose versions could move the figures.
"""

from __future__ import annotations

from pathlib import Path

try:  # run as a script: benchmarks/ is on sys.path
    from _paths import REPO_ROOT
    from _peer_env import PeerEnvError, ensure_env
except ImportError:  # python -m benchmarks.mot from the repository root
    from benchmarks._paths import REPO_ROOT
    from benchmarks._peer_env import PeerEnvError, ensure_env

__all__ = ["DEFAULT_MOT_ENV", "MOT_REQUIREMENTS", "PeerEnvError", "ensure_mot_env"]

DEFAULT_MOT_ENV = REPO_ROOT / ".venv-mot"

MOT_REQUIREMENTS = [
    "trackers==2.6.1",
    "supervision==0.31.2",
    "trackeval==1.3.0",
    "opencv-python==5.0.0.93",
    "numpy==2.4.6",
    "scipy==1.17.1",
]

_CHECK_SNIPPET = (
    "import trackers, supervision, trackeval; "
    "trackers.SORTTracker; trackers.ByteTrackTracker; trackers.OCSORTTracker; "
    "trackers.BoTSORTTracker; trackeval.datasets.MotChallenge2DBox; trackeval.metrics.HOTA"
)


def ensure_mot_env(env_dir: Path = DEFAULT_MOT_ENV) -> Path:
    """Create the environment of the MOT peers and TrackEval if needed; return its interpreter.

    Raises
    ------
    PeerEnvError
        If the environment cannot be created or pip cannot install :data:`MOT_REQUIREMENTS`
        (for example without network access); the message carries pip's last lines.
    """
    return ensure_env(env_dir, MOT_REQUIREMENTS, _CHECK_SNIPPET, "the MOT peer environment")
