"""Reading the MATLAB files users bring: voc-release5 DPM models and the Color Names table."""

from __future__ import annotations

import os
from typing import Any

__all__ = ["read_mat"]


def read_mat(path: str | os.PathLike[str], **options: Any) -> dict[str, Any]:
    """``scipy.io.loadmat(path, **options)``, with every failure as a ``ValueError`` that says why.

    MATLAB's ``-v7.3`` files are HDF5, which scipy does not read; their message says how to save
    the file again in a format it does.
    """
    import scipy.io  # local: keeps the importers light

    try:
        return scipy.io.loadmat(os.fspath(path), **options)
    except NotImplementedError as error:  # scipy's word for a v7.3 file
        raise ValueError(
            "it is a MATLAB v7.3 (HDF5) file, which this loader does not read: save it again in "
            "the v7 format (MATLAB: save(file, name, '-v7'); Octave: save -v7 file name)"
        ) from error
    except Exception as error:  # scipy raises assorted types on corrupt or foreign files
        raise ValueError(f"it is not a readable MATLAB v5/v7 file ({error})") from error
