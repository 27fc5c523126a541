"""MOT benchmark: our multi-person tracker beside SORT, ByteTrack, OC-SORT, BoT-SORT, Deep OC-SORT
and StrongSORT, every tracker on the same detections and, in parity rows, with the same boxes.

    python benchmarks/mot.py [--data DIR] [--sequences NAME_OR_DIR ...] [--trackers a,b,...]
                             [--detections public,cnn] [--no-parity]
                             [--frames N] [--repeats R] [--seeds S] [--no-end-to-end]
                             [--no-peers] [--dpm PATH] [--dpm-config JSON] [--hog-config JSON]
                             [--cnn-model PATH] [--reid-model PATH] [--tracker-config JSON]
                             [--json] [--picture PNG] [--results DIR] [--list]

Sequences: the MOTChallenge folders under ``--data`` (default ``<repo>/../shared/data/mot`` or
``$VTRACK_SHARED_DATA/mot``: PETS09-S2L1 and TUD-Stadtmitte), or those named by
``--sequences`` (names under ``--data``, or paths of any MOTChallenge-layout folder:
``seqinfo.ini``, ``img1/``, ``gt/gt.txt``, ``det/det.txt``). A sequence without a readable
``gt/gt.txt`` is refused before anything runs: no tracker could be scored on it.

Detection sources (``--detections``, default ``public,cnn``). Every tracker that is fed
detections runs once on each source, and its rows are named ``<tracker>@<source>``
(``sort@public``, ``ours@cnn``). All trackers of a source read the same MOTChallenge detection
file (``frame, id, x, y, w, h, conf, ...``, 1-based) and are handed the same boxes, frame by
frame; each reports a digest of the boxes it was given (``fed_digest``: frame, x, y, w, h in
file units, rounded to 1e-4 px, one function mirrored in the peer scripts), the same for every
tracker of a source.

* ``public``: the sequence's ``det/det.txt`` (confidences 0.5 to 1 in these files);
* ``cnn``: our CNN person detector (``tracking.detection.make_detector(--cnn-model)``, a
  ``CnnDetector``; by default Open Model Zoo's person-detection-0202, the product's default
  network) run once per sequence over every frame (``--frames`` of them) with the ``CnnConfig``
  defaults but ``threshold`` 0.1 (``CNN_DETECTION_THRESHOLD``) instead of 0.2: 0.1 is the floor
  of the low-score detections that ByteTrack's second association recovers (Zhang et al. 2022;
  BoxMOT's BoT-SORT ``track_low_thresh`` 0.10), so the trackers that use low scores get them and
  each of the others thresholds the scores by its own rule (Roboflow's ByteTrack and OC-SORT
  split at 0.6, SORT and BoT-SORT start tracks at 0.25/0.7, BoxMOT's Deep OC-SORT drops boxes
  under 0.5, ours weighs calibrated probabilities: ``low_confidence``, ``birth_confidence``).
  Written once to ``<results>/detections/<sequence>/cnn.txt`` (``frame, -1, x + 1, y + 1, w,
  h, c, -1, -1, -1``: boxes 1-based to 1/1000 px, ``c`` the network's confidence, the sigmoid
  of the ``Detections.scores`` log-odds, to 1e-6) with ``cnn.json`` beside it; a run with the
  same ``--results`` reuses it while the key (SHA-256 of the model's files, the configuration,
  the sequence, the frame count) is the same.

What score each tracker gets: the peers get the file's confidence column as it is (public: the
file's; cnn: the network's confidence ``c``). Ours reads the same file with
``MotDetections`` (``tracking/detection/external.py``, which takes the column as the
probability, clipped to ``[0, 1]``, when it has no calibration): for ``public`` that is the
column itself (as before); for ``cnn`` the column is first turned into the calibrated
probability the detector hands ``ours_cnn``, ``p = calibration(log(c / (1 - c)))`` with the
model's calibration (``KNOWN_CALIBRATIONS``; the network's confidence when it has none): our
tracker's thresholds are on calibrated probabilities. Boxes are the same: ``MotDetections``
only moves them to 0-based pixels.

Trackers, all in one run:

* peers ``sort``, ``bytetrack``, ``ocsort``, ``botsort``: Roboflow's ``trackers`` with their
  default parameters (``frame_rate`` set to the sequence's, see
  ``benchmarks/peers/mot_trackers.py``), frame by frame on the detection file of the source
  (``--det``); BoT-SORT also gets the frames for its camera-motion compensation. They run in
  their own environment (``.venv-mot``, ``benchmarks/_mot_env.py``) because ``trackers`` pulls
  ``opencv-python`` 5, which would shadow the project's headless OpenCV 4;
* peers with a learned appearance model, ``deepocsort``, ``strongsort`` and ``botsort_reid``:
  BoxMOT's (25.0.0) Deep OC-SORT, StrongSORT and BoT-SORT with re-identification, made by its
  factory with its default parameters (BoT-SORT's ``frame_rate`` the sequence's; the other two
  have none), in their own environment (``.venv-reid``, ``benchmarks/_reid_env.py``: BoxMOT,
  PyTorch 2.14.1, torchvision 0.29.1, OpenCV 4; about 5.5 GB, made once with pip), see
  ``benchmarks/peers/reid_trackers.py``. Their appearance is *our* re-identification network's
  (``tracking.detection.reid.ReidEmbedder``, ``--reid-model``, by default Open Model Zoo's
  person-reidentification-retail-0287): this process embeds every box of each source's
  detection file (``ReidEmbedder.embed(frame, 0-based boxes)``, L2-normalised rows, NaN where a
  box is too small) into ``<results>/detections/<sequence>/<source>.reid.npy``, aligned with the
  file's rows and cached like the detection file (``.reid.json``: the network's and the file's
  SHA-256, the frame count), and the trackers get those vectors with the detections
  (``Detections(embeddings=...)``), so BoxMOT never builds its ReID backend and no weights are
  loaded or downloaded (the peer script checks it). Their speed excludes the embedding network;
* ``ours``: :class:`tracking.people.MultiPersonTracker` with its default configuration on each
  source (``detector=None``; ``update(frame, i / fps, detections)``);
* end to end (``--end-to-end``, the default): ``ours_hog``, the same tracker running the
  embedded HOG people detector (``make_detector("default")``), ``ours_dpm`` running the
  voc-release5 INRIA person DPM (``--dpm``) at its operating point for tracking
  (``DPM_TRACKING_CONFIG``), and ``ours_cnn`` running the CNN person detector
  (``CnnDetector``, ``CnnConfig`` defaults) on ``--cnn-model``: what a service job with
  detector 'auto' runs. These have no source suffix: the tracker gets no detections and runs its
  detector on the schedule of its configuration. The DPM is slow: ``--no-end-to-end`` skips all
  three, ``--frames N`` shortens every sequence. A missing model (``--dpm``, ``--cnn-model``,
  ``--reid-model``) leaves its trackers (``--cnn-model``: also the cnn source) out with a note in
  a run of all trackers, and is an argument error when ``--trackers`` (or ``--detections``)
  names them;
* with ``--seeds S`` (default 4) each of ours also runs with the particle filter's seeds 1 to
  S - 1 (``ours_seed1@public``, ``ours_cnn_seed1``...), and the comparison with the peers adds
  the mean over the seeds (``ours_mean@public``...). The seeded end-to-end runs replay the
  detections of the first run, frame by frame (the detector is deterministic), so the detector
  runs once.

Box parity rows (``--parity``, the default). Our tracker reports boxes of a fixed aspect
(``PeopleTrackerConfig.box_aspect``, 0.41: width set to 0.41 x height about the box centre, the
height kept), the peers the detector's boxes, and box shape alone moves the scores. So for
every peer and source there is also ``<peer>+aspect@<source>``: the peer's rows through
:func:`aspect_rows`, which calls our tracker's own rule (``tracking.people.motion.with_aspect``,
with the ``box_aspect`` ours runs with); its speed is the peer's. And for ours
``ours+detbox@<source>`` (with its seeds): ``MultiPersonTracker`` with ``box_aspect=None``,
which reports the associated detections' smoothed aspect.

Re-identification in ours: each of ours also runs with the re-identification network of
``--reid-model`` (``ours+reid@<source>``, ``ours+detbox+reid@<source>``), as a service job
runs when the model is installed (``tracker.reid``); the tracker embeds the detections itself,
with the network that gives the re-id peers their embeddings. ``--no-ours-reid`` leaves these
rows out.

Scores: TrackEval (``benchmarks/peers/trackeval_score.py``, in ``.venv-mot``) on the MOTChallenge
result files written to ``--results`` (default: a new temporary folder, kept and named in the
output), against ``gt/gt.txt`` cut to the frames that were run: HOTA, DetA, AssA (means over the
localisation thresholds 0.05..0.95), MOTA, IDF1, ID switches, MT/ML, FP/FN (IoU 0.5), in percent
and counts, per sequence and over all sequences (TrackEval's combination). TrackEval runs in its
MOT15 mode: every ground-truth row with a non-zero flag (7th column) counts and no result box is
removed as a distractor match; the files here have no classes (8th column -1), which TrackEval's
MOT16/17 preprocessing rejects.

Coordinates: MOTChallenge files are 1-based; our tracker gets the detections moved to 0-based
image coordinates (:class:`tracking.detection.MotDetections` moves them, see
``tracking/datasets/mot.py``) and its boxes are written back 1-based (``track_rows`` in
``tracking/evaluation/mot.py``); the ground truth goes to TrackEval as the file has it. The
peers never look at pixels (camera-motion compensation aside, to which a pixel is nothing) and
keep the file's coordinates throughout; the re-id network crops the 0-based boxes.

Speed: frames per second of the trackers' ``update`` calls only (not image decoding, file
reading, building the detections, or the re-id embeddings), median over ``--repeats`` runs by
fresh trackers (the end-to-end runs: ``--end-to-end-repeats``, default 1); for the end-to-end
runs that includes the detector, which runs inside ``update`` (except in the seeded end-to-end
runs, which replay the detections). Peers are timed in their own process, ours in this one.

Output: a table per tracker and sequence, then for each source ours against the best peer per
metric (the difference of each of ours, its seed means and the end-to-end rows): first the
fair comparison, the best among the peers' rows *and* their ``+aspect`` rows (JSON
``best_peer``, ``ours_vs_best_peer``, by source), then the raw one, the peers' own boxes only
(``best_raw_peer``, ``ours_vs_best_raw_peer``). ``--json`` prints one JSON object on stdout
instead (the table goes to stderr); it also describes each source (``sources``: files, scores,
calibration, cache). ``--picture PNG`` (default: none) draws our tracks (``ours@public``) on a
PETS09-S2L1 frame: boxes with ids, 20-frame trails, body parts (filled: visible; hollow:
hidden); the committed ``docs/images/mot.png`` is made by passing its path
(``docs/benchmarks.md``).

Exit status: 0 when at least one tracker was scored; 2 for bad arguments or sequences (a
tracker named in ``--trackers`` that another option leaves out is a bad argument); 1 when no
tracker ran or none could be scored (TrackEval's environment unavailable, TrackEval failing),
with an ``error:`` line after the report.
"""

