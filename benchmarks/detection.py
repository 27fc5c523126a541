"""Person detection benchmark: the DPM engine, the CNN detectors, the embedded default, OpenCV's HOG
and public boxes.

    python benchmarks/detection.py [--data DIR] [--sequences NAME_OR_DIR ...] [--step N]
                                   [--detectors a,b,...] [--json] [--picture PNG] [--plot PNG]
                                   [--timing-frames N] [--repeats N] [--workers N]
                                   [--height H] [--no-timing] [--no-accuracy]

Accuracy, on every ``step``-th frame of each MOTChallenge sequence (default: PETS09-S2L1 and
TUD-Stadtmitte under ``<repo>/../shared/data/mot``; the same frames for every detector). The
default ``--step 1`` scores every frame, the protocol of issue 3's targets (on it the public
detections score AP 0.847 / 0.535, the figures the issue quotes); a run of the default detectors
takes about twenty minutes on two cores, most of it the VOC2007 model, which scores every root
exactly. ``--step 2`` (frames 1, 3, 5, ...) halves that; on it the public detections score
0.842 / 0.545, so margins of a few thousandths are not the same on the two protocols.

Without ``--picture PNG`` no picture is drawn (the committed ``docs/images/detections.png`` is
made by passing its path, see ``docs/benchmarks.md``); with it, the first DPM variant's
detections and part boxes on the first frame of the first sequence.

* AP at IoU 0.5 ("all points" VOC AP: detections of all frames sorted by score, greedy matching
  to the ground truth per frame, area under the precision envelope;
  ``tracking.evaluation.detection``);
* log-average miss rate over FPPI 1e-2..1e0 (Dollár et al. 2012), and a miss-rate/FPPI plot.

Boxes are compared in 0-based image pixels, the detectors' convention: ``MotSequence.gt`` and
``MotDetections`` move the files' 1-based boxes (``tracking/datasets/mot.py``).

Each detector runs at an evaluation threshold below its operating one so that its whole
precision/recall curve is seen: the DPM at ``model.thresh - 1``, the embedded default at SVM
score -0.5, the CNN detectors at network confidence 0.02 (operating: 0.2; the SSDs' own output
layer keeps nothing below it); OpenCV's peer runs as
OpenCV does by default (score 0, its own grouping); the public detections are used as published
(confidence >= 0.5).

Speed, at native resolution, on ``timing-frames`` frames of each sequence (median over ``repeats``
runs per frame, reported as frames per second): full-frame detection for each detector (the DPM at
the evaluation threshold and at the model's own, ``@model-threshold``: the star cascade prunes less
at lower thresholds), OpenCV's HOG at 1.0x, at the DPM's upscale (the same image scale) and at the
scale of the DPM's finest features (twice its upscale for models with an extra octave), and per
region of interest -- the DPM's ``dense_scores`` and ``detect_region`` over a window around each of
up to three ground-truth people per frame (centre +- 0.25 of its height; window heights 0.8..1.25
("wide", 6 pyramid levels) or 0.9..1.1 ("narrow", 3 levels) of its height: the spread a particle
filter searches). CNN detectors: full frames as the others, and, those at the frame's aspect
(a fixed input does not change how regions are searched), per region of interest
``detect_regions`` with the regions of a frame (the same windows, up to three) in one batched
inference, reported as regions per second (the regions of all timed frames over the sum of
each frame's median time). Every full-frame row also gets its speed as a ratio to the embedded
``default`` (timed in every run, on the same frames, whether or not it is among
``--detectors``): ``speed_ratio_to_default`` in the report. The detectors take turns frame by
frame, so that a burst of load on a shared machine slows them all rather than one.

``--height H`` resizes every frame (and its ground truth and public detections) to ``H`` pixels
high: the same scene as a camera of that resolution shows it, for the automatic enlargement of
the embedded default (``HogPeopleConfig.upscale_for``), the CNN's input size
(``CnnConfig.input_for``; the accuracy rows of a CNN give the input it chose) and the cost of
larger frames. Speed is
then measured on the resized frames.

DPM variants are named ``dpm-<model>[@upscale][:levels per octave][>min height][+exact]``, e.g.
``dpm-inria`` (the ``DpmConfig`` defaults with the star cascade), ``dpm-inria+exact`` (every root
scored exactly), ``dpm-inria@1.3:5`` (frame enlarged 1.3x, 5 levels per octave) or
``dpm-inria>128`` (only windows at least 128 pixels tall, the height of OpenCV's HOG window).
The default detectors include ``dpm-inria:2``: 2 levels per octave, the coarsest pyramid measured
that keeps issue 3's AP target, and the one that runs at least as fast as OpenCV's HOG on the
unscaled frame (``docs/benchmarks.md``, "Coarser pyramids").
CNN detectors (``tracking.detection.cnn``, OpenVINO) are named ``cnn-<model>[@native|@<W>x<H>]``
with a model of ``CNN_MODELS`` under ``<--data>/models`` (``0202``, ``0200``, ``retail-0013``,
``yolox-nano``): by default the input has the frame's aspect at the size ``CnnConfig`` gives
(the frame's own when its shorter side is 576-1080 px, else scaled into that range, enlarged at
most 2x); ``@native`` feeds the model's own input size (512x512 for 0202, 416x416 for
yolox-nano), ``@<W>x<H>`` a fixed one (multiples of 32), ``@<H>p`` the frame-aspect rule with
``H`` instead of 576 as the lower bound of the shorter side (``cnn-0202@480p``).

``--held-out OTB,...`` checks the CNN detectors on people of OTB sequences that no choice was
made on (``held_out`` in the report): the frames, of every 3rd, where a detection of calibrated
probability 0.5 or more covers the one annotated person (IoU 0.5). OTB annotates one person per
sequence, so this is a recall at the tracker's operating point, not an AP. ``cnn`` is the
product's default, person-detection-0202 at the frame's aspect (``cnn-0202``).
``default`` is the embedded detector with its enlargement chosen by the frame's height,
``default@<upscale>`` the same at a fixed enlargement. ``opencv-hog`` runs OpenCV's HOG at 1.5x,
``opencv-hog@<upscale>`` at another scale.

The machine may be shared; timings are medians. ``--workers`` sets the DPM's level threads (its
hot path makes no BLAS call, so BLAS's thread count does not matter to it; the report records
``OPENBLAS_NUM_THREADS`` all the same). OpenCV uses its default thread count. The CNN detectors
run on ``--workers`` inference threads when it is given, else on OpenVINO's choice (every core);
each model is compiled for a shape before that shape is timed.
"""

