"""Person re-identification embeddings on OpenVINO: one vector per person box, compared by cosine.

A tracker that loses a person (occlusion, a missed detection, a crossing) can tell who is who
again by appearance: the crop of each box goes through a re-identification network, which maps
it to a vector such that crops of one person lie close together (by the cosine of their angle)
and crops of different people far apart, whatever their pose and the camera's view.

The networks are Open Model Zoo's ``person-reidentification-retail-0277`` / ``0287`` / ``0288``
(strongest and slowest to smallest and fastest; Market-1501 rank-1 96.2 / 92.9 / 86.1 %). Their
descriptions in Open Model Zoo (``models/intel/<model>/description/<model>.md``) say they are
built on the OmniScaleNet backbone (0277 and 0287 with Linear Context Transform blocks), the
network of Zhou et al., *Omni-Scale Feature Learning for Person Re-Identification*, ICCV 2019
(OSNet, arXiv:1905.00953, which OpenVINO's training extensions name as their base). Each takes a
``1x3x256x128`` BGR crop of one person (0-255, normalised inside) and gives a 256-float
embedding.

:class:`ReidEmbedder` feeds them as Open Model Zoo's demos do: each box cropped from the frame
(clipped to it) and stretched to the network's input, whatever its aspect. The crops of one
frame go as one batch, padded to a power of two (so few input shapes are compiled, as the CNN
detector does for its regions), and the embeddings come back L2-normalised, so that
:func:`cosine_similarity` is a dot product.
"""

from __future__ import annotations

import os
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from types import MappingProxyType

import cv2
import numpy as np
from numpy.typing import ArrayLike

from tracking.detection.calibration import LogisticCalibration
from tracking.detection.cnn.runtime import CnnModelError, Network, load_network
from tracking.types import validate_uint8_frame

__all__ = ["KNOWN_REID_CALIBRATIONS", "ReidConfig", "ReidEmbedder", "cosine_similarity"]

# ``P(same person | cosine s) = sigmoid(a s + b)`` for each network, fitted by logistic
# regression (equal weight to both classes, so ``a s + b`` is the log likelihood ratio of "same"
# against "different" at even odds) on the ground-truth boxes of PETS09-S2L1 and TUD-Stadtmitte,
# every third frame, pairs of boxes 1 to 60 frames apart: 32,723 pairs of the same person,
# 190,747 of two people. The same person's median cosine is 0.72 (PETS) and 0.77 (TUD), two
# people's 0.09-0.19 (95th percentiles 0.28-0.46); occluded boxes make the low tail of "same".
KNOWN_REID_CALIBRATIONS: Mapping[str, LogisticCalibration] = MappingProxyType(
    {
        name: LogisticCalibration(
            a=a,
            b=b,
            source=f"{name}: same-person pairs against two-people pairs of the ground truth "
            "of PETS09-S2L1 and TUD-Stadtmitte, 1 to 60 frames apart",
        )
        for name, a, b in (
            ("person-reidentification-retail-0277", 14.4706, -4.85295),
            ("person-reidentification-retail-0287", 15.2293, -4.92473),
            ("person-reidentification-retail-0288", 14.3448, -5.20731),
        )
    }
)
"""Each Open Model Zoo re-identification network's calibration of cosine similarity into the
probability that two crops show the same person; another network gets 0287's."""


