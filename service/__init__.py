"""The tracking service: HTTP API, job workers, live streams and the ``vtrack`` command line."""

import importlib.metadata

try:
    __version__ = importlib.metadata.version("visual-tracking")
except importlib.metadata.PackageNotFoundError:  # run from a checkout without installing
    __version__ = "0+unknown"