from __future__ import annotations

import argparse
import dataclasses
import math
import os
import re
import statistics
import sys
import time
from collections.abc import Callable
from pathlib import Path

import cv2
import numpy as np

from tracking.datasets.mot import MotFormatError, MotSequence
from tracking.datasets.otb import load_otb_sequence, read_frame
from tracking.detection import (
    DpmConfig,
    DpmDetector,
    HogPeopleConfig,
    HogPeopleDetector,
    ModelFileError,
    MotDetections,
)
from tracking.detection.cnn import CnnConfig, CnnDetector, CnnModelError
from tracking.detection.nms import box_iou
from tracking.evaluation.detection import (
    DetectionCurve,
    average_precision,
    detection_curve,
    log_average_miss_rate,
)
from tracking.types import Box

try:  # run as a script: benchmarks/ is on sys.path
    from _drawing import require_drawing
    from _paths import SHARED_DATA
    from _report import print_json
except ImportError:  # python -m benchmarks.<name> from the repository root
    from benchmarks._drawing import require_drawing
    from benchmarks._paths import SHARED_DATA
    from benchmarks._report import print_json

DEFAULT_SEQUENCES = ("PETS09-S2L1", "TUD-Stadtmitte")
DEFAULT_DETECTORS = (
    "dpm-inria",
    "dpm-inria:2",  # the coarsest pyramid that keeps the AP target: speed against HOG at 1.0x
    "dpm-inria@1.3:5",
    "dpm-voc2007",
    # every detection model of the shared data (issue 75), the product's first
    "cnn",
    "cnn-0200",
    "cnn-retail-0013",
    "cnn-yolox-nano",
    "cnn-0202@native",
    "cnn-yolox-nano@native",
    "default",
    "opencv-hog",
    "public",
)
PEER_UPSCALE = 1.5  # the reference setting for OpenCV's HOG
CNN_THRESHOLD = 0.02  # the SSDs' output floor: the whole curve (operating: 0.2)
ROI_HALF_SIZE = 0.25  # region: ground-truth centre +- this fraction of its height
ROI_HEIGHTS = {  # window heights searched, as fractions of the person's height
    "wide": (0.8, 1.25),
    "narrow": (0.9, 1.1),
}

Detect = Callable[[np.ndarray, int], tuple[np.ndarray, np.ndarray]]


# --------------------------------------------------------------------------------- data
@dataclasses.dataclass
class Sequence:
    """A MOTChallenge sequence as the benchmark reads it: frames, ground truth and the public
    detections, all resized by ``scale`` (``--height``) and, with ``portrait``
    (``--portrait``), each frame centred on a black 9:16 canvas of its width, the picture of a
    camera turned on its side (ground truth and detections moved with it)."""

    source: MotSequence
    scale: float = 1.0
    portrait: bool = False

    def __post_init__(self) -> None:
        self.name = self.source.name
        height, width = self.source.read_frame(0).shape[:2]
        width, height = round(width * self.scale), round(height * self.scale)
        self._canvas = (round(width * 16 / 9), width) if self.portrait else (height, width)
        self._top = (self._canvas[0] - height) // 2
        self.gt = {i: self._placed(boxes) for i, boxes in self.source.gt.items()}
        self._public: MotDetections | None = None

    def _placed(self, boxes: np.ndarray) -> np.ndarray:
        return boxes * self.scale + np.array([0.0, self._top, 0.0, 0.0])

    def __len__(self) -> int:
        return len(self.source)

    def read_frame(self, index: int) -> np.ndarray:
        frame = self.source.read_frame(index)
        if self.scale != 1.0:
            size = (round(frame.shape[1] * self.scale), round(frame.shape[0] * self.scale))
            frame = cv2.resize(frame, size, interpolation=cv2.INTER_LINEAR)
        if not self.portrait:
            return frame
        canvas = np.zeros((*self._canvas, *frame.shape[2:]), frame.dtype)
        canvas[self._top : self._top + frame.shape[0]] = frame
        return canvas

    def load_public(self) -> MotDetections:
        """The public ``det/det.txt`` (read once; MotFormatError if missing or malformed)."""
        if self._public is None:
            self._public = MotDetections.from_file(self.source.detections_file)
        return self._public

    def public(self, index: int) -> tuple[np.ndarray, np.ndarray]:
        """The public ``det/det.txt`` boxes and scores of a 0-based frame."""
        d = self.load_public().for_frame(index)
        return self._placed(d.boxes), d.scores