@dataclass(frozen=True)
class ReidConfig:
    """Options of :class:`ReidEmbedder`.

    Attributes
    ----------
    threads:
        Inference threads; 0: OpenVINO's choice.
    max_batch:
        Crops per inference request; more boxes go in several. Two requests run at once,
        each of ``ceil(boxes / 2)`` crops up to this
        (:meth:`~tracking.detection.cnn.runtime.Network.infer_batches`), so a video compiles
        a few input shapes only.
    min_box_side:
        A box whose part inside the frame is narrower or lower than this many pixels gets no
        embedding (a NaN row): a crop of a few pixels stretched to 256x128 says nothing about
        who is in it.
    """

    threads: int = 0
    max_batch: int = 4
    min_box_side: float = 8.0

    def __post_init__(self) -> None:
        if isinstance(self.threads, bool) or not isinstance(self.threads, int) or self.threads < 0:
            raise ValueError(f"threads must be an integer >= 0, got {self.threads!r}")
        if (
            isinstance(self.max_batch, bool)
            or not isinstance(self.max_batch, int)
            or self.max_batch < 1
        ):
            raise ValueError(f"max_batch must be an integer >= 1, got {self.max_batch!r}")
        if not np.isfinite(self.min_box_side) or self.min_box_side < 1:
            raise ValueError(f"min_box_side must be a number >= 1, got {self.min_box_side!r}")


@dataclass(slots=True)
class ReidEmbedder:
    """Appearance embeddings of people's boxes with a re-identification network.

    Parameters
    ----------
    network:
        The loaded model (:func:`~tracking.detection.cnn.runtime.load_network`): one image input
        ``(N, 3, H, W)`` taller than wide and a first output ``(N, D)``.
    config:
        Options.

    Raises
    ------
    CnnModelError
        A network whose input or output is not a re-identification network's.
    """

    network: Network
    config: ReidConfig = field(default_factory=ReidConfig)

    def __post_init__(self) -> None:
        name = self.network.path.name
        _, channels, height, width = self.network.input_shape
        if channels != 3 or height <= width:
            raise CnnModelError(
                f"{name}'s input is {self.network.input_shape}: a re-identification network "
                "takes a crop of one person, (N, 3, H, W) with H > W"
            )
        output = self.network.output_shapes[0]
        if len(output) != 2 or output[1] < 1:
            raise CnnModelError(
                f"{name}'s output is {output}: a re-identification network gives one embedding "
                "per crop, (N, D)"
            )

    @classmethod
    def from_file(
        cls, path: str | os.PathLike[str], config: ReidConfig | None = None
    ) -> ReidEmbedder:
        """The network at ``path`` (an OpenVINO IR ``.xml`` with its ``.bin``, or ONNX), read
        once per process (:func:`~tracking.detection.cnn.runtime.load_network`).

        Raises
        ------
        CnnModelError
            A file that is not a model, or a model that is not a re-identification network.
        """
        config = ReidConfig() if config is None else config
        return cls(load_network(Path(path), config.threads), config)

    @property
    def model_name(self) -> str:
        """The model's name (its file's stem)."""
        return self.network.name

    @property
    def calibration(self) -> LogisticCalibration:
        """``P(same person | cosine) = sigmoid(a cosine + b)`` for this network
        (:data:`KNOWN_REID_CALIBRATIONS`; another network gets 0287's)."""
        default = KNOWN_REID_CALIBRATIONS["person-reidentification-retail-0287"]
        return KNOWN_REID_CALIBRATIONS.get(self.model_name, default)

    def prepare(self) -> None:
        """Compile the network for every batch of crops now (``Network.prepare_batches``),
        not on the frames that first need each."""
        self.network.prepare_batches(self.network.input_shape[1:], self.config.max_batch)

    @property
    def embedding_size(self) -> int:
        """``D``: the length of each embedding (256 for Open Model Zoo's networks)."""
        return int(self.network.output_shapes[0][1])

    def embed(self, frame: np.ndarray, boxes: ArrayLike) -> np.ndarray:
        """The embedding of each box of ``frame``.

        Parameters
        ----------
        frame:
            RGB ``(H, W, 3)`` or greyscale ``(H, W)`` uint8 (a greyscale frame is repeated
            into three channels).
        boxes:
            ``(K, 4)`` ``x, y, w, h`` in frame pixels (0-based top-left corner).

        Returns
        -------
        (K, D) float32
            L2-normalised embeddings, in the order of ``boxes``; a NaN row for a box that is
            outside the frame, not finite, or whose part inside the frame is smaller than
            ``config.min_box_side`` on either side.
        """
        image = validate_uint8_frame(frame, "the re-identification embedder")
        array = np.asarray(boxes, dtype=np.float64)
        if array.size == 0:
            array = array.reshape(0, 4)
        if array.ndim != 2 or array.shape[1] != 4:
            raise ValueError(f"boxes must be (K, 4) x, y, w, h, got shape {np.shape(boxes)}")
        out = np.full((len(array), self.embedding_size), np.nan, dtype=np.float32)
        crops = self._crops(image, array)
        if not crops:
            return out
        rows = [index for index, _ in crops]
        embeddings = self._infer([image[y0:y1, x0:x1] for _, (x0, y0, x1, y1) in crops])
        norms = np.linalg.norm(embeddings, axis=1, keepdims=True)
        out[rows] = embeddings / np.maximum(norms, np.finfo(np.float32).tiny)
        return out

    def _crops(
        self, image: np.ndarray, boxes: np.ndarray
    ) -> list[tuple[int, tuple[int, int, int, int]]]:
        """``(row, (x0, y0, x1, y1))`` for each box whose part in the frame is large enough:
        its corners rounded to whole pixels and clipped to the frame."""
        height, width = image.shape[:2]
        side = self.config.min_box_side
        crops = []
        for index, (x, y, w, h) in enumerate(boxes):
            if not np.all(np.isfinite((x, y, w, h))):
                continue
            x0, y0 = max(0, round(x)), max(0, round(y))
            x1, y1 = min(width, round(x + w)), min(height, round(y + h))
            if x1 - x0 >= side and y1 - y0 >= side:
                crops.append((index, (x0, y0, x1, y1)))
        return crops

    def _infer(self, crops: list[np.ndarray]) -> np.ndarray:
        """``(len(crops), D)`` raw embeddings of RGB or greyscale crops, in batches of at most
        ``max_batch`` (:meth:`~tracking.detection.cnn.runtime.Network.infer_batches`)."""
        _, _, height, width = self.network.input_shape
        batch = np.empty((len(crops), height, width, 3), dtype=np.float32)
        for i, crop in enumerate(crops):
            # stretched to the input whatever its aspect, bilinear, as the demos do; then
            # BGR (a greyscale crop repeated), 0-255 (the network normalises inside)
            resized = cv2.resize(crop, (width, height), interpolation=cv2.INTER_LINEAR)
            batch[i] = resized[..., None] if resized.ndim == 2 else resized[..., ::-1]
        embeddings = self.network.infer_batches(batch.transpose(0, 3, 1, 2), self.config.max_batch)[
            0
        ]
        return np.asarray(embeddings, dtype=np.float32).reshape(len(crops), -1)