from __future__ import annotations

import argparse
import contextlib
import dataclasses
import hashlib
import itertools
import json
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable, Sequence
from pathlib import Path

import cv2
import numpy as np
from tqdm import tqdm

from tracking.evaluation.mot import (
    MotFileError,
    SequenceInfo,
    find_mot_sequences,
    frame_rows,
    limit_frames,
    read_mot_rows,
    read_sequence_info,
    write_mot_file,
)
from tracking.tracks import FrameTracks

try:  # run as a script: benchmarks/ is on sys.path
    from _drawing import require_drawing
    from _paths import SHARED_DATA
    from _report import print_json
except ImportError:  # python -m benchmarks.<name> from the repository root
    from benchmarks._drawing import require_drawing
    from benchmarks._paths import SHARED_DATA
    from benchmarks._report import print_json

DEFAULT_DATA = SHARED_DATA / "mot"
DEFAULT_DPM = SHARED_DATA / "dpm" / "INRIA" / "inriaperson_final.mat"
# The product's default network (service.models.catalog.DEFAULT_DETECTOR in the catalog's
# layout, what a job with detector 'auto' runs); the shared data's copy is OMZ's files.
DEFAULT_CNN_MODEL = (
    SHARED_DATA / "models" / "person-detection-0202" / "FP16" / "person-detection-0202.xml"
)
CNN_SUFFIXES = (".xml", ".onnx")  # tracking.detection.cnn.MODEL_SUFFIXES, without importing it
# Our re-identification network, whose embeddings the re-id peers get (tracking.detection.reid).
DEFAULT_REID_MODEL = (
    SHARED_DATA
    / "models"
    / "person-reidentification-retail-0287"
    / "FP16"
    / "person-reidentification-retail-0287.xml"
)
PEER_SCRIPT = Path(__file__).resolve().parent / "peers" / "mot_trackers.py"
REID_SCRIPT = Path(__file__).resolve().parent / "peers" / "reid_trackers.py"
SCORE_SCRIPT = Path(__file__).resolve().parent / "peers" / "trackeval_score.py"

MOT_PEERS = ("sort", "bytetrack", "ocsort", "botsort")  # Roboflow's trackers, .venv-mot
REID_PEERS = ("deepocsort", "strongsort", "botsort_reid")  # BoxMOT, .venv-reid
PEERS = (*MOT_PEERS, *REID_PEERS)
OURS = "ours"
END_TO_END = ("ours_hog", "ours_dpm", "ours_cnn")
TRACKERS = (*PEERS, OURS, *END_TO_END)
SOURCES = ("public", "cnn")  # detection sources, --detections
# The CNN source's operating point: confidence >= 0.1, the floor of the low-score detections
# that ByteTrack's second association uses (Zhang et al. 2022; BoxMOT's BoT-SORT:
# track_low_thresh 0.10), so that trackers that use low scores get them; the others threshold
# the scores themselves (ours: low_confidence, birth_confidence on calibrated probabilities).
CNN_DETECTION_THRESHOLD = 0.1
ASPECT = "+aspect"  # a peer's rows with our box post-processing
DETBOX = "+detbox"  # ours reporting the detections' aspect (box_aspect=None)
REID = "+reid"  # ours with the re-identification network (--reid-model)
PICTURE_SEQUENCE = "PETS09-S2L1"
PICTURE_TRAIL = 20  # frames of trail behind each track
PICTURE_MAX_BYTES = 300_000

# Columns of the table: (key, header, digits); scores in percent, IDSW a count.
TABLE = (
    ("HOTA", "HOTA", 1),
    ("MOTA", "MOTA", 1),
    ("IDF1", "IDF1", 1),
    ("IDSW", "IDSW", 0),
    ("DetA", "DetA", 1),
    ("AssA", "AssA", 1),
    ("MT", "MT", 0),
    ("ML", "ML", 0),
    ("FP", "FP", 0),
    ("FN", "FN", 0),
)
LOWER_IS_BETTER = frozenset({"IDSW", "ML", "FP", "FN"})
# Metrics on which ours is compared with the best peer (and fps, as a ratio).
COMPARED = ("HOTA", "MOTA", "IDF1", "IDSW", "DetA", "AssA")
COMBINED = "COMBINED"


# --------------------------------------------------------------------------------------------
# Runs


@dataclasses.dataclass
class Run:
    """One tracker on one sequence: its result rows and the time of its update calls.

    Attributes
    ----------
    rows:
        ``(N, 7)`` ``frame, id, x, y, w, h, score`` in MOTChallenge units (1-based).
    seconds:
        Seconds spent in ``update`` over the whole sequence, one per repeat.
    frames:
        Frames tracked.
    deterministic:
        Whether every repeat gave the same rows.
    estimates:
        Our tracker's output per frame (first repeat), kept for the picture.
    """

    rows: np.ndarray
    seconds: list[float]
    frames: int
    deterministic: bool = True
    estimates: list[FrameTracks] | None = None

    @property
    def fps(self) -> float:
        return self.frames / max(statistics.median(self.seconds), 1e-12)


@dataclasses.dataclass
class DetectionSource:
    """Detections every tracker of one source gets: a MOTChallenge detection file per sequence.

    Attributes
    ----------
    name:
        ``public`` or ``cnn``.
    files:
        Sequence name -> detection file (rows ``frame, -1, x, y, w, h, conf, -1, -1, -1``, file
        units: frames and pixels 1-based).
    calibration:
        How ours reads the confidence column: ``None``, as the probability (clipped to
        ``[0, 1]``, :class:`MotDetections` without calibration); else a
        ``LogisticCalibration`` of the confidence's log-odds, ``p = calibration(log(c / (1 -
        c)))``: the probability the detector itself gives the tracker (the CNN's
        ``Detections.probabilities``).
    details:
        What the report says about it.
    embeddings:
        Sequence name -> ``.npy`` re-identification embeddings aligned with the file's rows
        (only when the re-id peers run).
    """

    name: str
    files: dict[str, Path]
    calibration: object | None = None
    details: dict[str, object] = dataclasses.field(default_factory=dict)
    embeddings: dict[str, Path] = dataclasses.field(default_factory=dict)


@dataclasses.dataclass
class Outcome:
    """Everything measured in one benchmark run."""

    sequences: list[SequenceInfo]
    frames: dict[str, int]
    runs: dict[str, dict[str, Run]] = dataclasses.field(default_factory=dict)
    errors: dict[str, dict[str, str]] = dataclasses.field(default_factory=dict)
    details: dict[str, dict[str, object]] = dataclasses.field(default_factory=dict)
    notes: list[str] = dataclasses.field(default_factory=list)
    sources: dict[str, DetectionSource] = dataclasses.field(default_factory=dict)

    def add(self, tracker: str, sequence: str, run: Run) -> None:
        self.runs.setdefault(tracker, {})[sequence] = run

    def fail(self, tracker: str, sequence: str, message: str) -> None:
        self.errors.setdefault(tracker, {})[sequence] = message
        print(f"{tracker} on {sequence} failed: {message}", file=sys.stderr)


def row_name(base: str, source: str | None = None, seed: int = 0) -> str:
    """A row of the report: ``<base>[_seed<k>][@<source>]`` (``sort@public``,
    ``ours+detbox_seed2@cnn``; the end-to-end trackers have no source: ``ours_cnn_seed1``)."""
    seeded = base if seed == 0 else f"{base}_seed{seed}"
    return seeded if source is None else f"{seeded}@{source}"


# --------------------------------------------------------------------------------------------
# Detection sources


def fed_digest(rows: np.ndarray) -> str:
    """Digest of the detections a tracker was given, ``(N, 5)`` ``frame, x, y, w, h`` in file
    units (1-based) in the order given, rounded to 1e-4 px. The peer scripts compute the same
    (``benchmarks/peers/_sequences.py`` mirrors it), so the
    report shows that every tracker of a source got the same boxes."""
    values = np.round(np.asarray(rows, dtype=np.float64).reshape(-1, 5), 4) + 0.0  # no -0.0
    return hashlib.sha256(np.ascontiguousarray(values).tobytes()).hexdigest()[:16]


def ours_fed_digest(detections: object, frames: int) -> str:
    """:func:`fed_digest` of what ours is handed by ``detections.for_frame`` over ``frames``
    frames (its 0-based boxes moved back to file units)."""
    from tracking.datasets.mot import image_to_mot_boxes

    fed = []
    for index in range(frames):
        boxes = image_to_mot_boxes(detections.for_frame(index).boxes)
        fed.append(np.column_stack([np.full(len(boxes), index + 1.0), boxes]))
    return fed_digest(np.concatenate(fed) if fed else np.zeros((0, 5)))


def _files_sha256(*paths: Path) -> str:
    digest = hashlib.sha256()
    for path in paths:
        with path.open("rb") as file:
            for block in iter(lambda f=file: f.read(1 << 20), b""):
                digest.update(block)
    return digest.hexdigest()


def _model_files(path: Path) -> list[Path]:
    """A model's files: an OpenVINO IR's .xml and .bin, or the one file."""
    weights = path.with_suffix(".bin")
    return [path, weights] if path.suffix.lower() == ".xml" and weights.is_file() else [path]


def _cached(meta: Path, target: Path, key: dict[str, object]) -> tuple[str, bool]:
    """The key's digest, and whether ``target`` was made with it (its ``meta`` says so)."""
    digest = hashlib.sha256(json.dumps(key, sort_keys=True, default=str).encode()).hexdigest()
    try:
        recorded = json.loads(meta.read_text())["key_sha256"]
    except (OSError, ValueError, KeyError, TypeError):
        recorded = None
    return digest, recorded == digest and target.is_file()


def public_source(sequences: Sequence[SequenceInfo]) -> DetectionSource:
    """The public detections ``det/det.txt``: peers get the confidence column as it is, ours
    reads it as the probability (clipped to ``[0, 1]``; 0.5 to 1 in these files)."""
    return DetectionSource(
        "public",
        {s.name: s.det_path for s in sequences},
        None,
        {
            "detections": "public det/det.txt",
            "peers_score": "the file's confidence column as it is",
            "ours_score": "the file's confidence column read as the probability (clipped to "
            "[0, 1]; MotDetections.from_file without calibration)",
        },
    )