# --------------------------------------------------------------------------------- detectors
@dataclasses.dataclass
class Entry:
    """One detector of the benchmark."""

    name: str
    description: str
    detect: Detect  # (frame, 0-based index) -> boxes (N, 4), scores (N,)
    timed: bool = True
    dpm: DpmDetector | None = None
    cnn: CnnDetector | None = None
    regions: bool = False  # time the CNN's batched regions of interest too


def _opencv_peer(upscale: float) -> Detect:
    """OpenCV's own pipeline: detectMultiScale with its defaults (grouping), boxes shrunk."""
    hog = cv2.HOGDescriptor()
    hog.setSVMDetector(cv2.HOGDescriptor_getDefaultPeopleDetector())
    sw, sh = HogPeopleConfig().box_scale

    def detect(frame: np.ndarray, index: int) -> tuple[np.ndarray, np.ndarray]:
        image = frame if upscale == 1.0 else cv2.resize(frame, None, fx=upscale, fy=upscale)
        rects, weights = hog.detectMultiScale(image)
        if len(rects) == 0:
            return np.zeros((0, 4)), np.zeros(0)
        boxes = np.asarray(rects, dtype=np.float64).reshape(-1, 4) / upscale
        boxes[:, 0] += boxes[:, 2] * (1 - sw) / 2
        boxes[:, 1] += boxes[:, 3] * (1 - sh) / 2
        boxes[:, 2:] *= (sw, sh)
        return boxes, np.ravel(weights).astype(float)

    return detect


DPM_MODELS = {"inria": "INRIA/inriaperson_final.mat", "voc2007": "VOC2007/person_final.mat"}
DPM_FORM = "dpm-<model>[@upscale][:levels][>min height][+exact]"
CNN_MODELS = {  # under <--data>/models
    "0202": "person-detection-0202/FP16/person-detection-0202.xml",
    "0200": "person-detection-0200/FP16/person-detection-0200.xml",
    "retail-0013": "person-detection-retail-0013/FP16/person-detection-retail-0013.xml",
    "yolox-nano": "yolox-nano/yolox_nano.onnx",
}
CNN_DEFAULT_MODEL = "0202"  # ``cnn``: the product's default network
CNN_FORM = "cnn-<model>[@native|@<W>x<H>|@<H>p]"
DETECTOR_FORMS = (
    f"{DPM_FORM} with model {' or '.join(DPM_MODELS)}, cnn, {CNN_FORM} with model "
    f"{', '.join(CNN_MODELS)}, default[@upscale], opencv-hog[@upscale] or public"
)


class DetectorNameError(ValueError):
    """A ``--detectors`` name the benchmark does not know; the message lists the valid forms."""


_DPM_NAME = re.compile(
    r"dpm-(?P<model>[a-z0-9]+)(@(?P<upscale>[0-9.]+))?(:(?P<levels>[0-9]+))?"
    r"(>(?P<min_height>[0-9.]+))?(?P<exact>\+exact)?"
)


def parse_dpm_name(name: str) -> tuple[str, dict[str, object]]:
    """``dpm-<model>[@upscale][:levels][>min height][+exact]`` -> model file, DpmConfig fields.

    ``+exact`` scores every root exactly (no star cascade).
    """
    form = DPM_FORM
    match = _DPM_NAME.fullmatch(name)
    if match is None or match["model"] not in DPM_MODELS:
        raise DetectorNameError(
            f"bad DPM detector name {name!r}: {form} with a model of {sorted(DPM_MODELS)}"
        )
    fields: dict[str, object] = {"cascade": match["exact"] is None}
    if match["upscale"]:
        fields["upscale"] = _positive(match["upscale"], name, form)
    if match["levels"]:
        fields["levels_per_octave"] = int(_positive(match["levels"], name, form))
    if match["min_height"]:
        fields["min_height"] = _positive(match["min_height"], name, form)
    return DPM_MODELS[match["model"]], fields


_CNN_NAME = re.compile(
    r"cnn-(?P<model>[a-z0-9-]+?)"
    r"(@(?:(?P<native>native)|(?P<width>[0-9]+)x(?P<height>[0-9]+)|(?P<low>[0-9]+)p))?"
)


def parse_cnn_name(name: str) -> tuple[str, tuple[int, int] | str | float | None]:
    """``cnn`` or ``cnn-<model>[@native|@<W>x<H>|@<H>p]`` -> model file under ``models/``, input.

    The input is ``None`` (the frame's aspect, ``CnnConfig``'s rule), ``"native"`` (the
    model's own size, known once it is loaded), ``(width, height)``, multiples of the
    networks' stride (32), or a number: the rule with that lower bound on the shorter side
    instead of 576 (``@480p``: frames of 480-1080 px at their size).
    """
    if name == "cnn":
        return CNN_MODELS[CNN_DEFAULT_MODEL], None
    match = _CNN_NAME.fullmatch(name)
    if match is None or match["model"] not in CNN_MODELS:
        raise DetectorNameError(
            f"bad CNN detector name {name!r}: {CNN_FORM} with a model of {sorted(CNN_MODELS)}"
        )
    model = CNN_MODELS[match["model"]]
    if match["native"]:
        return model, "native"
    if match["low"]:
        low = int(match["low"])
        if not 32 <= low <= CnnConfig().input_heights[1]:
            raise DetectorNameError(f"bad CNN detector name {name!r}: @<H>p with 32 <= H <= 1080")
        return model, float(low)
    if match["width"] is None:
        return model, None
    stride = CnnConfig().stride
    size = (int(match["width"]), int(match["height"]))
    if not all(v >= stride and v % stride == 0 for v in size):
        raise DetectorNameError(
            f"bad CNN detector name {name!r}: {CNN_FORM}, W and H multiples of {stride}"
        )
    return model, size


