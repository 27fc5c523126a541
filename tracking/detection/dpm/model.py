"""voc-release5 deformable part models: the MATLAB ``model`` struct as typed, immutable objects.

A voc-release5 model is an object detection grammar (Girshick, Felzenszwalb, McAllester,
"Object Detection with Grammar Models", NIPS 2011). The models users download for pedestrians
(``INRIA/inriaperson_final.mat``) and PASCAL persons (``VOC2007/person_final.mat``) are mixtures
of star models (``model.type == 'M'``):

* the start symbol has one structural rule per component (``model.rules{model.start}``); its
  ``rhs`` lists the root and the parts, ``anchor{j} = [ax ay ds]`` places symbol ``j`` at
  ``(2^ds x + ax, 2^ds y + ay)`` on the pyramid level ``interval * ds`` below the root's
  (``ds = 1``: the parts' features have twice the root resolution);
* every right-hand-side symbol is a non-terminal with a single deformation rule whose ``rhs`` is
  a terminal (a filter); the root's deformation weights are ``[1000 0 1000 0]``, which pins it;
* parameters live in ``model.blocks``: filters (``shape = [h w 32]``, MATLAB column-major),
  offsets (the bias, scaled by ``model.features.bias``), location weights (3 numbers, one per
  octave of the pyramid, ``loc_feat.m``) and the separable quadratic deformation weights
  ``w = [a_x b_x a_y b_y]``.

The conventions follow ``model_get_block.m``: a filter with ``flip = 1`` is ``flipfeat`` of its
block (columns reversed, orientation channels permuted), a deformation with ``flip = 1`` negates
``b_x``. The deformation cost of a part placed ``(dx, dy)`` cells from its anchor
(``dx = anchor - placement``, as ``dt.cc``/``bounded_dt.cc`` and ``get_detection_trees.cc``
define it) is ``a_x dx^2 + b_x dx + a_y dy^2 + b_y dy`` (Felzenszwalb et al., PAMI 2010, eq. 2).

References
----------
P. F. Felzenszwalb, R. B. Girshick, D. McAllester, D. Ramanan, "Object Detection with
Discriminatively Trained Part-Based Models", IEEE TPAMI 32(9), 2010. R. B. Girshick,
P. F. Felzenszwalb, D. McAllester, "Discriminatively Trained Deformable Part Models, Release 5",
http://people.cs.uchicago.edu/~rbg/latent-release5/ (``model/model_get_block.m``,
``features/flipfeat.m``, ``gdetect/gdetect_dp.m``).
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from tracking.matfiles import read_mat

__all__ = [
    "DpmComponent",
    "DpmModel",
    "FilterSymbol",
    "ModelFileError",
    "flip_filter",
    "load_dpm_model",
]

# flipfeat.m: the channel permutation of a horizontally mirrored HOG cell (1-based there).
_FLIP_PERMUTATION = np.array(
    [10, 9, 8, 7, 6, 5, 4, 3, 2, 1, 18, 17, 16, 15, 14, 13, 12, 11, 19, 27, 26, 25, 24, 23,
     22, 21, 20, 30, 31, 28, 29, 32]
) - 1  # fmt: skip
_NUM_FEATURES = 32  # model.features.dim of the release5 models (31 HOG + truncation)


class ModelFileError(ValueError):
    """A file is not a voc-release5 mixture-of-star-models MATLAB model."""


@dataclass(frozen=True, slots=True)
class FilterSymbol:
    """One right-hand-side symbol of a component: a filter behind a deformation rule.

    Attributes
    ----------
    filter_index:
        0-based index into ``model.filters`` (voc-release5's order of filter boxes).
    weights:
        ``(h, w, 32)`` float32 filter, already mirrored when the filter has ``flip = 1``.
    anchor:
        ``(ax, ay, ds)``: the symbol sits at ``(2^ds x + ax, 2^ds y + ay)`` cells of the level
        ``interval * ds`` below the root's level ``l`` when the start symbol is at ``(x, y, l)``.
    deformation:
        ``(a_x, b_x, a_y, b_y)`` float64; the cost of a displacement ``(dx, dy)`` (anchor minus
        placement, in cells of the symbol's level) is ``a_x dx^2 + b_x dx + a_y dy^2 + b_y dy``;
        ``None`` for a filter that sits directly on its anchor (no deformation rule).
    bias:
        Offset of the deformation rule times ``model.features.bias``.
    location:
        ``(3,)`` weights of the octave indicator ``loc_feat.m`` for the symbol's own level.
    """

    filter_index: int
    weights: np.ndarray
    anchor: tuple[int, int, int]
    deformation: np.ndarray | None
    bias: float
    location: np.ndarray

    @property
    def size(self) -> tuple[int, int]:
        """Filter size ``(h, w)`` in cells."""
        return int(self.weights.shape[0]), int(self.weights.shape[1])


@dataclass(frozen=True, slots=True)
class DpmComponent:
    """One component (one structural rule of the start symbol) of a mixture of star models.

    Attributes
    ----------
    index:
        0-based rule index (voc-release5's component number minus one).
    root:
        The root filter symbol (anchor ``(0, 0, 0)``).
    parts:
        The part filter symbols, in the rule's ``rhs`` order.
    bias:
        Structural rule offset times ``model.features.bias``.
    location:
        ``(3,)`` octave-indicator weights of the structural rule.
    window:
        Detection window ``(h, w)`` in root cells (``rules{start}(i).detwindow``).
    shift:
        ``shiftwindow`` ``(h, w)`` in root cells (the window's offset from the root position).
    mirrored:
        Whether the root filter is a mirrored (``flip = 1``) filter.
    bbox_regression:
        ``(4, 2 (1 + P) + 1)`` coefficients predicting ``x1, y1, x2, y2`` from the filter centres
        (``bboxpred_get.m``), or ``None`` when the model has none.
    """

    index: int
    root: FilterSymbol
    parts: tuple[FilterSymbol, ...]
    bias: float
    location: np.ndarray
    window: tuple[int, int]
    shift: tuple[int, int]
    mirrored: bool
    bbox_regression: np.ndarray | None

    @property
    def symbols(self) -> tuple[FilterSymbol, ...]:
        """Root followed by the parts."""
        return (self.root, *self.parts)


@dataclass(frozen=True, slots=True)
class DpmModel:
    """A voc-release5 mixture of star models, ready for detection.

    Attributes
    ----------
    name:
        ``model.class`` (e.g. ``"inriaperson"``).
    components:
        The components in rule order (each mirrored component follows its original).
    sbin:
        HOG cell size in pixels at the pyramid's native octave (8).
    interval:
        Pyramid levels per octave (10).
    threshold:
        ``model.thresh``: the score above which voc-release5 reports a detection.
    max_size:
        ``(h, w)`` of the largest root filter in cells; the feature pyramid is padded by it.
    extra_octave:
        Whether the pyramid has an extra octave of ``sbin / 4`` features, which lets roots sit on
        ``sbin / 2`` features (objects half the model's native size).
    num_features:
        Channels per HOG cell (32, the last one the truncation feature).
    path:
        File the model was read from, if any.
    """

    name: str
    components: tuple[DpmComponent, ...]
    sbin: int
    interval: int
    threshold: float
    max_size: tuple[int, int]
    extra_octave: bool
    num_features: int = _NUM_FEATURES
    path: Path | None = None

    @property
    def num_parts(self) -> int:
        """Most parts in any component."""
        return max((len(c.parts) for c in self.components), default=0)


def flip_filter(weights: np.ndarray) -> np.ndarray:
    """Mirror a ``(h, w, 32)`` HOG filter left-right, as voc-release5 ``flipfeat.m``."""
    return np.ascontiguousarray(weights[:, ::-1, _FLIP_PERMUTATION])


# A struct of the MATLAB file as scipy.io reads it: its fields are attributes, listed in
# ``_fieldnames``; nothing is known of them statically.
_Struct = Any


def _readonly(array: np.ndarray) -> np.ndarray:
    array.setflags(write=False)
    return array


def _field(struct: _Struct, name: str, where: str) -> _Struct:
    if not hasattr(struct, "_fieldnames") or name not in struct._fieldnames:
        raise ModelFileError(f"{where} has no field {name!r}")
    return getattr(struct, name)


def _as_list(value: object) -> list:
    """A MATLAB struct array or cell array as a Python list (``squeeze_me`` drops 1-arrays)."""
    if isinstance(value, np.ndarray):
        if value.dtype == object:
            return list(value.ravel())
        if value.size == 0:
            return []
    return [value]


def _int(value: object, where: str) -> int:
    array = np.asarray(value, dtype=np.float64).ravel()
    if array.size != 1 or not np.isfinite(array[0]) or array[0] != round(array[0]):
        raise ModelFileError(f"{where} must be one integer, got {value!r}")
    return int(array[0])


def _vector(value: object, size: int, where: str) -> np.ndarray:
    try:
        array = np.asarray(value, dtype=np.float64).ravel()
    except (TypeError, ValueError) as error:
        raise ModelFileError(f"{where} must be {size} numbers, got {value!r}") from error
    if array.size != size:
        raise ModelFileError(f"{where} must have {size} values, got {array.size}")
    return array


class _Reader:
    """Reads parameters out of the loaded MATLAB struct (``model_get_block.m``)."""

    def __init__(self, model: _Struct) -> None:
        self.model = model
        self.blocks = _as_list(_field(model, "blocks", "model"))
        self.filters = _as_list(_field(model, "filters", "model"))
        self.symbols = _as_list(_field(model, "symbols", "model"))
        self.rules = _as_list(_field(model, "rules", "model"))
        features = _field(model, "features", "model")
        self.bias_scale = float(_field(features, "bias", "model.features"))
        self.num_features = _int(_field(features, "dim", "model.features"), "features.dim")
        if self.num_features != _NUM_FEATURES:
            raise ModelFileError(
                f"only 32-dimensional HOG models are supported, got features.dim "
                f"{self.num_features}"
            )

    def block(self, ref: _Struct, where: str) -> np.ndarray:
        label = _int(_field(ref, "blocklabel", where), f"{where}.blocklabel")
        if not 1 <= label <= len(self.blocks):
            raise ModelFileError(f"{where}.blocklabel {label} is outside 1..{len(self.blocks)}")
        block = self.blocks[label - 1]
        return np.asarray(_field(block, "w", f"model.blocks({label})"), dtype=np.float64)

    def scalar_block(self, rule: _Struct, name: str, where: str) -> float:
        if name not in getattr(rule, "_fieldnames", ()):
            return 0.0
        return float(_vector(self.block(getattr(rule, name), f"{where}.{name}"), 1, where)[0])

    def location(self, rule: _Struct, where: str) -> np.ndarray:
        if "loc" not in getattr(rule, "_fieldnames", ()):
            return np.zeros(3)  # models from before the location features
        return _vector(self.block(rule.loc, f"{where}.loc"), 3, f"{where}.loc")

    def filter(self, index: int) -> np.ndarray:
        """Filter ``index`` (0-based) as ``(h, w, 32)`` float32, mirrored if flagged."""
        where = f"model.filters({index + 1})"
        spec = self.filters[index]
        size = _vector(_field(spec, "size", where), 2, f"{where}.size").astype(int)
        flip = bool(_int(_field(spec, "flip", where), f"{where}.flip"))
        flat = self.block(spec, where)
        shape = (int(size[0]), int(size[1]), self.num_features)
        if flat.size != np.prod(shape):
            raise ModelFileError(
                f"{where} has {flat.size} weights, expected {shape[0]}x{shape[1]}x{shape[2]}"
            )
        weights = flat.reshape(shape, order="F").astype(np.float32)  # MATLAB column-major
        return flip_filter(weights) if flip else np.ascontiguousarray(weights)

    def rules_of(self, symbol: int) -> list:
        if not 1 <= symbol <= len(self.rules):
            raise ModelFileError(f"symbol {symbol} has no rules entry")
        return _as_list(self.rules[symbol - 1])

    def symbol(self, number: int, anchor: tuple[int, int, int]) -> FilterSymbol:
        """The filter behind right-hand-side symbol ``number`` (1-based)."""
        if not 1 <= number <= len(self.symbols):
            raise ModelFileError(f"rule refers to symbol {number}, model has {len(self.symbols)}")
        kind = str(_field(self.symbols[number - 1], "type", f"model.symbols({number})"))
        deformation = None
        bias = 0.0
        location = np.zeros(3)
        terminal = number
        if kind == "N":
            rules = self.rules_of(number)
            if len(rules) != 1 or str(_field(rules[0], "type", "rule")) != "D":
                raise ModelFileError(
                    f"symbol {number} must have exactly one deformation rule (mixture of star "
                    f"models), got {len(rules)} rule(s)"
                )
            rule = rules[0]
            where = f"model.rules{{{number}}}"
            terminal = _int(_field(rule, "rhs", where), f"{where}.rhs")
            definition = _field(rule, "def", where)
            deformation = _vector(self.block(definition, f"{where}.def"), 4, f"{where}.def")
            if "flip" in definition._fieldnames and _int(definition.flip, f"{where}.def.flip"):
                deformation = deformation * np.array([1.0, -1.0, 1.0, 1.0])  # b_x -> -b_x
            bias = self.scalar_block(rule, "offset", where) * self.bias_scale
            location = self.location(rule, where)
        elif kind != "T":
            raise ModelFileError(f"symbol {number} has unknown type {kind!r}")
        if not 1 <= terminal <= len(self.symbols):
            raise ModelFileError(f"deformation rule refers to symbol {terminal}")
        terminal_symbol = self.symbols[terminal - 1]
        if str(_field(terminal_symbol, "type", "symbol")) != "T":
            raise ModelFileError(f"symbol {terminal} must be a terminal (a filter)")
        filter_number = _int(_field(terminal_symbol, "filter", "symbol"), "symbol.filter")
        if not 1 <= filter_number <= len(self.filters):
            raise ModelFileError(f"symbol {terminal} refers to missing filter {filter_number}")
        if deformation is not None and (deformation[0] <= 0 or deformation[2] <= 0):
            raise ModelFileError(
                f"symbol {number}: quadratic deformation weights must be positive, got "
                f"{deformation.tolist()}"
            )
        return FilterSymbol(
            filter_index=filter_number - 1,
            weights=_readonly(self.filter(filter_number - 1)),
            anchor=anchor,
            deformation=None if deformation is None else _readonly(deformation),
            bias=bias,
            location=_readonly(location),
        )


def _bbox_regression(model: _Struct, index: int, num_symbols: int) -> np.ndarray | None:
    """Coefficients of ``bboxpred{index + 1}``: rows x1, y1, x2, y2."""
    if "bboxpred" not in model._fieldnames:
        return None
    entries = _as_list(model.bboxpred)
    if index >= len(entries) or not hasattr(entries[index], "_fieldnames"):
        return None
    entry = entries[index]
    expected = 2 * num_symbols + 1
    rows = []
    for name in ("x1", "y1", "x2", "y2"):
        if name not in entry._fieldnames:
            return None
        coefficients = np.asarray(getattr(entry, name), dtype=np.float64).ravel()
        if coefficients.size != expected:
            raise ModelFileError(
                f"model.bboxpred{{{index + 1}}}.{name} has {coefficients.size} coefficients, "
                f"expected {expected}"
            )
        rows.append(coefficients)
    return _readonly(np.stack(rows))


def _component(reader: _Reader, rule: _Struct, index: int) -> DpmComponent:
    where = f"model.rules{{start}}({index + 1})"
    if str(_field(rule, "type", where)) != "S":
        raise ModelFileError(f"{where} must be a structural rule")
    rhs = np.asarray(_field(rule, "rhs", where), dtype=np.float64).ravel().astype(int)
    anchors = _as_list(_field(rule, "anchor", where))
    if len(anchors) == 3 and all(np.ndim(a) == 0 for a in anchors):
        anchors = [anchors]  # a single rhs symbol: squeeze_me flattened the cell array
    if len(anchors) != rhs.size or rhs.size == 0:
        raise ModelFileError(f"{where} has {rhs.size} rhs symbols but {len(anchors)} anchors")
    symbols = []
    for j, (number, anchor) in enumerate(zip(rhs, anchors, strict=True)):
        values = _vector(anchor, 3, f"{where}.anchor{{{j + 1}}}").astype(int)
        if values[2] not in (0, 1):
            raise ModelFileError(f"{where}: anchor scale ds must be 0 or 1, got {values[2]}")
        symbols.append(reader.symbol(int(number), (int(values[0]), int(values[1]), int(values[2]))))
    root, parts = symbols[0], tuple(symbols[1:])
    if root.anchor != (0, 0, 0):
        raise ModelFileError(f"{where}: the first rhs symbol (root) must have anchor [0 0 0]")
    window = _vector(_field(rule, "detwindow", where), 2, f"{where}.detwindow").astype(int)
    shift = (
        _vector(rule.shiftwindow, 2, f"{where}.shiftwindow").astype(int)
        if "shiftwindow" in rule._fieldnames
        else np.zeros(2, dtype=int)
    )
    flip = int(_field(reader.filters[root.filter_index], "flip", "filter"))
    return DpmComponent(
        index=index,
        root=root,
        parts=parts,
        bias=reader.scalar_block(rule, "offset", where) * reader.bias_scale,
        location=_readonly(reader.location(rule, where)),
        window=(int(window[0]), int(window[1])),
        shift=(int(shift[0]), int(shift[1])),
        mirrored=bool(flip),
        bbox_regression=_bbox_regression(reader.model, index, len(symbols)),
    )


def _load_matlab(path: Path) -> _Struct:
    if not path.is_file():
        raise ModelFileError(f"DPM model file not found: {path}")
    try:
        contents = read_mat(path, struct_as_record=False, squeeze_me=True)
    except ValueError as error:
        raise ModelFileError(f"{path}: {error}") from error
    if "model" not in contents:
        names = sorted(k for k in contents if not k.startswith("__"))
        raise ModelFileError(f"{path} holds no variable 'model' (found {names})")
    return contents["model"]


def load_dpm_model(path: str | os.PathLike[str]) -> DpmModel:
    """Read a voc-release5 model file (``*_final.mat``) as users download it.

    Parameters
    ----------
    path:
        MATLAB v5 file holding the struct ``model`` of a mixture of star models.

    Returns
    -------
    DpmModel

    Raises
    ------
    ModelFileError
        If the file is missing, is not a MATLAB file, holds no ``model`` or a ``model`` that is
        not a voc-release5 mixture of star models with 32-dimensional HOG filters.
    """
    path = Path(path)
    model = _load_matlab(path)
    where = f"model in {path}"
    if not hasattr(model, "_fieldnames"):
        raise ModelFileError(f"{where} is not a struct (got {type(model).__name__})")
    try:
        reader = _Reader(model)
        start = _int(_field(model, "start", "model"), "model.start")
        rules = reader.rules_of(start)
        if not rules:
            raise ModelFileError(f"{where}: the start symbol has no rules")
        components = tuple(_component(reader, rule, i) for i, rule in enumerate(rules))
        max_size = _vector(_field(model, "maxsize", "model"), 2, "model.maxsize").astype(int)
        features = model.features
        extra = (
            bool(_int(features.extra_octave, "features.extra_octave"))
            if "extra_octave" in features._fieldnames
            else False
        )
        sbin = _int(_field(model, "sbin", "model"), "model.sbin")
        interval = _int(_field(model, "interval", "model"), "model.interval")
        threshold = float(np.asarray(_field(model, "thresh", "model"), dtype=np.float64))
    except ModelFileError as error:
        raise ModelFileError(f"{path}: {error}") from None
    except (TypeError, ValueError, AttributeError, IndexError) as error:
        raise ModelFileError(f"{path}: malformed voc-release5 model ({error})") from error
    if sbin % 4 != 0 or sbin < 4:
        raise ModelFileError(f"{path}: model.sbin must be a positive multiple of 4, got {sbin}")
    if interval < 1:
        raise ModelFileError(f"{path}: model.interval must be positive, got {interval}")
    name = str(getattr(model, "class", "")) if "class" in model._fieldnames else ""
    return DpmModel(
        name=name or path.stem,
        components=components,
        sbin=sbin,
        interval=interval,
        threshold=threshold,
        max_size=(int(max_size[0]), int(max_size[1])),
        extra_octave=extra,
        path=path,
    )