def cnn_source(
    sequences: Sequence[SequenceInfo], frames: dict[str, int], model: Path, folder: Path
) -> DetectionSource:
    """The CNN person detector's detections, at confidence >= ``CNN_DETECTION_THRESHOLD``, as
    MOTChallenge files ``<folder>/detections/<sequence>/cnn.txt`` (see :func:`cnn_detection_file`).

    Raises
    ------
    ImportError, ValueError, OSError
        If the detector cannot be made or run.
    """
    from tracking.detection import make_detector
    from tracking.detection.cnn import CnnConfig

    config = dataclasses.replace(CnnConfig(), threshold=CNN_DETECTION_THRESHOLD)
    detector = make_detector(model, config)
    files, made = {}, {}
    for sequence in sequences:
        path, reused, seconds = cnn_detection_file(
            detector, config, model, sequence, frames[sequence.name], folder
        )
        files[sequence.name] = path
        made[sequence.name] = "reused" if reused else f"detected in {seconds:.1f} s"
    calibration = detector.calibration
    return DetectionSource(
        "cnn",
        files,
        calibration,
        {
            "detections": f"CNN {model.stem}, confidence >= {CNN_DETECTION_THRESHOLD}",
            "detector": str(model),
            "detector_options": dataclasses.asdict(config),
            "calibration": None if calibration is None else dataclasses.asdict(calibration),
            "made": made,
            "peers_score": "the network's confidence c in [0, 1] (sigmoid of the Detections' "
            "log-odds scores), as the detection file holds it",
            "ours_score": "the calibrated probability p = calibration(log(c / (1 - c))) of the "
            "file's c, what the detector hands ours_cnn"
            if calibration is not None
            else "the file's confidence (the model has no calibration)",
        },
    )


def cnn_detection_file(
    detector: object,
    config: object,
    model: Path,
    sequence: SequenceInfo,
    frames: int,
    folder: Path,
) -> tuple[Path, bool, float]:
    """``<folder>/detections/<sequence>/cnn.txt``: the detector on every frame up to
    ``frames``, one row per detection ``frame, -1, x + 1, y + 1, w, h, c, -1, -1, -1`` (boxes
    1-based to 1/1000 px, ``c`` the network's confidence, the sigmoid of ``Detections.scores``,
    to 1e-6). Reused when ``cnn.json`` beside it records the same key: the model files' SHA-256,
    the configuration, the sequence and the frame count. (path, reused, seconds detecting)."""
    target = folder / "detections" / sequence.name / "cnn.txt"
    meta = target.with_suffix(".json")
    key = {
        "model": str(model),
        "model_sha256": _files_sha256(*_model_files(model)),
        "config": dataclasses.asdict(config),
        "sequence": str(sequence.path),
        "frames": frames,
    }
    digest, reused = _cached(meta, target, key)
    if reused:
        return target, True, 0.0
    lines = []
    start = time.perf_counter()
    progress = tqdm(
        range(frames), desc=f"cnn {sequence.name}", unit="frame", file=sys.stderr, leave=False,
        disable=None,
    )  # fmt: skip
    for index in progress:
        found = detector.detect(read_rgb(sequence.frame_paths[index]))
        confidence = 1.0 / (1.0 + np.exp(-np.asarray(found.scores, dtype=np.float64)))
        for (x, y, w, h), c in zip(found.boxes, confidence, strict=True):
            lines.append(f"{index + 1},-1,{x + 1:.3f},{y + 1:.3f},{w:.3f},{h:.3f},{c:.6f},-1,-1,-1")
    seconds = time.perf_counter() - start
    target.parent.mkdir(parents=True, exist_ok=True)
    partial = target.with_suffix(".txt.partial")
    partial.write_text("".join(f"{line}\n" for line in lines))
    partial.replace(target)
    meta.write_text(
        json.dumps({"key_sha256": digest, **key, "rows": len(lines)}, indent=1, default=str)
    )
    return target, False, seconds


def ours_detections(source: DetectionSource, sequence: SequenceInfo) -> object:
    """The detections ours gets from ``source``: :class:`MotDetections` of the same file (0-based
    boxes), the confidence column read as :attr:`DetectionSource.calibration` says."""
    from tracking.datasets.mot import read_mot_rows as read_rows
    from tracking.detection import MotDetections

    path = source.files[sequence.name]
    if source.calibration is None:
        return MotDetections.from_file(path)
    rows = read_rows(path).copy()  # as MotDetections.from_file reads it
    c = np.clip(rows[:, 6], 1e-6, 1 - 1e-6)
    rows[:, 6] = source.calibration.probability(np.log(c / (1 - c)))
    return MotDetections(rows)


def embeddings_file(
    embedder: object, reid_model: Path, source: DetectionSource, sequence: SequenceInfo,
    frames: int, folder: Path,
) -> tuple[Path, bool, float]:  # fmt: skip
    """``<folder>/detections/<sequence>/<source>.reid.npy``: our re-identification network's
    embedding of every row of the source's detection file (``(rows, D)`` float32, in the file's
    row order; NaN for rows past ``frames`` and boxes it cannot embed). Reused when the
    ``.reid.json`` beside it records the same key: the network's and the detection file's
    SHA-256 and the frame count. (path, reused, seconds embedding)."""
    from tracking.datasets.mot import mot_to_image_boxes
    from tracking.datasets.mot import read_mot_rows as read_rows

    det = source.files[sequence.name]
    target = folder / "detections" / sequence.name / f"{source.name}.reid.npy"
    meta = target.with_name(f"{source.name}.reid.json")
    key = {
        "reid_model": str(reid_model),
        "reid_model_sha256": _files_sha256(*_model_files(reid_model)),
        "detections": str(det),
        "detections_sha256": _files_sha256(det),
        "frames": frames,
    }
    digest, reused = _cached(meta, target, key)
    if reused:
        return target, True, 0.0
    rows = read_rows(det)
    out = np.full((len(rows), embedder.embedding_size), np.nan, dtype=np.float32)
    start = time.perf_counter()
    progress = tqdm(
        range(frames), desc=f"re-id {source.name} {sequence.name}", unit="frame",
        file=sys.stderr, leave=False, disable=None,
    )  # fmt: skip
    for index in progress:
        picked = np.flatnonzero(rows[:, 0] == index + 1)
        if picked.size:
            frame = read_rgb(sequence.frame_paths[index])
            out[picked] = embedder.embed(frame, mot_to_image_boxes(rows[picked, 2:6]))
    seconds = time.perf_counter() - start
    target.parent.mkdir(parents=True, exist_ok=True)
    with target.with_suffix(".partial").open("wb") as file:
        np.save(file, out)
    target.with_suffix(".partial").replace(target)
    meta.write_text(json.dumps({"key_sha256": digest, **key}, indent=1, default=str))
    return target, False, seconds


def prepare_sources(
    args: argparse.Namespace, outcome: Outcome, folder: Path, names: Sequence[str]
) -> None:
    """``outcome.sources`` of ``names``; a source that cannot be made is left out with a note."""
    for name in names:
        if name == "public":
            outcome.sources[name] = public_source(outcome.sequences)
            continue
        problem = cnn_model_problem(args.cnn_model)
        if problem is not None:
            outcome.notes.append(f"note: the cnn detections are left out: {problem} (--cnn-model)")
            continue
        print(f"cnn detections ({args.cnn_model.stem}) ...", file=sys.stderr)
        try:
            outcome.sources[name] = cnn_source(
                outcome.sequences, outcome.frames, args.cnn_model, folder
            )
        except (ImportError, ValueError, OSError) as exc:
            outcome.notes.append(f"note: the cnn detections are left out: {exc}")


def prepare_embeddings(args: argparse.Namespace, outcome: Outcome, folder: Path) -> bool:
    """Every source's embeddings for the re-id peers (:func:`embeddings_file`); False (and a
    note) if they cannot be made."""
    try:
        from tracking.detection.reid import ReidEmbedder

        embedder = ReidEmbedder.from_file(args.reid_model)
        for source in outcome.sources.values():
            made = {}
            for sequence in outcome.sequences:
                path, reused, seconds = embeddings_file(
                    embedder, args.reid_model, source, sequence, outcome.frames[sequence.name],
                    folder,
                )  # fmt: skip
                source.embeddings[sequence.name] = path
                made[sequence.name] = "reused" if reused else f"embedded in {seconds:.1f} s"
            source.details["reid_embeddings"] = {"model": str(args.reid_model), "made": made}
    except (ImportError, ValueError, OSError) as exc:
        outcome.notes.append(f"note: re-id peers skipped: no embeddings: {exc}")
        return False
    return True


# --------------------------------------------------------------------------------------------
# Peers


def run_peers(
    python: Path,
    kinds: Sequence[str],
    outcome: Outcome,
    source: DetectionSource,
    repeats: int,
    frames: int | None,
    frame_rate: str,
) -> None:
    """Run each peer over all sequences on ``source`` in its environment (one process per peer
    and source): Roboflow's trackers with ``mot_trackers.py``, BoxMOT's with
    ``reid_trackers.py`` (and the source's embeddings)."""
    folders = [str(s.path) for s in outcome.sequences]
    for kind in kinds:
        reid = kind in REID_PEERS
        name = row_name(kind, source.name)
        script = REID_SCRIPT if reid else PEER_SCRIPT
        command = [str(python), str(script), kind, *folders, "--repeats", str(repeats)]
        command += ["--frame-rate", frame_rate]
        for sequence in outcome.sequences:
            command += ["--det", str(source.files[sequence.name])]
            if reid:
                command += ["--embeddings", str(source.embeddings[sequence.name])]
        if frames is not None:
            command += ["--frames", str(frames)]
        print(f"running {name} ...", file=sys.stderr)
        completed = subprocess.run(command, stdout=subprocess.PIPE, text=True, check=False)
        try:
            report = json.loads(completed.stdout) if completed.returncode == 0 else None
        except ValueError:
            report = None
        if report is None:
            for sequence in outcome.sequences:
                outcome.fail(name, sequence.name, f"peer script exited with {completed.returncode}")
            continue
        outcome.details[name] = {
            "source": "boxmot" if reid else "trackers",
            "family": "peer",
            "base": kind,
            "detection_source": source.name,
            "class": report["class"],
            "detections": source.details["detections"],
            "score": source.details["peers_score"],
            "versions": report["versions"],
            "params": report["params"],
            "fed_digest": {},
        }
        if reid:
            outcome.details[name]["embeddings"] = report["embeddings"]
        by_name = {s.name: s for s in outcome.sequences}
        for entry in report["sequences"]:
            sequence = entry["name"]
            if "error" in entry:
                outcome.fail(name, sequence, entry["error"])
                continue
            if sequence not in by_name or entry["frames"] != outcome.frames[sequence]:
                outcome.fail(name, sequence, "unexpected sequence or length in the peer's report")
                continue
            outcome.details[name]["fed_digest"][sequence] = entry["fed_digest"]
            if reid:
                outcome.details[name].setdefault("unembedded", {})[sequence] = entry["unembedded"]
            rows = np.asarray(entry["rows"], dtype=np.float64).reshape(-1, 7)
            run = Run(rows, entry["seconds"], entry["frames"], entry["deterministic"])
            outcome.add(name, sequence, run)


def aspect_rows(rows: np.ndarray, aspect: float) -> np.ndarray:
    """Result rows (``frame, id, x, y, w, h, ...``) with our tracker's box post-processing:
    each box set to width ``aspect * h`` about its centre, its height kept. The rule is ours,
    imported (``tracking.people.motion.with_aspect``, what ``MultiPersonTracker`` reports
    with ``box_aspect``), not a copy. It moves no centre, so it is the same in 1-based file
    units as in the tracker's 0-based ones."""
    from tracking.people import motion

    out = np.array(rows, dtype=np.float64, copy=True).reshape(-1, np.shape(rows)[-1])
    if len(out):
        out[:, 2:6] = motion.with_aspect(out[:, 2:6], aspect)
    return out