def _positive(text: str, name: str, form: str) -> float:
    """``text`` (a number in detector ``name``) as a positive float, else DetectorNameError."""
    try:
        value = float(text)
    except ValueError:
        value = math.nan
    if not (math.isfinite(value) and value > 0):
        raise DetectorNameError(f"bad detector name {name!r}: {form}, with positive numbers")
    return value


def _upscale(name: str, detector: str) -> float:
    """The scale of ``<detector>@<upscale>``."""
    return _positive(name.removeprefix(f"{detector}@"), name, f"{detector}@<upscale>")


def check_detector_name(name: str) -> str:
    """``name`` if the benchmark knows the detector, checked without loading any model.

    Raises
    ------
    DetectorNameError
        For a name of no known form, or a malformed DPM or ``@<upscale>`` suffix.
    """
    if name.startswith("dpm-"):
        parse_dpm_name(name)
    elif name == "cnn" or name.startswith("cnn-"):
        parse_cnn_name(name)
    elif name.startswith(("default@", "opencv-hog@")):
        _upscale(name, name.partition("@")[0])
    elif name not in ("default", "opencv-hog", "public"):
        raise DetectorNameError(f"unknown detector {name!r}; the detectors are {DETECTOR_FORMS}")
    return name


def detector_names(text: str) -> list[str]:
    """``--detectors``: comma-separated names, each checked (an argparse error names the bad
    one, before any model loads or frame is read)."""
    names = [n.strip() for n in text.split(",") if n.strip()]
    if not names:
        raise argparse.ArgumentTypeError(f"no detector named; the detectors are {DETECTOR_FORMS}")
    try:
        return [check_detector_name(n) for n in names]
    except DetectorNameError as error:
        raise argparse.ArgumentTypeError(str(error)) from None


def build_entries(args: argparse.Namespace, names: list[str]) -> dict[str, Entry]:
    """The requested detectors (model files from ``--data``).

    Raises
    ------
    DetectorNameError
        For an unknown name.
    ModelFileError
        If a DPM model file is missing or malformed.
    CnnModelError
        If a CNN model file is missing or malformed.
    """
    entries: dict[str, Entry] = {}
    for name in names:
        if name.startswith("dpm-"):
            model, fields = parse_dpm_name(name)
            probe = DpmDetector.from_file(args.data / "dpm" / model)
            config = DpmConfig(
                threshold=probe.model.threshold - 1.0, workers=args.workers or 1, **fields
            )
            detector = DpmDetector(probe.model, config)
            scale = "by frame height" if config.upscale is None else f"{config.upscale:g}"

            def detect(frame: np.ndarray, index: int, d: DpmDetector = detector) -> tuple:
                result = d.detect(frame)
                return result.boxes, result.scores

            entries[name] = Entry(
                name,
                f"DPM {model}, upscale {scale}, {detector.interval} levels/octave, windows "
                f">= {config.min_height or 0:g} px, {'cascade' if config.cascade else 'exact'}, "
                "threshold thresh-1",
                detect,
                dpm=detector,
            )
        elif name == "cnn" or name.startswith("cnn-"):
            entries[name] = cnn_entry(name, args.data, args.workers or 0)
        elif name == "default" or name.startswith("default@"):
            entries[name] = default_entry(name)
        elif name == "opencv-hog" or name.startswith("opencv-hog@"):
            upscale = PEER_UPSCALE if name == "opencv-hog" else _upscale(name, "opencv-hog")
            entries[name] = Entry(
                name,
                f"OpenCV HOG detectMultiScale defaults at {upscale:g}x (peer)",
                _opencv_peer(upscale),
            )
        elif name == "public":
            entries[name] = Entry(
                name, "public det/det.txt", lambda f, i: (None, None), timed=False
            )
        else:
            raise DetectorNameError(
                f"unknown detector {name!r}; the detectors are {DETECTOR_FORMS}"
            )
    return entries


def cnn_entry(name: str, data: Path, threads: int = 0) -> Entry:
    """The CNN detector ``name`` (``cnn-<model>[@native|@<W>x<H>]``) with its model from
    ``data/models``, at confidence :data:`CNN_THRESHOLD` on ``threads`` inference threads (0:
    OpenVINO's choice); CnnModelError if the model file is missing or malformed."""
    model, size = parse_cnn_name(name)
    config = CnnConfig(threshold=CNN_THRESHOLD, threads=threads)
    detector = CnnDetector.from_file(data / "models" / model, config)
    if size == "native":
        _, _, height, width = detector.network.input_shape
        detector = CnnDetector(
            detector.network, dataclasses.replace(config, input_size=(width, height))
        )
        shown = f"{width}x{height} (native)"
    elif isinstance(size, float):
        config = dataclasses.replace(config, input_heights=(size, config.input_heights[1]))
        detector = CnnDetector(detector.network, config)
        shown = f"frame aspect (shorter side {size:g}-{config.input_heights[1]:g} px)"
    elif size is not None:
        detector = CnnDetector(detector.network, dataclasses.replace(config, input_size=size))
        shown = f"{size[0]}x{size[1]}"
    elif detector.network.reshapeable:
        low, high = config.input_heights
        shown = (
            f"frame aspect (shorter side {low:g}-{high:g} px, enlarged <= {config.max_upscale:g}x)"
        )
    else:
        _, _, height, width = detector.network.input_shape
        shown = f"{width}x{height} (letterboxed: the model's only shape)"

    def detect(frame: np.ndarray, index: int, d: CnnDetector = detector) -> tuple:
        result = d.detect(frame)
        return result.boxes, result.scores

    return Entry(
        name,
        f"CNN {Path(model).name}, input {shown}, confidence >= {CNN_THRESHOLD:g}, "
        f"{threads or 'default'} threads",
        detect,
        cnn=detector,
        regions=size is None,
    )


