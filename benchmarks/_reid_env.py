"""The separate virtual environment of the multi-object-tracking peers with a learned appearance
model (BoxMOT's Deep OC-SORT, StrongSORT and BoT-SORT with re-identification).

BoxMOT needs PyTorch and torchvision (its trackers hold tensors, and its ReID backends are
PyTorch models) and ``opencv-python`` 4, none of which may sit beside the project's packages:
``opencv-python``'s ``cv2`` would shadow the project's ``opencv-python-headless``, and PyTorch
is several gigabytes the product does not use. They therefore live in ``<repo>/.venv-reid``
(ignored by git, like every ``.venv*``), created once by :func:`ensure_reid_env` (with
:func:`_peer_env.ensure_env`) and reused while :data:`REID_REQUIREMENTS` stay the same.
``benchmarks/mot.py`` runs ``benchmarks/peers/reid_trackers.py`` with its interpreter.

No model weights are ever loaded there: ``benchmarks/mot.py`` computes the re-identification
embeddings with *our* network (``tracking.detection.reid``, OpenVINO) in its own process and
hands them to the trackers, which then never build their ReID backend (the peer script checks
that they did not).

Pins (Python 3.11), the versions the benchmark was verified with: BoxMOT 25.0.0 and the
numerical libraries whose versions could move the figures. ``torch==2.14.1`` with
``torchvision==0.29.1``: a pair pip takes from this machine's disk (torchvision from PyPI does
not import beside the CPU-only ``torch==2.13.0`` wheel also there); the environment is about
5.5 GB.
"""

from __future__ import annotations

from pathlib import Path

try:  # run as a script: benchmarks/ is on sys.path
    from _paths import REPO_ROOT
    from _peer_env import PeerEnvError, ensure_env
except ImportError:  # python -m benchmarks.mot from the repository root
    from benchmarks._paths import REPO_ROOT
    from benchmarks._peer_env import PeerEnvError, ensure_env

__all__ = ["DEFAULT_REID_ENV", "REID_REQUIREMENTS", "PeerEnvError", "ensure_reid_env"]

DEFAULT_REID_ENV = REPO_ROOT / ".venv-reid"

REID_REQUIREMENTS = [
    "boxmot==25.0.0",
    "torch==2.14.1",
    "torchvision==0.29.1",
    "numpy==2.4.6",
    "scipy==1.17.1",
    "opencv-python==4.14.0.94",
    "lapx==0.11.1",
    "filterpy==1.4.5",
]

_CHECK_SNIPPET = (
    "import boxmot, torch; from boxmot import create_tracker; "
    "from boxmot.trackers.specs import TrackerSpec; "
    "from boxmot.structures import Boxes, Detections; "
    "boxmot.DeepOcSort; boxmot.StrongSort; boxmot.BotSort"
)


def ensure_reid_env(env_dir: Path = DEFAULT_REID_ENV) -> Path:
    """Create the environment of the re-identification peers if needed; return its interpreter.

    Raises
    ------
    PeerEnvError
        If the environment cannot be created or pip cannot install :data:`REID_REQUIREMENTS`;
        the message carries pip's last lines.
    """
    return ensure_env(env_dir, REID_REQUIREMENTS, _CHECK_SNIPPET, "the re-id peer environment")