def add_parity_rows(outcome: Outcome, aspect: float) -> None:
    """Every peer run ``<peer>@<source>`` again as ``<peer>+aspect@<source>``: its rows through
    :func:`aspect_rows` (the tracking, its time and its ids unchanged)."""
    peers = [
        t
        for t, d in outcome.details.items()
        if d.get("family") == "peer" and "postprocess" not in d and t in outcome.runs
    ]
    for tracker in peers:
        details = outcome.details[tracker]
        name = row_name(details["base"] + ASPECT, details["detection_source"])
        outcome.details[name] = {
            **details,
            "base": details["base"] + ASPECT,
            "of": tracker,
            "postprocess": f"box width set to {aspect} x height about its centre, height kept "
            "(tracking.people.motion.with_aspect, ours' box_aspect)",
        }
        for sequence, run in outcome.runs[tracker].items():
            rows = aspect_rows(run.rows, aspect)
            outcome.add(name, sequence, Run(rows, run.seconds, run.frames, run.deterministic))
        for sequence, message in outcome.errors.get(tracker, {}).items():
            outcome.errors.setdefault(name, {})[sequence] = message


@dataclasses.dataclass(frozen=True)
class OurTracker:
    """One of our trackers: how to make a fresh one, and what it runs on."""

    factory: Callable[[], object]
    source: str | None  # the detection source it is fed (None: it runs its own detector)
    details: dict[str, object]
    fill_gaps: float = 0.0  # seconds; the service's job option of that name
    detector: object | None = None  # the detector the trackers get (None: a source's)

    @property
    def end_to_end(self) -> bool:
        return self.source is None


def _frame_key(frame: np.ndarray) -> bytes:
    """Identity of a frame's pixels."""
    digest = hashlib.blake2b(np.ascontiguousarray(frame).data, digest_size=16).digest()
    return digest + repr(frame.shape).encode()


class RecordingDetector:
    """A detector that runs on every frame and keeps its full-frame results by frame content.

    The runs of one end-to-end tracker with different particle-filter seeds see the same frames
    and detection is a pure function of the frame: the first run records, the others replay
    (:class:`ReplayedDetector`; the DPM costs 2 s per frame, the tracker 10 ms). Every call of
    the recording run detects, so its timed repeats include the detector (and the key, a hash of
    the frame's pixels: 1.4 ms on a PETS frame, 2% of the embedded detector's time, 0.1% of the
    DPM's). Region-of-interest and dense-score calls go to the detector itself.
    """

    def __init__(self, make: Callable[[], object]) -> None:
        self._make = make
        self._detector: object | None = None
        self.seen: dict[bytes, object] = {}

    @property
    def detector(self) -> object:
        if self._detector is None:
            self._detector = self._make()
        return self._detector

    def detect(self, frame: np.ndarray) -> object:
        found = self.seen[_frame_key(frame)] = self.detector.detect(frame)
        return found

    def __getattr__(self, name: str) -> object:  # part_names, calibration, detect_region...
        return getattr(self.detector, name)


class ReplayedDetector:
    """The recorded results of a :class:`RecordingDetector`; frames it has not seen are
    detected (and recorded) anew."""

    def __init__(self, recorder: RecordingDetector) -> None:
        self._recorder = recorder

    def detect(self, frame: np.ndarray) -> object:
        found = self._recorder.seen.get(_frame_key(frame))
        return self._recorder.detect(frame) if found is None else found

    def __getattr__(self, name: str) -> object:
        return getattr(self._recorder, name)


def build_ours(
    names: Sequence[str],
    dpm: Path,
    seeds: int = 1,
    dpm_config: object | None = None,
    hog_config: object | None = None,
    tracker_config: object | None = None,
    fill_gaps: float = 0.0,
    cnn_model: Path = DEFAULT_CNN_MODEL,
    sources: Sequence[str] = ("public",),
    parity: bool = False,
    reid_model: Path | None = None,
) -> dict[str, OurTracker]:
    """Our trackers by row name: ``MultiPersonTracker`` with the default configuration on each
    detection source of ``sources`` (``ours@public``, ``ours@cnn``; with ``parity`` also
    ``ours+detbox@<source>``, the same with ``box_aspect=None``: it reports the associated
    detections' smoothed aspect instead of 0.41), or with its own detector (``ours_hog``,
    ``ours_dpm``, ``ours_cnn``: the CNN detector on the network ``cnn_model`` with the
    ``CnnConfig`` defaults, as a service job runs it; the model loads on first use, like the
    DPM's). With ``seeds`` above 1, each also runs with the particle filter's seeds 1, 2...
    (``ours_seed1@public``, ``ours_dpm_seed1``...): the scores of a particle filter vary with
    its random draws, and one seed would hide by how much. The seeded end-to-end runs replay the
    detections of the first run (:class:`ReplayedDetector`), so their speed is the tracker's
    alone. ``dpm_config`` and
    ``hog_config``: a ``DpmConfig`` for ``ours_dpm`` (default: ``DPM_TRACKING_CONFIG``, the
    DPM's operating point for tracking) and a ``HogPeopleConfig`` for ``ours_hog`` (default:
    the embedded defaults); ``tracker_config``: a ``PeopleTrackerConfig`` for all of ours
    (default: the defaults); ``fill_gaps``: seconds of the results' gaps to fill
    (:class:`tracking.gap_filling.GapFiller`, the service's ``fill_gaps``; 0: none);
    ``reid_model``: a re-identification network with which ours also runs as a service job
    with the model installed runs it (``ours+reid@<source>``, ``ours+detbox+reid@<source>``:
    the tracker embeds each frame's detections itself).

    ``tracking.people`` and ``tracking.detection`` are imported here, not at module level, so
    the harness also runs with the peers only while they are missing.

    Raises
    ------
    ImportError
        If ``tracking.people`` cannot be imported.
    """
    from tracking.detection import DPM_TRACKING_CONFIG, make_detector
    from tracking.detection.cnn import CnnConfig
    from tracking.people import MultiPersonTracker, PeopleTrackerConfig

    config = tracker_config or PeopleTrackerConfig()
    recorded = {"fill_gaps": fill_gaps}
    variants = [(OURS, config)]
    if parity and config.box_aspect is not None:  # else ours already reports the detections'
        variants.append((OURS + DETBOX, dataclasses.replace(config, box_aspect=None)))
    reid = None
    if reid_model is not None:
        from tracking.detection.reid import ReidEmbedder

        reid = ReidEmbedder.from_file(reid_model)
    networks = [("", None)] + ([(REID, reid)] if reid is not None else [])
    out: dict[str, OurTracker] = {}
    if OURS in names:
        for source in sources:
            for (base, variant), (suffix, embedder) in itertools.product(variants, networks):
                for seed in range(seeds):
                    seeded = dataclasses.replace(variant, seed=seed)
                    used = {
                        "family": "ours",
                        "base": base + suffix,
                        "detection_source": source,
                        "detections": source,
                        **recorded,
                        "config": dataclasses.asdict(seeded),
                        "reid_model": str(reid_model) if embedder is not None else None,
                    }
                    out[row_name(base + suffix, source, seed)] = OurTracker(
                        lambda c=seeded, r=embedder: MultiPersonTracker(c, detector=None, reid=r),
                        source,
                        {**used, "seed": seed} if seed else used,
                        fill_gaps,
                    )
    detectors = {
        "ours_hog": (
            "default",
            hog_config,
            {"detections": "embedded HOG", "detector": "default"},
        ),
        "ours_dpm": (
            dpm,
            dpm_config or DPM_TRACKING_CONFIG,
            {"detections": "DPM", "detector": str(dpm)},
        ),
        "ours_cnn": (
            cnn_model,
            CnnConfig(),
            {"detections": f"CNN {Path(cnn_model).stem}", "detector": str(cnn_model)},
        ),
    }
    for name in [n for n in names if n in detectors]:
        model, options, details = detectors[name]
        details = {"family": "ours", "base": name, "detection_source": None, **details}
        options_used = dataclasses.asdict(options) if options else {}
        details = {**details, **recorded, "detector_options": options_used}
        recorder = RecordingDetector(lambda m=model, o=options: make_detector(m, o))
        # as a service job: the CNN's tracks keep its boxes' shape (service.pipelines)
        own = dataclasses.replace(config, box_aspect=None) if name == "ours_cnn" else config
        for seed in range(seeds):
            seeded = dataclasses.replace(own, seed=seed)
            detector = ReplayedDetector(recorder) if seed else recorder
            # the configuration the run uses, its seed included, is the one reported
            used = {**details, "config": dataclasses.asdict(seeded)}
            out[row_name(name, None, seed)] = OurTracker(
                lambda c=seeded, d=detector: MultiPersonTracker(c, detector=d),
                None,
                {**used, "seed": seed} if seed else used,
                fill_gaps,
                detector,
            )
    return out


def detector_calibration(detector: object | None) -> dict[str, object] | None:
    """The score calibration ``detector`` ran with (``a``, ``b``, ``source``), or None.

    Part of what an end-to-end run measured: the tracker weighs detections by their calibrated
    probability, and a model's calibration can change between runs (a fitted file beside it,
    ``KNOWN_CALIBRATIONS`` refitted). Ask only after the detector has run: a
    :class:`RecordingDetector` makes its detector on first use.
    """
    calibration = None if detector is None else getattr(detector, "calibration", None)
    if calibration is None or not dataclasses.is_dataclass(calibration):
        return None
    return dataclasses.asdict(calibration)


def public_detections(sequence: SequenceInfo) -> object:
    """The sequence's ``det/det.txt`` as :class:`MotDetections` (0-based boxes)."""
    return ours_detections(public_source([sequence]), sequence)


def read_rgb(path: Path) -> np.ndarray:
    image = cv2.imread(str(path), cv2.IMREAD_COLOR)
    if image is None:
        raise MotFileError(f"cannot decode {path}")
    return cv2.cvtColor(image, cv2.COLOR_BGR2RGB)


def track_ours(
    ours: OurTracker,
    sequence: SequenceInfo,
    frames: int,
    progress: tqdm,
    keep_estimates: bool,
    detections: object | None = None,
) -> tuple[np.ndarray, float, list[FrameTracks] | None]:
    """One run of a fresh tracker on ``detections`` (a :class:`MotDetections`; None for an
    end-to-end tracker): result rows, seconds in ``update``, estimates if kept."""
    from tracking.gap_filling import GapFiller

    if (detections is None) != ours.end_to_end:
        raise ValueError("a tracker fed a detection source needs its detections, and only it")
    tracker = ours.factory()
    filler = GapFiller(ours.fill_gaps) if ours.fill_gaps > 0 else None
    rows = []
    estimates: list[FrameTracks] | None = [] if keep_estimates else None
    seconds = 0.0
    for index in range(frames):
        frame = read_rgb(sequence.frame_paths[index])
        current = detections.for_frame(index) if detections is not None else None
        timestamp = sequence.timestamp(index)
        start = time.perf_counter()
        tracks = tracker.update(frame, timestamp, current)  # a fresh tracker: frame `index`
        seconds += time.perf_counter() - start  # fps: update calls only, as the table says
        # filled frames' rows come after later frames' rows: the file is sorted when written
        filled = filler.push(tracks) if filler else []
        rows.append(frame_rows(tracks)[:, :7])
        rows += [frame_rows(f)[:, :7] for f in filled]
        if estimates is not None:
            estimates.append(tracks)
        progress.update(1)
    return np.concatenate(rows) if rows else np.zeros((0, 7)), seconds, estimates


