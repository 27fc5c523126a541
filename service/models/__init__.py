"""The CNN model files the service can use: a catalog of Intel Open Model Zoo models
(:mod:`.catalog`) and their verified download (:mod:`.fetch`, ``vtrack models fetch``).

Only the command line and the Docker build download; the runtime (``tracking/``) takes a models
folder from its settings and never imports this package.
"""

from service.models.catalog import (
    CATALOG,
    DEFAULT_DETECTOR,
    DEFAULT_MODELS,
    DEFAULT_POSE,
    DEFAULT_REID,
    OMZ_HUMAN_RIGHTS_NOTICE,
    OMZ_LICENCE,
    CatalogModel,
    ModelFile,
    UnknownModelError,
    check_name,
    model_path,
)
from service.models.fetch import (
    FetchResult,
    ModelFetchError,
    fetch_models,
    file_state,
    mirror_base,
    model_state,
    source_url,
)

__all__ = [
    "CATALOG",
    "DEFAULT_DETECTOR",
    "DEFAULT_MODELS",
    "DEFAULT_POSE",
    "DEFAULT_REID",
    "OMZ_HUMAN_RIGHTS_NOTICE",
    "OMZ_LICENCE",
    "CatalogModel",
    "FetchResult",
    "ModelFetchError",
    "ModelFile",
    "UnknownModelError",
    "check_name",
    "fetch_models",
    "file_state",
    "mirror_base",
    "model_path",
    "model_state",
    "source_url",
]
