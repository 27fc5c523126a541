"""The settings that name a network (``VTRACK_CNN_MODEL``, ``VTRACK_POSE_MODEL``,
``VTRACK_REID_MODEL``), resolved to a file and checked the same way by ``vtrack serve`` (the
service's settings) and ``vtrack analyze`` (its flags and the same variables).

Each is a model name of the models folder (``VTRACK_MODELS_DIR``) or the path of an OpenVINO
``.xml`` (with its ``.bin``) or an ``.onnx`` file; unset, its task's default model of the folder.
A network named explicitly must be there and load; a default model missing from the folder is no
error (what needs it runs without it, and says so where that matters).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from service.models.catalog import (
    CATALOG,
    DEFAULT_DETECTOR,
    DEFAULT_POSE,
    DEFAULT_REID,
    Task,
    model_path,
)

__all__ = [
    "CNN_SETTING",
    "MODEL_SETTINGS",
    "POSE_SETTING",
    "REID_SETTING",
    "ModelSetting",
    "check_model_setting",
    "load_model",
    "model_setting_path",
]

MODEL_FILE_SUFFIXES = (".xml", ".onnx")
"""What a value with one of these suffixes names: a file (anything else: a model name). The
runtime's ``MODEL_SUFFIXES``, repeated here so that reading the settings imports no OpenVINO."""


@dataclass(frozen=True, slots=True)
class ModelSetting:
    """A setting that names a network.

    Attributes
    ----------
    field:
        The settings field (``pose_model``); the variable is ``VTRACK_<FIELD>``.
    task:
        The catalog task of the models it may name.
    default:
        The catalog model of the models folder used when it is unset.
    what:
        What the network is, for messages (``a pose``: "needs a pose model").
    """

    field: str
    task: Task
    default: str
    what: str

    @property
    def variable(self) -> str:
        return f"VTRACK_{self.field.upper()}"

    @property
    def catalog_names(self) -> tuple[str, ...]:
        """The catalog's models of this setting's task."""
        return tuple(name for name, model in CATALOG.items() if model.task == self.task)


CNN_SETTING = ModelSetting("cnn_model", "person-detection", DEFAULT_DETECTOR, "a CNN person")
POSE_SETTING = ModelSetting("pose_model", "pose", DEFAULT_POSE, "a pose")
REID_SETTING = ModelSetting("reid_model", "reidentification", DEFAULT_REID, "a re-identification")
MODEL_SETTINGS = (CNN_SETTING, POSE_SETTING, REID_SETTING)


def model_setting_path(value: str | None, models_dir: Path | None, default: str) -> Path | None:
    """The network file a setting's ``value`` names: a path (an ``.xml`` or ``.onnx``) as it
    is, a catalog name in ``models_dir``, unset the ``default`` model of ``models_dir``. None
    without a models folder, or for a value that is neither (it need not exist: see
    :func:`check_model_setting`)."""
    if value is not None and Path(value).suffix.lower() in MODEL_FILE_SUFFIXES:
        return Path(value)
    if models_dir is None:
        return None
    if value is not None and value not in CATALOG:
        return None
    return model_path(models_dir, value or default)


def load_model(path: Path, task: Task, threads: int = 0) -> object:
    """The network at ``path`` loaded as the part of the tracker that runs it (the detector,
    the pose estimator, the re-identification embedder).

    Raises
    ------
    CnnModelError
        (a ValueError) What is wrong with the file: missing, not a model, not one of ``task``.
    """
    if task == "pose":
        from tracking.detection.pose import PoseConfig, PoseEstimator

        return PoseEstimator.from_file(path, PoseConfig(threads=threads))
    if task == "reidentification":
        from tracking.detection.reid import ReidConfig, ReidEmbedder

        return ReidEmbedder.from_file(path, ReidConfig(threads=threads))
    from tracking.detection.cnn import CnnConfig, CnnDetector

    return CnnDetector.from_file(path, CnnConfig(threads=threads))


def check_model_setting(
    setting: ModelSetting, value: str | None, models_dir: Path | None, origin: str | None = None
) -> Path | None:
    """The file of ``setting`` set to ``value`` (None: unset), loaded once if it is there to
    check that it is such a network.

    ``origin`` names where ``value`` came from in messages (a flag: ``--pose-model``); by
    default the setting's variable. A value that names no file, or a file that is missing or is
    not the setting's kind of network, raises; so does the default model of ``models_dir`` when
    it is there but is not a network (named as VTRACK_MODELS_DIR's).

    Raises
    ------
    ValueError
        Each message names ``origin`` (or VTRACK_MODELS_DIR) and says why and what to do.
    """
    origin = origin or setting.variable
    path = model_setting_path(value, models_dir, setting.default)
    if value is not None:
        known = ", ".join(setting.catalog_names)
        if value in CATALOG and CATALOG[value].task != setting.task:
            raise ValueError(
                f"{origin} {value!r} is a {CATALOG[value].task} model: it takes {setting.what} "
                f"model ({known}) or the path of an .xml or .onnx file"
            )
        if path is None and value in CATALOG:
            raise ValueError(
                f"{origin} {value!r} names a model of the models folder, and VTRACK_MODELS_DIR "
                f"is not set: `vtrack models fetch {value} --dir DIR` fills one, then set "
                "VTRACK_MODELS_DIR=DIR"
            )
        if path is None:
            raise ValueError(
                f"{origin} {value!r} is neither a model of VTRACK_MODELS_DIR ({known}) nor an "
                ".xml or .onnx file: `vtrack models fetch` downloads the models"
            )
        if not path.is_file():
            remedy = (
                f"`vtrack models fetch {value} --dir {models_dir}` downloads it"
                if value in CATALOG
                else "give the path of an existing .xml (with its .bin) or .onnx file"
            )
            raise ValueError(f"{origin} {value!r}: {path} is not a file: {remedy}")
    if path is None or not path.is_file():
        return path  # the default model, not fetched: what needs it runs without it
    try:
        load_model(path, setting.task)
    except ValueError as error:  # CnnModelError: what is wrong with the file
        where = origin if value is not None else "VTRACK_MODELS_DIR"
        fetched = value is None or value in CATALOG
        again = "; `vtrack models fetch` downloads it again" if fetched else ""
        raise ValueError(f"{where}: {error}{again}") from None
    return path