def run_ours(
    ours: dict[str, OurTracker],
    outcome: Outcome,
    repeats: int,
    end_to_end_repeats: int,
    picture_sequence: str | None,
) -> None:
    given: dict[tuple[str, str], object] = {}  # (source, sequence) -> MotDetections
    for name, tracker in ours.items():
        outcome.details[name] = {"source": "ours", **tracker.details}
        if not tracker.end_to_end:
            source = outcome.sources[tracker.source]
            outcome.details[name]["detections"] = source.details["detections"]
            outcome.details[name]["score"] = source.details["ours_score"]
            outcome.details[name]["fed_digest"] = {}
        count = end_to_end_repeats if tracker.end_to_end else repeats
        total = count * sum(outcome.frames.values())
        progress = tqdm(
            total=total, desc=name, unit="frame", file=sys.stderr, leave=False, disable=None
        )
        with progress as bar:
            for sequence in outcome.sequences:
                bar.set_postfix_str(sequence.name)
                frames = outcome.frames[sequence.name]
                keep = sequence.name == picture_sequence
                try:
                    detections = None
                    if not tracker.end_to_end:
                        key = (tracker.source, sequence.name)
                        if key not in given:
                            given[key] = ours_detections(outcome.sources[key[0]], sequence)
                        detections = given[key]
                        digest = ours_fed_digest(detections, frames)
                        outcome.details[name]["fed_digest"][sequence.name] = digest
                    runs = [
                        track_ours(tracker, sequence, frames, bar, keep and k == 0, detections)
                        for k in range(count)
                    ]
                except Exception as exc:  # one broken run must not stop the benchmark
                    outcome.fail(name, sequence.name, f"{type(exc).__name__}: {exc}")
                    continue
                rows = runs[0][0]
                same = all(r.shape == rows.shape and np.array_equal(r, rows) for r, _, _ in runs)
                run = Run(rows, [s for _, s, _ in runs], frames, same, runs[0][2])
                outcome.add(name, sequence.name, run)
                print(
                    f"{name} {sequence.name}: {frames} frames, {run.fps:.1f} fps", file=sys.stderr
                )
        calibration = detector_calibration(tracker.detector) if name in outcome.runs else None
        if calibration is not None:
            outcome.details[name]["calibration"] = calibration


# --------------------------------------------------------------------------------------------
# Scoring


def write_results(outcome: Outcome, folder: Path) -> None:
    """Every run's rows to ``folder/<tracker>/<sequence>.txt``."""
    for tracker, runs in outcome.runs.items():
        for name, run in runs.items():
            write_mot_file(folder / tracker / f"{name}.txt", run.rows)


def prepare_ground_truth(outcome: Outcome, folder: Path) -> None:
    """``folder/<sequence>/gt/gt.txt``: each ground truth cut to the frames that were run."""
    for sequence in outcome.sequences:
        rows = read_mot_rows(sequence.gt_path, min_columns=6)  # file units, written back as is
        rows = limit_frames(rows, outcome.frames[sequence.name])
        target = folder / sequence.name / "gt" / "gt.txt"
        target.parent.mkdir(parents=True)
        # gt rows as they are (flag, class, visibility columns kept)
        text = "\n".join(",".join(f"{v:g}" for v in row) for row in rows)
        target.write_text(text + "\n" if text else "")


def run_trackeval(python: Path, outcome: Outcome, results: Path) -> dict[str, object]:
    """TrackEval's figures for every tracker that ran on every sequence.

    Raises
    ------
    RuntimeError
        If the scoring script fails.
    """
    trackers = [t for t, runs in outcome.runs.items() if len(runs) == len(outcome.sequences)]
    partial = [t for t in outcome.runs if t not in trackers]
    for tracker in partial:
        outcome.notes.append(f"note: {tracker} is not scored: it did not run on every sequence")
    if not trackers:
        return {"trackers": {}, "errors": {}}
    gt = Path(tempfile.mkdtemp(prefix="vtrack-mot-gt-"))
    try:
        prepare_ground_truth(outcome, gt)
        command = [str(python), str(SCORE_SCRIPT), "--gt", str(gt), "--results", str(results)]
        for sequence in outcome.sequences:
            command += ["--sequence", f"{sequence.name}:{outcome.frames[sequence.name]}"]
        for tracker in trackers:
            command += ["--tracker", tracker]
        completed = subprocess.run(command, stdout=subprocess.PIPE, text=True, check=False)
    finally:
        shutil.rmtree(gt, ignore_errors=True)
    if completed.returncode != 0:
        raise RuntimeError(f"TrackEval exited with code {completed.returncode}")
    return json.loads(completed.stdout)


def best_peers(figures: dict[str, dict[str, object]]) -> dict[str, dict[str, object]]:
    """Per compared metric and fps, the best peer and its value among ``figures`` (peer ->
    figures of one sequence); fewest is best for IDSW."""
    best: dict[str, dict[str, object]] = {}
    for metric in [*COMPARED, "fps"]:
        values = {t: float(v[metric]) for t, v in figures.items() if metric in v}
        if not values:
            continue
        pick = min if metric in LOWER_IS_BETTER else max
        tracker = pick(values, key=values.__getitem__)
        best[metric] = {"tracker": tracker, "value": values[tracker]}
    return best


def versus_best(ours: dict[str, object], best: dict[str, dict[str, object]]) -> dict[str, float]:
    """Ours minus the best peer per metric; for fps the ratio ``fps_ratio``."""
    out: dict[str, float] = {}
    for metric, reference in best.items():
        if metric not in ours:
            continue
        if metric == "fps":
            out["fps_ratio"] = float(ours["fps"]) / max(float(reference["value"]), 1e-12)
        else:
            out[metric] = float(ours[metric]) - float(reference["value"])
    return out


def tracker_figures(outcome: Outcome, tracker: str, scores: dict[str, dict]) -> dict[str, dict]:
    """TrackEval's figures and the speed of one tracker, per sequence and combined."""
    runs = outcome.runs[tracker]
    names = [s.name for s in outcome.sequences]
    out: dict[str, dict] = {}
    for name in names:
        if name in runs:
            run = runs[name]
            out[name] = {
                **scores.get(name, {}),
                "fps": run.fps,
                "frames": run.frames,
                "seconds": run.seconds,
                "boxes": len(run.rows),
                "deterministic": run.deterministic,
            }
    if len(names) > 1 and len(runs) == len(names):
        frames = sum(runs[n].frames for n in names)
        seconds = sum(statistics.median(runs[n].seconds) for n in names)
        out[COMBINED] = {
            **scores.get("COMBINED_SEQ", {}),
            "fps": frames / max(seconds, 1e-12),
            "frames": frames,
        }
    return out


def _order(tracker: str, details: dict[str, object], sources: Sequence[str]) -> tuple:
    """Where a row goes in the report: by source (end-to-end last), the peers (their own boxes,
    then ``+aspect``) before ours (then ``+detbox``), by name, by seed."""
    source = details.get("detection_source")
    base = str(details.get("base", tracker))
    plain = base.removesuffix(ASPECT).removesuffix(DETBOX)
    names = [*PEERS, OURS, *END_TO_END]
    return (
        list(sources).index(source) if source in sources else len(sources),
        0 if details.get("family") == "peer" else 1,
        base != plain,
        names.index(plain) if plain in names else len(names),
        details.get("seed", 0),
        tracker,
    )


def compare(
    trackers: dict[str, dict], keys: Sequence[str], source: str, fair: bool
) -> tuple[dict[str, dict], dict[str, dict]]:
    """(best peer per sequence and metric, ours minus it per tracker and sequence) on
    ``source``: among the peers' rows of that source, their ``+aspect`` rows included when
    ``fair``; ours: our rows of that source and the end-to-end ones (seed 0), and the means over
    the seeds (``<base>_mean@<source>``)."""
    peers = [
        t
        for t, d in trackers.items()
        if d.get("family") == "peer"
        and d.get("detection_source") == source
        and (fair or "postprocess" not in d)
    ]
    ours: dict[str, list[str]] = {}  # base row name -> its seeded rows
    for tracker, details in trackers.items():
        if details.get("family") == "ours" and details.get("detection_source") in (source, None):
            base = row_name(str(details["base"]), details.get("detection_source"))
            ours.setdefault(base, []).append(tracker)
    best: dict[str, dict] = {}
    versus: dict[str, dict[str, dict[str, float]]] = {}
    for key in keys:
        figures = {
            t: trackers[t]["sequences"][key] for t in peers if key in trackers[t]["sequences"]
        }
        if not figures:
            continue
        best[key] = best_peers(figures)
        for base, rows in ours.items():
            first = trackers.get(base, {}).get("sequences", {}).get(key)
            if first:
                versus.setdefault(base, {})[key] = versus_best(first, best[key])
            seeded = [
                trackers[t]["sequences"][key] for t in rows if key in trackers[t]["sequences"]
            ]
            if len(seeded) > 1:  # the mean over the particle filter's seeds
                numbers = [m for m, v in seeded[0].items() if isinstance(v, (int, float))]
                mean = {m: float(np.mean([r[m] for r in seeded])) for m in numbers}
                name, _, at = base.partition("@")
                mean_name = f"{name}_mean@{at}" if at else f"{name}_mean"
                versus.setdefault(mean_name, {})[key] = versus_best(mean, best[key])
    return best, versus


