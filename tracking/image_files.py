"""Image files read by their bytes, whatever their names."""

from __future__ import annotations

import os

import cv2
import numpy as np


def read_rgb(path: str | os.PathLike[str]) -> np.ndarray | None:
    """The image file ``path`` as RGB uint8 ``(H, W, 3)``; ``None`` when it is missing or not
    an image OpenCV decodes.

    Read by Python and decoded from memory: ``cv2.imread`` takes the name as UTF-8, so a name
    that is not (a file named on a Latin-1 system, a non-ASCII name under a Latin-1 locale)
    was a missing file, or crashed the process.
    """
    try:
        data = np.fromfile(path, dtype=np.uint8)
    except OSError:
        return None
    bgr = cv2.imdecode(data, cv2.IMREAD_COLOR) if data.size else None
    return None if bgr is None else cv2.cvtColor(bgr, cv2.COLOR_BGR2RGB)