def cnn_input(detector: CnnDetector, shape: tuple[int, ...]) -> str:
    """``WxH``, the network input of a frame of ``shape``."""
    if detector.network.reshapeable:
        width, height = detector.config.input_for(shape)
    else:
        _, _, height, width = detector.network.input_shape
    return f"{width}x{height}"


def default_entry(name: str = "default") -> Entry:
    """The embedded default (``default`` or ``default@<upscale>``) at SVM score -0.5."""
    fixed = None if name == "default" else _upscale(name, "default")
    detector = HogPeopleDetector(HogPeopleConfig(hit_threshold=-0.5, upscale=fixed))

    def detect(frame: np.ndarray, index: int, d: HogPeopleDetector = detector) -> tuple:
        result = d.detect(frame)
        return result.boxes, result.scores

    scale = "by frame height" if fixed is None else f"{fixed:g}x"
    return Entry(name, f"embedded default (OpenCV HOG {scale}, our NMS, SVM >= -0.5)", detect)


# --------------------------------------------------------------------------------- accuracy
def evaluate(entry: Entry, sequence: Sequence, frames: list[int]) -> tuple[DetectionCurve, float]:
    """Detection curve of ``entry`` on ``frames`` of ``sequence`` and seconds per frame."""
    records = []
    seconds = []
    for index in frames:
        gt = sequence.gt[index]
        if entry.name == "public":
            records.append((*sequence.public(index), gt))
            continue
        frame = sequence.read_frame(index)
        start = time.perf_counter()
        boxes, scores = entry.detect(frame, index)
        seconds.append(time.perf_counter() - start)
        records.append((boxes, scores, gt))
    return detection_curve(records), (statistics.median(seconds) if seconds else math.nan)


# --------------------------------------------------------------------------------- speed
def _median_time(call: Callable[[], object], repeats: int) -> float:
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        call()
        times.append(time.perf_counter() - start)
    return statistics.median(times)


def timing(
    entries: dict[str, Entry],
    sequences: list[Sequence],
    frames_per_sequence: int,
    repeats: int,
) -> dict[str, dict[str, float]]:
    """Frames (or regions) per second on the sequences' frames (native resolution unless
    ``--height``); medians over frames and repeats. The embedded ``default`` is timed in every
    run, the reference of :func:`ratios_to_default`; full frames are timed frame by frame, each
    detector in turn on the same frame."""
    out: dict[str, dict[str, float]] = {}
    for sequence in sequences:
        picks = np.linspace(0, len(sequence) - 1, frames_per_sequence).round().astype(int)
        frames = [(i, sequence.read_frame(int(i))) for i in picks]
        peers = {f"opencv-hog@{u:g}": _opencv_peer(u) for u in (1.0, PEER_UPSCALE)}
        for entry in entries.values():
            if entry.dpm is None:
                continue
            # The DPM's scale for these frames and its finest features' (its scale, doubled
            # by the extra octave if the model has one).
            scale = entry.dpm.config.upscale_for(frames[0][1].shape)
            finest = scale * (2.0 if entry.dpm.model.extra_octave else 1.0)
            for u in {scale, finest} - {1.0, PEER_UPSCALE}:
                peers[f"opencv-hog@{u:g}"] = _opencv_peer(u)
        row: dict[str, float] = {}
        calls: dict[str, Callable[[np.ndarray, int], object]] = {
            name: entry.detect for name, entry in entries.items() if entry.timed
        }
        if "default" not in calls:  # the reference of the speed ratios
            calls["default"] = default_entry().detect
        for entry in entries.values():
            if entry.cnn is not None:  # compile the frame's shape outside the timing
                entry.detect(*frames[0][::-1])
        for name, entry in entries.items():
            if entry.dpm is not None:  # also at the threshold it runs at by default
                operating = DpmDetector(
                    entry.dpm.model, dataclasses.replace(entry.dpm.config, threshold=None)
                )
                calls[f"{name}@model-threshold"] = lambda f, i, d=operating: d.detect(f)
        calls.update(peers)
        # The detectors take turns frame by frame: a burst of load on a shared machine then
        # falls on all of them, not on one, and their ratios hold.
        per_frame: dict[str, list[float]] = {name: [] for name in calls}
        for i, f in frames:
            for name, call in calls.items():
                per_frame[name].append(_median_time(lambda c=call, f=f, i=i: c(f, i), repeats))
        for name, times in per_frame.items():
            row[f"{name} full"] = 1.0 / statistics.median(times)
        for name, entry in entries.items():
            if entry.dpm is None:
                continue
            dpm = entry.dpm
            for spread in ROI_HEIGHTS:
                dense, region_times = [], []
                for i, frame in frames:
                    for g in sequence.gt[int(i)][:3]:
                        region, heights = roi_around(g, spread)
                        args = (frame, region, heights)
                        dense.append(
                            _median_time(lambda a=args, d=dpm: d.dense_scores(*a), repeats)
                        )
                        region_times.append(
                            _median_time(lambda a=args, d=dpm: d.detect_region(*a), repeats)
                        )
                if dense:
                    row[f"{name} roi-{spread} dense_scores"] = 1.0 / statistics.median(dense)
                    row[f"{name} roi-{spread} detect_region"] = 1.0 / statistics.median(
                        region_times
                    )
        for name, entry in entries.items():
            if entry.cnn is not None and entry.regions:
                row.update(_cnn_regions(name, entry.cnn, sequence, frames, repeats))
        out[sequence.name] = row
    return out