def summarize(outcome: Outcome, scored: dict[str, object], results: Path) -> dict[str, object]:
    """All figures as one JSON-ready dict: per tracker and sequence, best peers, differences."""
    scores: dict[str, dict] = scored.get("trackers", {})
    sources = list(outcome.sources)
    order = sorted(outcome.runs, key=lambda t: _order(t, outcome.details.get(t, {}), sources))
    trackers = {
        t: {
            **outcome.details.get(t, {}),
            "sequences": tracker_figures(outcome, t, scores.get(t, {})),
        }
        for t in order
    }
    keys = [s.name for s in outcome.sequences] + ([COMBINED] if len(outcome.sequences) > 1 else [])
    best: dict[str, dict] = {}
    versus: dict[str, dict] = {}
    best_raw: dict[str, dict] = {}
    versus_raw: dict[str, dict] = {}
    for source in sources:
        best[source], versus[source] = compare(trackers, keys, source, fair=True)
        best_raw[source], versus_raw[source] = compare(trackers, keys, source, fair=False)
    errors = {t: dict(e) for t, e in outcome.errors.items()}
    for tracker, message in scored.get("errors", {}).items():
        errors.setdefault(tracker, {})["trackeval"] = message
    return {
        "sequences": {
            s.name: {
                "frames": outcome.frames[s.name],
                "frame_rate": s.frame_rate,
                "path": str(s.path),
            }
            for s in outcome.sequences
        },
        "protocol": {
            "detections": "every tracker <name>@<source> runs on the same detection file of its "
            "source (public: det/det.txt; cnn: our CNN detector's, run once per sequence); "
            "ours_hog, ours_dpm and ours_cnn run their own detector",
            "box_parity": "<peer>+aspect@<source>: the peer's rows with our box post-processing "
            "(width = box_aspect x height about the centre); ours+detbox@<source>: ours with "
            "box_aspect=None (the detections' smoothed aspect)",
            "comparison": "best_peer / ours_vs_best_peer: the best of the peers' rows of each "
            "source, their +aspect rows included (the fair comparison); best_raw_peer / "
            "ours_vs_best_raw_peer: the peers' own boxes only",
            "coordinates": "MOTChallenge files are 1-based; ours gets 0-based boxes and writes "
            "1-based ones; the peers keep the file's",
            "trackeval": {k: v for k, v in scored.items() if k in ("trackeval", "config")},
            "scores": "percent; HOTA, DetA, AssA are means over IoU 0.05..0.95, MOTA, IDF1 and "
            "the counts at IoU 0.5",
            "fps": "frames / (median over repeats of the seconds in update calls)",
        },
        "sources": {
            name: {**source.details, "files": {k: str(v) for k, v in source.files.items()}}
            for name, source in outcome.sources.items()
        },
        "trackers": trackers,
        "best_peer": best,
        "ours_vs_best_peer": versus,
        "best_raw_peer": best_raw,
        "ours_vs_best_raw_peer": versus_raw,
        "results_dir": str(results),
        "errors": errors,
        "notes": outcome.notes,
    }


# --------------------------------------------------------------------------------------------
# Report


def _cell(value: object, digits: int, width: int, signed: bool = False) -> str:
    if value is None:
        return f"{'-':>{width}}"
    sign = "+" if signed else ""
    return f"{float(value):>{sign}{width}.{digits}f}"


def format_table(report: dict[str, object]) -> str:
    """The readable report: one line per tracker and sequence, then ours against the best peer."""
    sequences: dict[str, dict] = report["sequences"]
    trackers: dict[str, dict] = report["trackers"]
    keys = [*sequences, COMBINED] if len(sequences) > 1 else list(sequences)
    width = max([len(n) for n in trackers] + [len(k) for k in keys] + [8])
    frames = sum(s["frames"] for s in sequences.values())
    header = "".join(f" {h:>6}" for _, h, _ in TABLE)
    lines = [
        f"MOT: {len(sequences)} sequences, {frames} frames. <tracker>@<source>: every tracker "
        "of a source on the same detections (public: det/det.txt; cnn: our CNN detector's); "
        "<peer>+aspect: the peer's boxes with our post-processing (width 0.41 x height about "
        "the centre); ours+detbox: ours reporting the detections' aspect; ours_hog, ours_dpm, "
        "ours_cnn run their own detector. Scores by TrackEval (HOTA, DetA, AssA over IoU "
        "0.05..0.95; MOTA, IDF1, counts at IoU 0.5), in percent. fps: update calls only, "
        "median of the repeats (re-id peers: without the re-id network, which ran before).",
        "",
        f"{'tracker':<{width}}  {'sequence':<{width}} {header} {'fps':>8}",
    ]
    for tracker, entry in trackers.items():
        for key in keys:
            v = entry["sequences"].get(key)
            if v is None:
                continue
            cells = "".join(f" {_cell(v.get(k), d, 6)}" for k, _, d in TABLE)
            lines.append(f"{tracker:<{width}}  {key:<{width}} {cells} {v['fps']:8.1f}")
        for name, message in report["errors"].get(tracker, {}).items():
            lines.append(f"{tracker:<{width}}  {name:<{width}}  error: {message}")
        lines.append("")
    for tracker, failures in report["errors"].items():
        if tracker not in trackers:  # failed on every sequence
            lines += [f"{tracker}: {name}: {message}" for name, message in failures.items()]

    for source in report["best_peer"]:
        for fair in (True, False):
            lines += comparison_lines(report, source, fair, width)
    lines.append(f"result files: {report['results_dir']}")
    if report["notes"]:
        lines += ["", *report["notes"]]
    return "\n".join(lines)


def comparison_lines(report: dict[str, object], source: str, fair: bool, width: int) -> list[str]:
    """The block of ours against the best peer on ``source`` (``fair``: the peers' ``+aspect``
    rows included), one column per row of ours (named without ``@<source>``)."""
    best: dict[str, dict] = report["best_peer" if fair else "best_raw_peer"].get(source, {})
    versus: dict[str, dict] = report["ours_vs_best_peer" if fair else "ours_vs_best_raw_peer"]
    versus = versus.get(source, {})
    ours = list(versus)
    if not best or not ours:
        return []
    labels = [t.removesuffix(f"@{source}") for t in ours]
    column = max([10, *(len(label) for label in labels)])
    what = (
        "the best of the peers' rows and their +aspect rows (our box post-processing): the "
        "fair comparison"
        if fair
        else "the best of the peers' own boxes (raw)"
    )
    lines = [
        f"Ours against the best peer on the {source} detections: {what} (ours - best, in "
        "points; IDSW: ours - fewest; fps: ours / fastest peer)",
        f"{'sequence':<{width}}  {'metric':<6} {'best peer':>{width + 8}}  "
        + " ".join(f"{label:>{column}}" for label in labels),
    ]
    for key, metrics in best.items():
        for metric, ref in metrics.items():
            digits = 0 if metric == "IDSW" else 1
            ref_text = f"{ref['value']:.{digits}f} {ref['tracker'].removesuffix(f'@{source}')}"
            cells = []
            for tracker in ours:
                diff = versus[tracker].get(key, {})
                if metric == "fps":
                    ratio = diff.get("fps_ratio")
                    cells.append(f"{'-' if ratio is None else f'x{ratio:.3g}':>{column}}")
                else:
                    cells.append(_cell(diff.get(metric), digits, column, signed=True))
            lines.append(f"{key:<{width}}  {metric:<6} {ref_text:>{width + 8}}  " + " ".join(cells))
        lines.append("")
    return lines


# --------------------------------------------------------------------------------------------
# Picture

_PALETTE = (
    (230, 25, 75), (60, 180, 75), (255, 225, 25), (0, 130, 200), (245, 130, 48),
    (145, 30, 180), (70, 240, 240), (240, 50, 230), (210, 245, 60), (250, 190, 190),
    (0, 128, 128), (230, 190, 255), (170, 110, 40), (255, 250, 200), (128, 0, 0),
    (170, 255, 195), (128, 128, 0), (255, 215, 180), (0, 0, 128), (255, 255, 255),
)  # fmt: skip


def picture_frame(estimates: list[FrameTracks]) -> int:
    """The frame (0-based) with the most tracks, at least ``PICTURE_TRAIL`` frames in."""
    first = min(PICTURE_TRAIL, len(estimates) - 1)
    counts = [len(e) for e in estimates[first:]]
    return first + int(np.argmax(counts))


def draw_tracks(
    frame: np.ndarray, estimates: list[FrameTracks], index: int, caption: str
) -> np.ndarray:
    """Frame ``index`` (RGB) with its tracks: boxes with ids, trails of the feet over the last
    ``PICTURE_TRAIL`` frames, part centres (filled: visible; hollow: hidden)."""
    canvas = frame.copy()
    current = estimates[index]
    live = {e.track_id for e in current}
    trails: dict[int, list[tuple[int, int]]] = {}
    for past in estimates[max(index - PICTURE_TRAIL, 0) : index + 1]:
        for e in past:
            if e.track_id in live:
                feet = (round(e.box.x + e.box.w / 2), round(e.box.y + e.box.h))
                trails.setdefault(e.track_id, []).append(feet)
    for e in current:
        colour = _PALETTE[e.track_id % len(_PALETTE)]
        points = np.array(trails.get(e.track_id, []), dtype=np.int32)
        if len(points) > 1:
            cv2.polylines(canvas, [points.reshape(-1, 1, 2)], False, colour, 2, cv2.LINE_AA)
        for part in e.parts:
            centre = (round(part.x), round(part.y))
            cv2.circle(canvas, centre, 2, colour, -1 if part.visible else 1, cv2.LINE_AA)
        x0, y0 = round(e.box.x), round(e.box.y)
        x1, y1 = round(e.box.x + e.box.w), round(e.box.y + e.box.h)
        cv2.rectangle(canvas, (x0, y0), (x1, y1), colour, 1 if e.occluded else 2)
        label = str(e.track_id)
        (tw, th), _ = cv2.getTextSize(label, cv2.FONT_HERSHEY_SIMPLEX, 0.45, 1)
        top = max(y0 - th - 4, 0)
        cv2.rectangle(canvas, (x0, top), (x0 + tw + 4, top + th + 4), colour, -1)
        cv2.putText(
            canvas, label, (x0 + 2, top + th + 1), cv2.FONT_HERSHEY_SIMPLEX, 0.45, (0, 0, 0), 1,
            cv2.LINE_AA,
        )  # fmt: skip
    cv2.rectangle(canvas, (0, 0), (canvas.shape[1], 20), (0, 0, 0), -1)
    cv2.putText(
        canvas, caption, (4, 14), cv2.FONT_HERSHEY_SIMPLEX, 0.42, (255, 255, 255), 1, cv2.LINE_AA
    )
    return canvas


def save_picture(image: np.ndarray, path: Path, max_bytes: int = PICTURE_MAX_BYTES) -> int:
    """Save an RGB image as a palette PNG under ``max_bytes`` (shrunk if need be); its size."""
    from PIL import Image  # matplotlib's dependency; only the benchmark draws

    path.parent.mkdir(parents=True, exist_ok=True)
    scale = 1.0
    while True:
        size = (round(image.shape[1] * scale), round(image.shape[0] * scale))
        resized = image if scale == 1.0 else cv2.resize(image, size, interpolation=cv2.INTER_AREA)
        # octree keeps the few saturated drawing colours exact (median cut merges them)
        palette = Image.fromarray(resized).quantize(256, method=Image.Quantize.FASTOCTREE)
        palette.save(path, optimize=True)
        written = path.stat().st_size
        if written <= max_bytes or scale < 0.3:
            return written
        scale *= 0.85


def make_picture(outcome: Outcome, path: Path) -> dict[str, object] | None:
    """Draw our tracks on the picture sequence; what was drawn, or None if nothing could be."""
    sequence = next((s for s in outcome.sequences if s.name == PICTURE_SEQUENCE), None)
    if sequence is None:
        return None
    for tracker in (
        row_name(OURS, "public"),
        row_name(OURS, "cnn"),
        "ours_dpm",
        "ours_cnn",
        "ours_hog",
    ):
        run = outcome.runs.get(tracker, {}).get(sequence.name)
        if run is None or not run.estimates or not any(run.estimates):
            continue
        index = picture_frame(run.estimates)
        detections = outcome.details[tracker]["detections"]
        caption = (
            f"{sequence.name} frame {index + 1}: {tracker} ({detections} detections); trails "
            f"{PICTURE_TRAIL} frames; parts filled = visible, hollow = hidden"
        )
        image = draw_tracks(read_rgb(sequence.frame_paths[index]), run.estimates, index, caption)
        written = save_picture(image, path)
        return {"path": str(path), "tracker": tracker, "frame": index + 1, "bytes": written}
    return None