def cosine_similarity(a: ArrayLike, b: ArrayLike) -> np.ndarray:
    """``(K, M)`` cosine similarities of the rows of ``a`` ``(K, D)`` and ``b`` ``(M, D)``.

    The rows are taken as L2-normalised (as :meth:`ReidEmbedder.embed` gives them), so this is
    their dot product, clipped to ``[-1, 1]``. A row with a NaN (a box that had no embedding)
    gives NaN against every row of the other side.
    """
    a = np.asarray(a, dtype=np.float32)
    b = np.asarray(b, dtype=np.float32)
    if a.ndim != 2 or b.ndim != 2 or a.shape[1] != b.shape[1]:
        raise ValueError(f"cosine_similarity needs (K, D) and (M, D), got {a.shape} and {b.shape}")
    bad_a = ~np.isfinite(a).all(axis=1)
    bad_b = ~np.isfinite(b).all(axis=1)
    # zeros in place of NaN rows: a BLAS may skip terms multiplied by zero, so NaN is set after
    similarity = np.where(bad_a[:, None], 0.0, a) @ np.where(bad_b[:, None], 0.0, b).T
    similarity = np.clip(similarity, -1.0, 1.0).astype(np.float32)
    similarity[bad_a, :] = np.nan
    similarity[:, bad_b] = np.nan
    return similarity