def _cnn_regions(
    name: str,
    detector: CnnDetector,
    sequence: Sequence,
    frames: list[tuple[int, np.ndarray]],
    repeats: int,
) -> dict[str, float]:
    """Regions per second of ``detect_regions``, each frame's regions (around up to three
    ground-truth people) in one call: the regions of all frames over the sum of each frame's
    median time."""
    row = {}
    for spread in ROI_HEIGHTS:
        count, seconds = 0, 0.0
        for i, frame in frames:
            regions = [roi_around(g, spread) for g in sequence.gt[int(i)][:3]]
            if not regions:
                continue
            detector.detect_regions(frame, regions)  # compiles this batch size untimed
            seconds += _median_time(
                lambda f=frame, r=regions: detector.detect_regions(f, r), repeats
            )
            count += len(regions)
        if count:
            row[f"{name} roi-{spread} detect_regions"] = count / seconds
    return row


def ratios_to_default(speed: dict[str, dict[str, float]]) -> dict[str, dict[str, float]]:
    """Each full-frame speed of :func:`timing` divided by the embedded ``default``'s on the
    same frames, per sequence, by detector name (2.0: twice as fast)."""
    out = {}
    for sequence, row in speed.items():
        reference = row.get("default full")
        if not reference:
            continue
        out[sequence] = {
            what.removesuffix(" full"): fps / reference
            for what, fps in row.items()
            if what.endswith(" full")
        }
    return out


def roi_around(gt: np.ndarray, spread: str = "wide") -> tuple[Box, tuple[float, float]]:
    """The benchmark's region of interest and window-height range around a ground-truth box."""
    x, y, w, h = (float(v) for v in gt)
    half = ROI_HALF_SIZE * h
    region = Box(x + w / 2 - half, y + h / 2 - half, 2 * half, 2 * half)
    low, high = ROI_HEIGHTS[spread]
    return region, (low * h, high * h)


# --------------------------------------------------------------------------------- pictures
def save_picture(detector: DpmDetector, sequence: Sequence, index: int, path: Path) -> None:
    """Detections and their part boxes drawn on one frame (palette PNG, kept small)."""
    from PIL import Image  # matplotlib's dependency; only the benchmark draws

    frame = sequence.read_frame(index)
    result = dataclasses.replace(detector.config, threshold=None)
    detections = DpmDetector(detector.model, result, detector.calibration).detect(frame)
    canvas = frame.copy()
    colors = [
        (230, 25, 75), (60, 180, 75), (255, 225, 25), (0, 130, 200), (245, 130, 48),
        (145, 30, 180), (70, 240, 240), (240, 50, 230), (210, 245, 60), (250, 190, 190),
        (0, 128, 128),
    ]  # fmt: skip
    for box, parts, p in zip(
        detections.boxes, detections.parts, detections.probabilities, strict=True
    ):
        for k, part in enumerate(parts):
            if np.all(np.isfinite(part)):
                x, y, w, h = part
                cv2.rectangle(
                    canvas, (int(x), int(y)), (int(x + w), int(y + h)), colors[k % len(colors)], 1
                )
        x, y, w, h = box
        cv2.rectangle(canvas, (int(x), int(y)), (int(x + w), int(y + h)), (255, 255, 255), 2)
        cv2.putText(
            canvas, f"{p:.2f}", (int(x), max(int(y) - 3, 10)), cv2.FONT_HERSHEY_SIMPLEX, 0.4,
            (255, 255, 255), 1, cv2.LINE_AA,
        )  # fmt: skip
    path.parent.mkdir(parents=True, exist_ok=True)
    image = Image.fromarray(canvas).quantize(colors=128)
    image.save(path, optimize=True)