# --------------------------------------------------------------------------------------------
# Command line


def _names(text: str | None) -> list[str] | None:
    return None if text is None else [n.strip() for n in text.split(",") if n.strip()]


def _sources(text: str) -> tuple[str, ...]:
    """``--detections``: known source names, in their canonical order."""
    names = _names(text) or []
    unknown = [n for n in names if n not in SOURCES]
    if unknown or not names:
        raise argparse.ArgumentTypeError(
            f"unknown detection source {', '.join(unknown) or repr(text)}; choose from "
            f"{', '.join(SOURCES)}"
        )
    return tuple(n for n in SOURCES if n in names)


def _config(kind: str, text: str) -> object:
    """``--dpm-config``, ``--hog-config``, ``--tracker-config``: the JSON object's fields over
    the default configuration of class ``kind`` (for the DPM: ``DPM_TRACKING_CONFIG``)."""
    import tracking.detection
    import tracking.people

    defaults = {
        "DpmConfig": tracking.detection.DPM_TRACKING_CONFIG,
        "HogPeopleConfig": tracking.detection.HogPeopleConfig(),
        "PeopleTrackerConfig": tracking.people.PeopleTrackerConfig(),
    }
    try:
        fields = json.loads(text)
        if not isinstance(fields, dict):
            raise ValueError("expected a JSON object of field names and values")
        return dataclasses.replace(defaults[kind], **fields)
    except (ValueError, TypeError) as error:  # JSONDecodeError is a ValueError
        raise argparse.ArgumentTypeError(f"not a valid {kind}: {error}") from None


def parse_args(argv: Sequence[str] | None) -> argparse.Namespace:
    parser = argparse.ArgumentParser(
        description="Run our multi-person tracker and SORT, ByteTrack, OC-SORT, BoT-SORT, Deep "
        "OC-SORT, StrongSORT on MOTChallenge sequences, each on the same detections, and score "
        "them with TrackEval."
    )
    parser.add_argument(
        "--data", type=Path, default=DEFAULT_DATA, help=f"MOT folder (default {DEFAULT_DATA})"
    )
    parser.add_argument(
        "--sequences",
        nargs="+",
        help="sequence names under --data or MOTChallenge folders (default: all under --data)",
    )
    parser.add_argument(
        "--trackers",
        help=f"comma-separated tracker names, of {', '.join(TRACKERS)} (default: all that the "
        "other options leave in)",
    )
    parser.add_argument(
        "--detections",
        type=_sources,
        metavar="SOURCES",
        help="comma-separated detection sources every tracker runs on, of "
        f"{', '.join(SOURCES)} (default: both; cnn: the --cnn-model network at confidence >= "
        f"{CNN_DETECTION_THRESHOLD}, run once per sequence and kept under --results)",
    )
    parser.add_argument(
        "--parity",
        action=argparse.BooleanOptionalAction,
        default=True,
        help="also the box parity rows: <peer>+aspect@<source> (the peer's boxes with our "
        "box_aspect) and ours+detbox@<source> (ours with box_aspect=None) (default on)",
    )
    parser.add_argument(
        "--no-ours-reid",
        action="store_true",
        help="no ours+reid rows (ours with the --reid-model network)",
    )
    parser.add_argument("--frames", type=int, help="only the first N frames of every sequence")
    parser.add_argument(
        "--repeats", type=int, default=3, help="timed runs per tracker and sequence (default 3)"
    )
    parser.add_argument(
        "--seeds",
        type=int,
        default=4,
        help="particle-filter seeds of each of ours (default 4: ours, ours_seed1..3, "
        "ours_dpm_seed1..3...); seeded end-to-end runs replay the first run's detections",
    )
    parser.add_argument(
        "--tracker-config",
        type=lambda text: _config("PeopleTrackerConfig", text),
        help="PeopleTrackerConfig fields for all of ours as JSON, e.g. '{\"report_missing\": 0.6}' "
        "(default: the tracker defaults)",
    )
    parser.add_argument(
        "--fill-gaps",
        type=float,
        default=0.0,
        metavar="SECONDS",
        help="fill our tracks' gaps of at most this long in the results, as the service's "
        "fill_gaps job option does (default 0: none)",
    )
    parser.add_argument(
        "--end-to-end",
        action=argparse.BooleanOptionalAction,
        default=True,
        help="also run ours with its own detectors, HOG, DPM and CNN (default on; the DPM is slow)",
    )
    parser.add_argument(
        "--end-to-end-repeats", type=int, default=1, help="timed end-to-end runs (default 1)"
    )
    parser.add_argument(
        "--dpm", type=Path, default=DEFAULT_DPM, help=f"DPM model (default {DEFAULT_DPM})"
    )
    parser.add_argument(
        "--dpm-config",
        type=lambda text: _config("DpmConfig", text),
        help="DpmConfig fields for ours_dpm as JSON, over DPM_TRACKING_CONFIG, e.g. "
        '\'{"upscale": 1.3, "levels_per_octave": 5}\' (default: DPM_TRACKING_CONFIG)',
    )
    parser.add_argument(
        "--hog-config",
        type=lambda text: _config("HogPeopleConfig", text),
        help="HogPeopleConfig fields for ours_hog as JSON, over the embedded defaults",
    )
    parser.add_argument(
        "--cnn-model",
        type=Path,
        default=DEFAULT_CNN_MODEL,
        metavar="PATH",
        help="network of ours_cnn and of the cnn detections, an OpenVINO IR .xml (its .bin "
        f"beside it) or an .onnx file (default: the product's default, {DEFAULT_CNN_MODEL})",
    )
    parser.add_argument(
        "--reid-model",
        type=Path,
        default=DEFAULT_REID_MODEL,
        metavar="PATH",
        help="our re-identification network, whose embeddings the re-id peers (deepocsort, "
        f"strongsort, botsort_reid) get (default {DEFAULT_REID_MODEL})",
    )
    parser.add_argument(
        "--no-peers", action="store_true", help="skip the peers (SORT, ..., Deep OC-SORT, ...)"
    )
    parser.add_argument(
        "--peer-frame-rate",
        choices=("sequence", "library"),
        default="sequence",
        help="frame_rate given to the peers: the sequence's (default) or the library's 30",
    )
    parser.add_argument(
        "--mot-env",
        type=Path,
        help="virtual environment of the peers and TrackEval, created if needed (.venv-mot)",
    )
    parser.add_argument(
        "--reid-env",
        type=Path,
        help="virtual environment of the re-id peers (BoxMOT, PyTorch), created if needed "
        "(.venv-reid)",
    )
    parser.add_argument(
        "--results",
        type=Path,
        help="folder for the MOTChallenge result files, <tracker>/<sequence>.txt "
        "(default: a new temporary folder)",
    )
    parser.add_argument(
        "--picture",
        type=lambda v: Path(v) if v else None,
        default=None,
        metavar="PNG",
        help=f"write a PNG of our tracks on a {PICTURE_SEQUENCE} frame to this path (default: "
        "no picture)",
    )
    parser.add_argument(
        "--score",
        action=argparse.BooleanOptionalAction,
        default=True,
        help="score the results with TrackEval (default on; --no-score: the result files only, "
        "for a script that scores them itself, as benchmarks/holdout_people.py does)",
    )
    parser.add_argument("--json", action="store_true", help="print one JSON object to stdout")
    parser.add_argument("--list", action="store_true", help="list the tracker names and exit")
    args = parser.parse_args(argv)
    for name in ("frames", "repeats", "seeds", "end_to_end_repeats"):
        value = getattr(args, name)
        if value is not None and value < 1:
            parser.error(f"--{name.replace('_', '-')} must be at least 1, got {value}")
    problem = tracker_problem(args)
    if problem is not None:
        parser.error(problem)
    if args.picture is not None:
        require_drawing(parser, "--picture", "PIL")
    return args


def tracker_problem(args: argparse.Namespace) -> str | None:
    """What is wrong with ``--trackers`` given the other options, or None.

    A tracker asked for by name is run or refused, never dropped: unknown names, and names
    that ``--no-peers``, ``--no-end-to-end`` or a missing ``--dpm``, ``--cnn-model`` or
    ``--reid-model`` model leave out, are argument errors; so is ``--detections cnn`` without
    its model.
    """
    if args.detections is not None and "cnn" in args.detections:
        problem = cnn_model_problem(args.cnn_model)
        if problem is not None:
            return f"--detections asks for cnn but {problem}; give its path with --cnn-model"
    requested = _names(args.trackers)
    if requested is None:  # all: the options choose, and a missing model becomes a note
        return None
    if not requested:
        return f"--trackers names no tracker; choose from {', '.join(TRACKERS)}"
    unknown = [n for n in requested if n not in TRACKERS]
    if unknown:
        return f"unknown tracker {', '.join(unknown)}; choose from {', '.join(TRACKERS)}"
    switched_off = (
        ("--no-peers", PEERS, args.no_peers),
        ("--no-end-to-end", END_TO_END, not args.end_to_end),
    )
    for flag, group, off in switched_off:
        excluded = [n for n in requested if n in group]
        if off and excluded:
            return (
                f"--trackers asks for {', '.join(excluded)}, which {flag} leaves out; "
                "drop one or the other"
            )
    if "ours_dpm" in requested and not args.dpm.is_file():
        return (
            f"--trackers asks for ours_dpm but there is no DPM model at {args.dpm}; give its "
            "path with --dpm"
        )
    if "ours_cnn" in requested:
        problem = cnn_model_problem(args.cnn_model)
        if problem is not None:
            return f"--trackers asks for ours_cnn but {problem}; give its path with --cnn-model"
    reid = [n for n in requested if n in REID_PEERS]
    if reid:
        problem = cnn_model_problem(args.reid_model, "re-identification")
        if problem is not None:
            return (
                f"--trackers asks for {', '.join(reid)} but {problem}; give its path with "
                "--reid-model"
            )
    return None


def cnn_model_problem(path: Path, kind: str = "CNN") -> str | None:
    """Why ``ours_cnn`` (or the cnn detections; ``kind`` "re-identification": the re-id peers'
    embeddings) cannot run the network at ``path`` (not a model file, missing, an IR without
    its weights), or None. Only the files are looked at, so that a bad path is told before
    anything runs; a file OpenVINO cannot read fails ``ours_cnn`` on every sequence."""
    if path.suffix.lower() not in CNN_SUFFIXES:
        return f"{path} is not a {kind} model (an OpenVINO IR .xml or an .onnx file)"
    if not path.is_file():
        return f"there is no {kind} model at {path}"
    weights = path.with_suffix(".bin")
    if path.suffix.lower() == ".xml" and not weights.is_file():
        return f"the {kind} model {path} has no weights {weights.name} beside it"
    return None


