"""The Intel Open Model Zoo (OMZ) models the project knows: their files, sizes, checksums and
official download addresses, so that ``vtrack models fetch`` can get them on purpose and check
every byte (the runtime never downloads; it loads files from a models folder).

A models folder has OMZ's own layout, ``<model>/<precision>/<model>.{xml,bin}``: OMZ's
downloader (``omz_downloader -o DIR``) writes the same under ``DIR/intel/``, which is then a
models folder too.

Where the facts come from: each entry's sizes, checksums and URLs are copied from
``models/intel/<model>/model.yml`` of the OMZ repository (github.com/openvinotoolkit/
open_model_zoo) at the release named beside it, chosen as the release whose files are those the
project measured (the copies of ``../shared/data/models``, sha256 compared). The tag 2021.2 lists
its files at ``storage.openvinotoolkit.org``; the repository's ``release-01org`` branch (commit
1808ec5c) lists the same files at ``download.01.org/opencv/2021/openvinotoolkit/2021.2/...``.
Releases from 2022.1 on give a sha384 ``checksum`` instead of a sha256: for the entries taken
from them, the sha256 below is that of a copy whose sha384 equals OMZ's (kept as ``sha384``).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from types import MappingProxyType
from typing import Literal

__all__ = [
    "CATALOG",
    "DEFAULT_DETECTOR",
    "DEFAULT_MODELS",
    "DEFAULT_POSE",
    "DEFAULT_REID",
    "OMZ_HUMAN_RIGHTS_NOTICE",
    "OMZ_LICENCE",
    "CatalogModel",
    "ModelFile",
    "Task",
    "UnknownModelError",
    "check_name",
    "model_path",
]

OMZ_LICENCE = "Apache-2.0"
"""The licence of Open Model Zoo and its Intel models (OMZ's README: "Open Model Zoo is licensed
under Apache License Version 2.0")."""

OMZ_HUMAN_RIGHTS_NOTICE = (
    "Intel is committed to the respect of human rights and avoiding complicity in human rights "
    "abuses, a policy reflected in the Intel Global Human Rights Principles. Accordingly, by "
    "accessing the Intel material on this platform you agree that you will not use the material "
    "in a product or application that causes or contributes to a violation of an internationally "
    "recognized human right."
)
"""The condition OMZ's README (github.com/openvinotoolkit/open_model_zoo, README.md, since
commit b1e5e456 "update legal notice", 2021-04-30, unchanged since) puts on its Intel
material, word for word but for the link on "Intel Global Human Rights Principles"
(https://www.intel.com/content/www/us/en/policy/policy-human-rights.html). It binds whoever
builds on these models, a surveillance product included: ``vtrack models fetch`` prints it and
the docs quote it."""

Task = Literal["person-detection", "pose", "reidentification"]


@dataclass(frozen=True, slots=True)
class ModelFile:
    """One file of a model, as OMZ's model.yml describes it.

    Attributes
    ----------
    path:
        Relative to a models folder, with ``/``: ``<model>/<precision>/<file>``.
    size:
        Bytes.
    sha256:
        Hex digest the downloaded bytes must have.
    url:
        OMZ's official storage address of the file.
    sha384:
        OMZ's own checksum where the entry comes from a release that gives sha384 rather than
        sha256 (2022.1 on), checked too; ``None`` otherwise.
    """

    path: str
    size: int
    sha256: str
    url: str
    sha384: str | None = None

    @property
    def name(self) -> str:
        """The file name, without its folders."""
        return self.path.rpartition("/")[2]


@dataclass(frozen=True, slots=True)
class CatalogModel:
    """A model of the catalog: its OMZ name, what it is for and its files (graph and weights)."""

    name: str
    task: Task
    description: str
    files: tuple[ModelFile, ...]

    @property
    def graph(self) -> str:
        """The ``.xml`` (OpenVINO IR graph) relative to a models folder: the file runtime
        options name; its ``.bin`` weights sit beside it."""
        (graph,) = (f.path for f in self.files if f.path.endswith(".xml"))
        return graph

    @property
    def size(self) -> int:
        """Bytes of all its files."""
        return sum(f.size for f in self.files)


_STORAGE = "https://storage.openvinotoolkit.org/repositories/open_model_zoo"


def _ir(
    name: str,
    precision: str,
    storage: str,
    xml: tuple[int, str],
    bin_: tuple[int, str],
    sha384: tuple[str, str] | None = None,
) -> tuple[ModelFile, ...]:
    """The ``.xml`` and ``.bin`` of an OMZ IR model, ``storage`` being the release's
    ``<release>/models_bin/<n>`` folder, (size, sha256) of each, and OMZ's sha384 if given."""
    folder = f"{name}/{precision}/{name}"
    return tuple(
        ModelFile(
            f"{folder}.{suffix}",
            size,
            sha256,
            f"{_STORAGE}/{storage}/{folder}.{suffix}",
            sha384[index] if sha384 else None,
        )
        for index, (suffix, (size, sha256)) in enumerate((("xml", xml), ("bin", bin_)))
    )


_MODELS = (
    # OMZ 2021.2 (tag 2021.2, models_bin/3): both files equal the measured copies
    CatalogModel(
        "person-detection-0202",
        "person-detection",
        "MobileNetV2-SSD person detector with two heads and clustered priors, 512x512 input "
        "(reshapeable to the frame's aspect); the default",
        _ir(
            "person-detection-0202",
            "FP16",
            "2021.2/models_bin/3",
            (188084, "649213976ea433d338752235944c96ce67809d175860b6814778847192497501"),
            (3634626, "c82526a14d4c3c2d4c04e06e1173f573374fb5a2a97393b926f96adbff7b345b"),
        ),
    ),
    # OMZ 2021.2 (tag 2021.2, models_bin/3): both files equal the measured copies
    CatalogModel(
        "person-detection-0200",
        "person-detection",
        "the same network at 256x256: faster, weaker on small people",
        _ir(
            "person-detection-0200",
            "FP16",
            "2021.2/models_bin/3",
            (187812, "b7c7c743a8062220511af588142efb74194014370d59cbf62ede84d772ccb684"),
            (3634626, "aba627cdd9c6576cf6e7442191b9663811d327f2ea0ffe113fb77ba07c124b58"),
        ),
    ),
    # OMZ 2021.2 (tag 2021.2, models_bin/3): both files equal the measured copies (later
    # releases converted it again: 2022.1 lists a 1,445,734-byte .bin)
    CatalogModel(
        "person-detection-retail-0013",
        "person-detection",
        "retail person detector (RMNet with lrelu + SSD), 320x544 input",
        _ir(
            "person-detection-retail-0013",
            "FP16",
            "2021.2/models_bin/3",
            (358248, "a1d2d3fbd200bb73813d35158a303d28b71178b9c3331a9f2edb411404a6cffe"),
            (1445736, "56eeccbeb3f27144046edacb95b459d60f3930f54051ef5b9e5253923c07b672"),
        ),
    ),
    # OMZ 2021.4 (tags 2021.4 to 2021.4.2, models_bin/3): both files equal the measured copies.
    # FP16-INT8 is the precision those copies have; OMZ dropped it for this model in 2022.3.
    CatalogModel(
        "human-pose-estimation-0001",
        "pose",
        "multi-person 2D pose, OpenPose-style (18 keypoints grouped with part affinity fields), "
        "256x456 input (reshapeable)",
        _ir(
            "human-pose-estimation-0001",
            "FP16-INT8",
            "2021.4/models_bin/3",
            (426156, "581b082e749848fdfc6d4b4b70e8189c3c2bae1c2d59c6b2c1a026a5471754e3"),
            (4170034, "df2a9f41f15c3a0c8a0c5a704650338a3cc5c7bb588f2bfc14ea7093fa37b446"),
        ),
    ),
    # The re-identification models: OMZ 2023.0 (tag 2023.0.0, models_bin/1; unchanged to
    # 2024.6, the newest). No model.yml with a sha256 lists these files (2021.x's are older
    # conversions of other sizes); their sha384 in 2023.0's model.yml equals that of the measured
    # copies, whose sha256 these are.
    CatalogModel(
        "person-reidentification-retail-0277",
        "reidentification",
        "person re-identification embedding (OSNet family), 256x128 crop to 256 values; "
        "the most accurate and slowest of the three",
        _ir(
            "person-reidentification-retail-0277",
            "FP16",
            "2023.0/models_bin/1",
            (616140, "82039b1bb986231c50345550e59def94e63579998e9cddbd1a312f293eb87729"),
            (4178806, "6bb69e09d07733cc3896b29081d2627f92db7b9aacd50f1a8c3df491cb10f1b7"),
            (
                "554b403108fea776cb54c971c4c8acfaaeaae3884b5945eefbcbad8b9ed3c84f"
                "0382cb72c666c02c07129826a668d79e",
                "0466aa71c44a14aa902a609c6500f4bc087cabbfa09c1e5bfb309f0a7e89fcdd"
                "9971e0359663e31803e3611bfa4d2353",
            ),
        ),
    ),
    CatalogModel(
        "person-reidentification-retail-0287",
        "reidentification",
        "person re-identification embedding (OSNet family), 256x128 crop to 256 values",
        _ir(
            "person-reidentification-retail-0287",
            "FP16",
            "2023.0/models_bin/1",
            (614946, "95125bc630208d9a27370b11bd04d220f93f64b60fe4be5bc576e9aebb69603d"),
            (1181124, "8811b3db2f6ebacbf2c05510593783316026ff779d9b048b6ca2581f17baf86c"),
            (
                "922cc5560fa298a9f02cac5bad5cbeeaee2a913ec435ae6f446d0c783936598b"
                "333c017ce1a702b605c2fd7fa33a6ee7",
                "ad86ea0b8661e43b01482fef63b2fe423ec9df8e55f6283f28c01094223f7731"
                "e4d60de5700036e6a2df7ebae0f5012d",
            ),
        ),
    ),
    CatalogModel(
        "person-reidentification-retail-0288",
        "reidentification",
        "person re-identification embedding (OSNet family), 256x128 crop to 256 values; "
        "the smallest and fastest of the three",
        _ir(
            "person-reidentification-retail-0288",
            "FP16",
            "2023.0/models_bin/1",
            (614533, "0d5021c772e603dce69d9ef2e326ecf0a43234cc8b4c5bb5e8aa566f090bdb51"),
            (364098, "08e24c2f1dd976ff8e1f667b93db2950ac8db8da09e163e1ca6463b82d1dbc42"),
            (
                "18814c6445b35224987bc44bcbdb47da6c3826e5da0b6aa00a88c06bf71491a8"
                "c4f42e1f62424c077cce46e76a41f7a2",
                "0a5ca9d000ce63b078149a3aa3993cd6e92d52fdecf1ff58fbe717481c2043db"
                "348938c32fed964846817dc321825a4c",
            ),
        ),
    ),
)

CATALOG: Mapping[str, CatalogModel] = MappingProxyType({m.name: m for m in _MODELS})
"""The known models by name, in the order above (detectors first, the default first)."""

DEFAULT_DETECTOR = "person-detection-0202"
"""The CNN person detector the service runs from its models folder (VTRACK_CNN_MODEL's
default)."""

DEFAULT_POSE = "human-pose-estimation-0001"
"""The pose network the service runs from its models folder (VTRACK_POSE_MODEL's default)."""

DEFAULT_REID = "person-reidentification-retail-0287"
"""The re-identification network the service runs from its models folder (VTRACK_REID_MODEL's
default): the middle of the three (Market-1501 rank-1 92.9 % against 0277's 96.2 %, with under a
third of its weights)."""

DEFAULT_MODELS = (DEFAULT_DETECTOR, DEFAULT_POSE, DEFAULT_REID)
"""What ``vtrack models fetch`` gets when no name is given: the networks a job runs by default."""


class UnknownModelError(KeyError, ValueError):
    """A name that is not in :data:`CATALOG`; the message lists the known names. A KeyError
    (a failed look-up) and a ValueError (a bad argument), for callers who catch either."""

    def __str__(self) -> str:  # KeyError's would show the message in quotes
        return str(self.args[0])


def check_name(name: str) -> CatalogModel:
    """The catalog's model ``name``; raises :class:`UnknownModelError` naming the known ones."""
    try:
        return CATALOG[name]
    except KeyError:
        known = ", ".join(CATALOG)
        raise UnknownModelError(f"unknown model {name!r}: the catalog has {known}") from None


def model_path(models_dir: Path, name: str) -> Path:
    """The graph (``.xml``) of model ``name`` inside the models folder ``models_dir``; it need
    not exist. Raises :class:`UnknownModelError` (a KeyError and a ValueError)."""
    return Path(models_dir) / check_name(name).graph