def save_plot(curves: dict[str, dict[str, DetectionCurve]], path: Path) -> None:
    """Miss rate against false positives per image, one panel per sequence."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, len(curves), figsize=(5 * len(curves), 4), squeeze=False)
    for ax, (sequence, by_detector) in zip(axes[0], curves.items(), strict=True):
        for name, curve in by_detector.items():
            if curve.fppi.size == 0:
                continue
            lamr = log_average_miss_rate(curve)
            ax.loglog(np.maximum(curve.fppi, 1e-3), curve.miss_rate, label=f"{name} ({lamr:.2f})")
        ax.set_xlim(1e-2, 1e1)
        ax.set_ylim(0.05, 1.0)
        ax.set_xlabel("false positives per image")
        ax.set_ylabel("miss rate")
        ax.set_title(sequence)
        ax.grid(True, which="both", alpha=0.3)
        ax.legend(fontsize=7, loc="lower left")
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=80)
    plt.close(fig)


# --------------------------------------------------------------------------------- main
def sequence_folder(item: str, data: Path) -> Path:
    """The folder of a ``--sequences`` item: a folder path, else a name under ``data/mot``.

    Raises
    ------
    MotFormatError
        If there is no such folder or it has no ground truth, which every detector is scored
        against.
    """
    path = Path(item)
    if not path.is_dir():
        path = data / "mot" / item
    if not path.is_dir():
        raise MotFormatError(
            f"no such sequence folder: {path} (--sequences takes folders or names under "
            f"{data / 'mot'})"
        )
    if not (path / "gt" / "gt.txt").is_file():
        raise MotFormatError(f"{path} has no gt/gt.txt, so no detector can be scored on it")
    return path


def _sequences(args: argparse.Namespace) -> list[Sequence]:
    """The ``--sequences``, resized to ``--height`` (MotFormatError with what is wrong)."""
    out = []
    for item in args.sequences:
        source = MotSequence.open(sequence_folder(item, args.data))
        height = source.read_frame(0).shape[0]
        out.append(Sequence(source, args.height / height if args.height else 1.0, args.portrait))
    return out


def parse_args(argv: list[str] | None) -> argparse.Namespace:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument(
        "--data",
        type=Path,
        default=SHARED_DATA,
        help=f"shared data root, with the sequences in mot/, the DPM models in dpm/ and the CNN "
        f"models in models/ (default {SHARED_DATA})",
    )
    parser.add_argument(
        "--sequences",
        nargs="+",
        default=list(DEFAULT_SEQUENCES),
        help="MOTChallenge sequence folders, or names under DATA/mot (default: "
        f"{' '.join(DEFAULT_SEQUENCES)})",
    )
    parser.add_argument(
        "--detectors",
        type=detector_names,
        metavar="A,B,...",
        default=",".join(DEFAULT_DETECTORS),
        help=f"comma-separated detectors, each {DETECTOR_FORMS} (default: "
        f"{','.join(DEFAULT_DETECTORS)})",
    )
    parser.add_argument(
        "--step",
        type=int,
        metavar="N",
        default=1,
        help="score every N-th frame of each sequence, starting with the first (default 1: "
        "every frame; 2: frames 1, 3, 5...)",
    )
    parser.add_argument(
        "--timing-frames",
        type=int,
        default=5,
        help="frames of each sequence the speed section times, spread over it (default 5)",
    )
    parser.add_argument(
        "--repeats", type=int, default=3, help="timed runs per frame or region (default 3)"
    )
    parser.add_argument(
        "--workers",
        type=int,
        help="DPM level threads (default 1); CNN inference threads (default: OpenVINO's "
        "choice, every core)",
    )
    parser.add_argument(
        "--height", type=int, help="resize the frames to this height in pixels (default: as is)"
    )
    parser.add_argument(
        "--portrait",
        action="store_true",
        help="centre each frame on a black 9:16 canvas of its width, as a camera turned on its "
        "side for a corridor frames it (after --height)",
    )
    parser.add_argument(
        "--picture",
        type=lambda v: Path(v) if v else None,
        default=None,
        metavar="PNG",
        help="write a PNG of the first DPM variant's detections and parts on a frame to this "
        "path (default: no picture)",
    )
    parser.add_argument("--plot", type=Path, metavar="PNG", help="miss rate / FPPI plot (PNG)")
    parser.add_argument(
        "--held-out",
        type=lambda text: [n.strip() for n in text.split(",") if n.strip()],
        metavar="OTB,...",
        help="also count, for each CNN detector, the frames of these OTB people sequences "
        "(under <--data>/otb, every 3rd frame) where a detection of probability >= 0.5 covers "
        "the annotated person (IoU 0.5): a check on data that chose nothing",
    )
    parser.add_argument("--no-timing", action="store_true", help="skip the speed section")
    parser.add_argument("--no-accuracy", action="store_true", help="skip the AP section")
    parser.add_argument("--json", action="store_true", help="print one JSON object")
    args = parser.parse_args(argv)
    for name in ("step", "timing_frames", "repeats", "workers"):
        value = getattr(args, name)
        if value is not None and value < 1:
            parser.error(f"--{name.replace('_', '-')} must be at least 1, got {value}")
    if args.height is not None and args.height < 16:
        parser.error("--height must be at least 16 pixels")
    if args.picture is not None:
        require_drawing(parser, "--picture", "PIL")
    if args.plot is not None:
        require_drawing(parser, "--plot", "matplotlib")
    return args


def main(argv: list[str] | None = None) -> int:
    args = parse_args(argv)
    try:
        report = run(args)
    except (MotFormatError, ModelFileError, CnnModelError) as error:
        # a missing or malformed input file: one line, the exit status of argparse's errors
        print(f"error: {error}", file=sys.stderr)
        return 2
    if args.json:
        print_json(report, indent=2)
    else:
        print_table(report)
    return 0


def run(args: argparse.Namespace) -> dict:
    """Every measurement the arguments ask for, as the report; the picture and plot saved.

    Raises
    ------
    MotFormatError
        If a sequence folder, its ground truth, public detections or a frame is missing or
        malformed.
    ModelFileError, CnnModelError
        If a DPM or CNN model file is missing or malformed.
    """
    sequences = _sequences(args)
    entries = build_entries(args, args.detectors)
    if "public" in entries:  # a bad det.txt is refused before the slow detectors run
        for sequence in sequences:
            sequence.load_public()
    results, curves = ({}, {}) if args.no_accuracy else accuracy(entries, sequences, args)
    speed = {} if args.no_timing else timing(entries, sequences, args.timing_frames, args.repeats)
    held_out = held_out_found(entries, args.data, args.held_out) if args.held_out else {}
    dpm = next((e.dpm for e in entries.values() if e.dpm is not None), None)
    if dpm is not None and args.picture:
        save_picture(dpm, sequences[0], 0, args.picture)
    if args.plot and curves:
        save_plot(curves, args.plot)
    report = {
        "protocol": {
            "iou": 0.5,
            "ap": "all-points VOC AP (precision envelope), greedy matching by score",
            "miss_rate": "log-average over 9 FPPI points in [1e-2, 1e0] (Dollar et al. 2012)",
            "step": args.step,
            "height": args.height,
            "roi": {"half_size": ROI_HALF_SIZE, "heights": ROI_HEIGHTS},
            "workers": args.workers or 1,
            "cnn_threads": args.workers or 0,  # 0: OpenVINO's choice
            "blas_threads": os.environ.get("OPENBLAS_NUM_THREADS", "default"),
        },
        "detectors": {n: e.description for n, e in entries.items()},
        "accuracy": results,
        "speed_fps": speed,
        "speed_ratio_to_default": ratios_to_default(speed),
    }
    if held_out:
        report["held_out"] = held_out
    return report


HELD_OUT_STEP = 3  # every 3rd frame of an OTB sequence
HELD_OUT_PROBABILITY = 0.5  # a detection the tracker would take as a person


def held_out_found(
    entries: dict[str, Entry], data: Path, names: list[str]
) -> dict[str, dict[str, list[int]]]:
    """Per CNN detector and OTB sequence, ``[found, frames]``: the frames (every
    :data:`HELD_OUT_STEP`-th) where a detection of calibrated probability at least
    :data:`HELD_OUT_PROBABILITY` covers the sequence's one annotated person with IoU 0.5. The
    OTB sequences annotate one person and no other, so AP cannot be scored on them; this asks
    whether the person a user points at would be detected, on data no choice was made on."""
    sequences = [load_otb_sequence(data / "otb" / name) for name in names]
    out: dict[str, dict[str, list[int]]] = {}
    for name, entry in entries.items():
        if entry.cnn is None:
            continue
        out[name] = {}
        for sequence in sequences:
            frames = range(0, len(sequence.frame_paths), HELD_OUT_STEP)
            found = 0
            for index in frames:
                detections = entry.cnn.detect(read_frame(sequence.frame_paths[index]))
                boxes = detections.boxes[detections.probabilities >= HELD_OUT_PROBABILITY]
                person = sequence.ground_truth[index][None]
                found += int(len(boxes) > 0 and box_iou(person, boxes).max() >= 0.5)
            out[name][sequence.name] = [found, len(frames)]
    return out


def accuracy(
    entries: dict[str, Entry], sequences: list[Sequence], args: argparse.Namespace
) -> tuple[dict[str, dict[str, dict[str, float]]], dict[str, dict[str, DetectionCurve]]]:
    """AP, log-average miss rate and seconds per frame of every detector on every ``--step``-th
    frame of each sequence (printed as they come unless ``--json``), and the curves."""
    results: dict[str, dict[str, dict[str, float]]] = {}
    curves: dict[str, dict[str, DetectionCurve]] = {}
    for sequence in sequences:
        frames = list(range(0, len(sequence), args.step))
        results[sequence.name] = {}
        curves[sequence.name] = {}
        for name, entry in entries.items():
            curve, seconds = evaluate(entry, sequence, frames)
            curves[sequence.name][name] = curve
            r = results[sequence.name][name] = {
                "ap": average_precision(curve),
                "log_average_miss_rate": log_average_miss_rate(curve),
                "seconds_per_frame": seconds,
                "frames": len(frames),
            }
            if entry.cnn is not None:  # the input the frame-size rule chose
                r["input"] = cnn_input(entry.cnn, sequence.read_frame(0).shape)
            if not args.json:  # progress: the DPM variants take minutes per sequence
                timed = f"  {seconds:.3f} s/frame" if math.isfinite(seconds) else ""
                print(
                    f"{sequence.name:16s} {name:22s} AP {r['ap']:.3f}  "
                    f"LAMR {r['log_average_miss_rate']:.3f}{timed}",
                    flush=True,
                )
    return results, curves


def _seconds(value: float, width: int = 0) -> str:
    """Seconds per frame to 3 decimals; "-" for a time that was not measured (NaN: the public
    detections are read, not detected)."""
    text = f"{value:.3f}" if math.isfinite(value) else "-"
    return f"{text:>{width}}"


def print_table(report: dict) -> None:
    """The report as readable tables."""
    print()
    print(f"{'sequence':16s} {'detector':22s} {'AP':>6s} {'LAMR':>6s} {'s/frame':>8s}")
    for sequence, rows in report["accuracy"].items():
        for name, r in rows.items():
            print(
                f"{sequence:16s} {name:22s} {r['ap']:6.3f} {r['log_average_miss_rate']:6.3f} "
                f"{_seconds(r['seconds_per_frame'], 8)}"
            )
    if report["speed_fps"]:
        print()
        print(f"{'sequence':16s} {'what':40s} {'fps':>8s}")
        for sequence, rows in report["speed_fps"].items():
            for what, fps in rows.items():
                print(f"{sequence:16s} {what:40s} {fps:8.2f}")
    for name, rows in report.get("held_out", {}).items():
        found = sum(f for f, _ in rows.values())
        frames = sum(n for _, n in rows.values())
        print(f"held out (OTB people found): {name:22s} {found} of {frames}")
    if report["speed_ratio_to_default"]:
        print()
        print(f"{'sequence':16s} {'full frame, speed / embedded default':40s} {'ratio':>8s}")
        for sequence, rows in report["speed_ratio_to_default"].items():
            for what, ratio in rows.items():
                print(f"{sequence:16s} {what:40s} {ratio:8.2f}")


if __name__ == "__main__":
    sys.exit(main())