def load_sequences(args: argparse.Namespace) -> list[SequenceInfo]:
    """The sequences to run, each with a readable ground truth (raises MotFileError with what
    is wrong)."""
    if args.sequences is None:
        paths = find_mot_sequences(args.data)
    else:
        paths = [Path(s) if Path(s).is_dir() else args.data / s for s in args.sequences]
    sequences = [read_sequence_info(p) for p in paths]
    for sequence in sequences:
        check_ground_truth(sequence)
    names = [s.name for s in sequences]
    duplicates = sorted({n for n in names if names.count(n) > 1})
    if duplicates:
        raise MotFileError(f"two sequences are named {', '.join(duplicates)}")
    return sequences


def check_ground_truth(sequence: SequenceInfo) -> None:
    """Refuse a sequence whose ``gt/gt.txt`` is missing or malformed before anything runs: no
    tracker could be scored on it, and the trackers (the DPM most of all) take long.

    Raises
    ------
    MotFileError
        Naming the file, or its bad line.
    """
    if not sequence.gt_path.is_file():
        raise MotFileError(
            f"{sequence.path} has no ground truth gt/gt.txt, so no tracker can be scored on it"
        )
    read_mot_rows(sequence.gt_path, min_columns=6)  # as prepare_ground_truth will read it


def select(args: argparse.Namespace) -> tuple[list[str], list[str]]:
    """(peers, ours) to run: those of ``--trackers`` (checked by :func:`tracker_problem`), else
    all that ``--no-peers`` and ``--no-end-to-end`` leave in."""
    requested = _names(args.trackers)
    if requested is None:
        requested = [
            *(() if args.no_peers else PEERS),
            OURS,
            *(END_TO_END if args.end_to_end else ()),
        ]
    peers = [n for n in PEERS if n in requested]
    ours = [n for n in (OURS, *END_TO_END) if n in requested]
    return peers, ours


def mot_python(args: argparse.Namespace, outcome: Outcome) -> Path | None:
    """The interpreter of the peers' and TrackEval's environment; None (and a note) if it is
    unavailable."""
    try:  # run as a script: benchmarks/ is on sys.path
        from _mot_env import PeerEnvError, ensure_mot_env
    except ImportError:  # python -m benchmarks.mot from the repository root
        from benchmarks._mot_env import PeerEnvError, ensure_mot_env
    try:
        return ensure_mot_env(*([args.mot_env] if args.mot_env else []))
    except PeerEnvError as exc:
        outcome.notes.append(f"note: peers and TrackEval skipped: {exc}")
        print(f"the MOT environment is unavailable, no peers, no scores: {exc}", file=sys.stderr)
        return None


def parity_aspect(args: argparse.Namespace, outcome: Outcome) -> float | None:
    """The box aspect ours reports (``PeopleTrackerConfig.box_aspect`` of the configuration it
    runs with), which the peers' ``+aspect`` rows get; None (and a note) when ours reports the
    detections' own aspect or cannot be imported."""
    try:
        from tracking.people import PeopleTrackerConfig
    except ImportError as exc:
        outcome.notes.append(f"note: no +aspect rows: tracking.people is unavailable: {exc}")
        return None
    aspect = (args.tracker_config or PeopleTrackerConfig()).box_aspect
    if aspect is None:
        outcome.notes.append("note: no +aspect rows: ours runs with box_aspect None")
    return aspect


def reid_python(args: argparse.Namespace, outcome: Outcome) -> Path | None:
    """The interpreter of the re-id peers' environment (BoxMOT); None (and a note) if it is
    unavailable."""
    try:  # run as a script: benchmarks/ is on sys.path
        from _reid_env import PeerEnvError, ensure_reid_env
    except ImportError:  # python -m benchmarks.mot from the repository root
        from benchmarks._reid_env import PeerEnvError, ensure_reid_env
    try:
        return ensure_reid_env(*([args.reid_env] if args.reid_env else []))
    except PeerEnvError as exc:
        outcome.notes.append(f"note: re-id peers skipped: {exc}")
        print(f"the re-id environment is unavailable, no re-id peers: {exc}", file=sys.stderr)
        return None


def make_ours(
    args: argparse.Namespace, names: list[str], outcome: Outcome
) -> dict[str, OurTracker]:
    """Our trackers of ``names``; those that cannot be made are left out with a note (only in a
    run of all trackers: :func:`tracker_problem` refuses a named ``ours_dpm`` or ``ours_cnn``
    without model)."""
    if "ours_dpm" in names and not args.dpm.is_file():
        outcome.notes.append(f"note: ours_dpm left out: no DPM model at {args.dpm}")
        names = [n for n in names if n != "ours_dpm"]
    cnn_problem = cnn_model_problem(args.cnn_model) if "ours_cnn" in names else None
    if cnn_problem is not None:
        outcome.notes.append(f"note: ours_cnn left out: {cnn_problem} (--cnn-model)")
        names = [n for n in names if n != "ours_cnn"]
    if not names:
        return {}
    try:
        return build_ours(
            names,
            args.dpm,
            args.seeds,
            args.dpm_config,
            args.hog_config,
            args.tracker_config,
            args.fill_gaps,
            args.cnn_model,
            list(outcome.sources),
            args.parity,
            None if args.no_ours_reid or cnn_model_problem(args.reid_model) else args.reid_model,
        )
    except ImportError as exc:
        outcome.notes.append(f"note: our tracker is unavailable (tracking.people: {exc})")
        return {}


def score(
    python: Path | None, outcome: Outcome, results: Path
) -> tuple[dict[str, object], str | None]:
    """TrackEval's figures, and why there are none if so (None when TrackEval ran)."""
    if python is None:
        return {}, "TrackEval's environment is unavailable (see the notes)"
    try:
        return run_trackeval(python, outcome, results), None
    except (RuntimeError, ValueError) as exc:
        outcome.notes.append(f"note: TrackEval failed, no scores: {exc}")
        return {}, f"TrackEval failed ({exc})"


def scored_trackers(report: dict[str, object]) -> list[str]:
    """The trackers with a TrackEval score (HOTA) on at least one sequence."""
    return [
        tracker
        for tracker, entry in report["trackers"].items()
        if any("HOTA" in figures for figures in entry["sequences"].values())
    ]


def list_trackers(args: argparse.Namespace) -> str:
    """``--list``: the detection sources, the tracker names and their report rows, and what each
    of ours tracks on (models: missing or not)."""

    def model(kind: str, path: Path, problem: str | None) -> str:
        return f"{kind} {path}" if problem is None else f"{kind}: {problem}"

    dpm_problem = None if args.dpm.is_file() else f"there is no DPM model at {args.dpm}"
    cnn = model("CNN", args.cnn_model, cnn_model_problem(args.cnn_model))
    detections = {
        "public": "det/det.txt of each sequence",
        "cnn": f"{cnn} at confidence >= {CNN_DETECTION_THRESHOLD}, once per sequence",
    }
    ours = {
        OURS: "each detection source (ours@<source>)",
        "ours_hog": "embedded HOG people detector",
        "ours_dpm": model("DPM", args.dpm, dpm_problem),
        "ours_cnn": cnn,
    }
    reid = cnn_model_problem(args.reid_model, "re-identification")
    width = max(len(n) for n in ours)
    lines = ["detections (--detections): " + ", ".join(SOURCES)]
    lines += [f"  {name:<{width}}  {text}" for name, text in detections.items()]
    lines += [
        "peers: " + ", ".join(MOT_PEERS) + " (Roboflow's trackers)",
        "       " + ", ".join(REID_PEERS) + " (BoxMOT, with "
        + model("our re-identification network", args.reid_model, reid) + ")",
        "ours:  " + ", ".join([OURS, *END_TO_END]),
    ]  # fmt: skip
    lines += [f"  {name:<{width}}  {source}" for name, source in ours.items()]
    lines += [
        "rows per source S: <peer>@S, <peer>+aspect@S (the peer's boxes with our box_aspect), "
        "ours@S, ours+detbox@S (box_aspect=None), and ours_seed<k>@S... for --seeds; the "
        "end-to-end rows ours_hog, ours_dpm, ours_cnn have no source",
    ]
    return "\n".join(lines)


def main(argv: Sequence[str] | None = None) -> int:
    args = parse_args(argv)
    if args.list:
        print(list_trackers(args))
        return 0
    peers, ours_names = select(args)
    try:
        sequences = load_sequences(args)
    except MotFileError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    frames = {s.name: min(len(s), args.frames or len(s)) for s in sequences}
    outcome = Outcome(sequences=sequences, frames=frames)

    results = args.results or Path(tempfile.mkdtemp(prefix="vtrack-mot-results-"))
    python = mot_python(args, outcome)
    if peers or OURS in ours_names:  # the trackers that are fed a detection source
        prepare_sources(args, outcome, results, args.detections or SOURCES)
    mot_peers = [p for p in peers if p in MOT_PEERS]
    if python is not None and mot_peers:
        for source in outcome.sources.values():
            run_peers(python, mot_peers, outcome, source, args.repeats, args.frames,
                      args.peer_frame_rate)  # fmt: skip
    reid_peers = [p for p in peers if p in REID_PEERS]
    if reid_peers and outcome.sources:
        problem = cnn_model_problem(args.reid_model, "re-identification")
        reid = None
        if problem is not None:
            outcome.notes.append(f"note: re-id peers skipped: {problem} (--reid-model)")
        else:
            reid = reid_python(args, outcome)
        if reid is not None and prepare_embeddings(args, outcome, results):
            for source in outcome.sources.values():
                run_peers(reid, reid_peers, outcome, source, args.repeats, args.frames,
                          args.peer_frame_rate)  # fmt: skip
    ours = make_ours(args, ours_names, outcome)
    if args.parity:
        aspect = parity_aspect(args, outcome)
        if aspect is not None:
            add_parity_rows(outcome, aspect)
    picture_sequence = PICTURE_SEQUENCE if args.picture is not None else None
    run_ours(ours, outcome, args.repeats, args.end_to_end_repeats, picture_sequence)
    if not outcome.runs:
        print("error: no tracker produced results", file=sys.stderr)
        for note in outcome.notes:
            print(note, file=sys.stderr)
        return 1

    write_results(outcome, results)
    scored, unscored = score(python, outcome, results) if args.score else ({}, None)
    report = summarize(outcome, scored, results)
    # a run that scored nothing has not measured anything
    if args.score and not scored_trackers(report):
        report["error"] = f"no tracker was scored: {unscored or 'see the notes and errors'}"
    if args.picture is not None:
        drawn = make_picture(outcome, args.picture)
        report["picture"] = drawn
        if drawn is not None:
            print(f"saved {drawn['path']} ({drawn['bytes']} bytes)", file=sys.stderr)

    table = format_table(report)
    if args.json:
        print(table, file=sys.stderr)
        # default=str: a configuration value JSON cannot hold (a path...) is written as text
        print_json(report)
    else:
        print(table)
    if "error" in report:  # after the report, so that it is the last line the user sees
        print(f"error: {report['error']}", file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    with contextlib.suppress(KeyboardInterrupt):
        sys.exit(main())
