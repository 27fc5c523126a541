"""MOT benchmark: our multi-person tracker beside SORT, ByteTrack, OC-SORT and BoT-SORT.

    python benchmarks/mot.py [--data DIR] [--sequences NAME_OR_DIR ...] [--trackers a,b,...]
                             [--frames N] [--repeats R] [--seeds S] [--no-end-to-end]
                             [--no-peers] [--dpm PATH] [--dpm-config JSON] [--hog-config JSON]
                             [--cnn-model PATH] [--tracker-config JSON] [--json]
                             [--picture PNG] [--results DIR] [--list]

Sequences: the MOTChallenge folders under ``--data`` (default ``<repo>/../shared/data/mot`` or
``$VTRACK_SHARED_DATA/mot``: PETS09-S2L1 and TUD-Stadtmitte), or those named by
``--sequences`` (names under ``--data``, or paths of any MOTChallenge-layout folder:
``seqinfo.ini``, ``img1/``, ``gt/gt.txt``, ``det/det.txt``). A sequence without a readable
``gt/gt.txt`` is refused before anything runs: no tracker could be scored on it.

Trackers, all in one run:

* peers ``sort``, ``bytetrack``, ``ocsort``, ``botsort``: Roboflow's ``trackers`` with their
  default parameters (``frame_rate`` set to the sequence's, see
  ``benchmarks/peers/mot_trackers.py``) on the public detections ``det/det.txt``, frame by frame;
  BoT-SORT also gets the frames for its camera-motion compensation. They run in their own
  environment (``.venv-mot``, ``benchmarks/_mot_env.py``) because ``trackers`` pulls
  ``opencv-python`` 5, which would shadow the project's headless OpenCV 4;
* ``ours``: :class:`tracking.people.MultiPersonTracker` with its default configuration on the
  same public detections (``detector=None``; ``update(frame, i / fps, detections)``);
* end to end (``--end-to-end``, the default): ``ours_hog``, the same tracker running the
  embedded HOG people detector (``make_detector("default")``), ``ours_dpm`` running the
  voc-release5 INRIA person DPM (``--dpm``) at its operating point for tracking
  (``DPM_TRACKING_CONFIG``), and ``ours_cnn`` running the CNN person detector
  (``CnnDetector``, ``CnnConfig`` defaults) on ``--cnn-model``, by default Open Model Zoo's
  person-detection-0202 under the shared data's ``models/``: the product's default model, which
  a service job with detector 'auto' runs. The tracker gets no detections and runs its detector
  on the schedule of its configuration. The DPM is slow: ``--no-end-to-end`` skips all three,
  ``--frames N`` shortens every sequence. A missing model (``--dpm``, ``--cnn-model``) leaves
  its tracker out with a note in a run of all trackers, and is an argument error when
  ``--trackers`` names it;
* with ``--seeds S`` (default 4) each of ours also runs with the particle filter's seeds 1 to
  S - 1 (``ours_seed1``, ``ours_cnn_seed1``...), and the comparison with the peers adds the
  mean over the seeds (``ours_mean``...). The seeded end-to-end runs replay the detections of
  the first run, frame by frame (the detector is deterministic), so the detector runs once.

Scores: TrackEval (``benchmarks/peers/trackeval_score.py``, in ``.venv-mot``) on the MOTChallenge
result files written to ``--results`` (default: a new temporary folder, kept and named in the
output), against ``gt/gt.txt`` cut to the frames that were run: HOTA, DetA, AssA (means over the
localisation thresholds 0.05..0.95), MOTA, IDF1, ID switches, MT/ML, FP/FN (IoU 0.5), in percent
and counts, per sequence and over all sequences (TrackEval's combination). TrackEval runs in its
MOT15 mode: every ground-truth row with a non-zero flag (7th column) counts and no result box is
removed as a distractor match; the files here have no classes (8th column -1), which TrackEval's
MOT16/17 preprocessing rejects.

Coordinates: MOTChallenge files are 1-based; our tracker gets the public detections moved to
0-based image coordinates (:class:`tracking.detection.MotDetections` moves them, see
``tracking/detection/sequences.py``) and its boxes are written back 1-based (``track_rows`` in
``tracking/evaluation/mot.py``); the ground truth goes to TrackEval as the file has it. The
peers never look at pixels (BoT-SORT's motion compensation aside, to which a pixel is nothing)
and keep the file's coordinates throughout.

Speed: frames per second of the trackers' ``update`` calls only (not image decoding, file
reading, or building the detections), median over ``--repeats`` runs by fresh trackers (the
end-to-end runs: ``--end-to-end-repeats``, default 1); for the end-to-end runs that includes the
detector, which runs inside ``update`` (except in the seeded end-to-end runs, which replay the
detections). Peers are timed in their own process, ours in this one.

Output: a table per sequence and tracker, then the best peer per metric and the difference of
each of ours to it; ``--json`` prints one JSON object on stdout instead (the table goes to
stderr). ``--picture PNG`` (default: none) draws our tracks on a PETS09-S2L1 frame: boxes with
ids, 20-frame trails, body parts (filled: visible; hollow: hidden); the committed
``docs/images/mot.png`` is made by passing its path (``docs/benchmarks.md``).

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
    estimates_to_rows,
    find_mot_sequences,
    limit_frames,
    read_mot_rows,
    read_sequence_info,
    write_mot_file,
)
from tracking.tracks import TrackEstimate

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
PEER_SCRIPT = Path(__file__).resolve().parent / "peers" / "mot_trackers.py"
SCORE_SCRIPT = Path(__file__).resolve().parent / "peers" / "trackeval_score.py"

PEERS = ("sort", "bytetrack", "ocsort", "botsort")
OURS = "ours"
END_TO_END = ("ours_hog", "ours_dpm", "ours_cnn")
TRACKERS = (*PEERS, OURS, *END_TO_END)
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
    estimates: list[tuple[TrackEstimate, ...]] | None = None

    @property
    def fps(self) -> float:
        return self.frames / max(statistics.median(self.seconds), 1e-12)


@dataclasses.dataclass
class Outcome:
    """Everything measured in one benchmark run."""

    sequences: list[SequenceInfo]
    frames: dict[str, int]
    runs: dict[str, dict[str, Run]] = dataclasses.field(default_factory=dict)
    errors: dict[str, dict[str, str]] = dataclasses.field(default_factory=dict)
    details: dict[str, dict[str, object]] = dataclasses.field(default_factory=dict)
    notes: list[str] = dataclasses.field(default_factory=list)

    def add(self, tracker: str, sequence: str, run: Run) -> None:
        self.runs.setdefault(tracker, {})[sequence] = run

    def fail(self, tracker: str, sequence: str, message: str) -> None:
        self.errors.setdefault(tracker, {})[sequence] = message
        print(f"{tracker} on {sequence} failed: {message}", file=sys.stderr)


def run_peers(
    python: Path,
    kinds: Sequence[str],
    outcome: Outcome,
    repeats: int,
    frames: int | None,
    frame_rate: str,
) -> None:
    """Run each peer over all sequences in the MOT environment (one process per peer)."""
    folders = [str(s.path) for s in outcome.sequences]
    for kind in kinds:
        command = [str(python), str(PEER_SCRIPT), kind, *folders, "--repeats", str(repeats)]
        command += ["--frame-rate", frame_rate]
        if frames is not None:
            command += ["--frames", str(frames)]
        print(f"running {kind} ...", file=sys.stderr)
        completed = subprocess.run(command, stdout=subprocess.PIPE, text=True, check=False)
        try:
            report = json.loads(completed.stdout) if completed.returncode == 0 else None
        except ValueError:
            report = None
        if report is None:
            for sequence in outcome.sequences:
                outcome.fail(kind, sequence.name, f"peer script exited with {completed.returncode}")
            continue
        outcome.details[kind] = {
            "source": "trackers",
            "class": report["class"],
            "detections": "public",
            "versions": report["versions"],
            "params": report["params"],
        }
        by_name = {s.name: s for s in outcome.sequences}
        for entry in report["sequences"]:
            name = entry["name"]
            if "error" in entry:
                outcome.fail(kind, name, entry["error"])
                continue
            if name not in by_name or entry["frames"] != outcome.frames[name]:
                outcome.fail(kind, name, "unexpected sequence or length in the peer's report")
                continue
            rows = np.asarray(entry["rows"], dtype=np.float64).reshape(-1, 7)
            run = Run(rows, entry["seconds"], entry["frames"], entry["deterministic"])
            outcome.add(kind, name, run)


@dataclasses.dataclass(frozen=True)
class OurTracker:
    """One of our trackers: how to make a fresh one, and what it runs on."""

    factory: Callable[[], object]
    public: bool  # fed the public detections (else it runs its own detector)
    details: dict[str, object]
    fill_gaps: float = 0.0  # seconds; the service's job option of that name
    detector: object | None = None  # the detector the trackers get (None: public detections)


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
) -> dict[str, OurTracker]:
    """Our trackers by name: ``MultiPersonTracker`` with the default configuration, on the public
    detections (``ours``) or with its own detector (``ours_hog``, ``ours_dpm``, ``ours_cnn``:
    the CNN detector on the network ``cnn_model`` with the ``CnnConfig`` defaults, as a service
    job runs it; the model loads on first use, like the DPM's). With ``seeds``
    above 1, each also runs with the particle filter's seeds 1, 2... (``ours_seed1``,
    ``ours_dpm_seed1``...): the scores of a particle filter vary with its random draws, and one
    seed would hide by how much. The seeded end-to-end runs replay the detections of the first
    run (:class:`ReplayedDetector`), so their speed is the tracker's alone. ``dpm_config`` and
    ``hog_config``: a ``DpmConfig`` for ``ours_dpm`` (default: ``DPM_TRACKING_CONFIG``, the
    DPM's operating point for tracking) and a ``HogPeopleConfig`` for ``ours_hog`` (default:
    the embedded defaults); ``tracker_config``: a ``PeopleTrackerConfig`` for all of ours
    (default: the defaults); ``fill_gaps``: seconds of the results' gaps to fill
    (:class:`tracking.gap_filling.GapFiller`, the service's ``fill_gaps``; 0: none).

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
    sources = {
        OURS: (None, None, {"detections": "public"}),
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
    out: dict[str, OurTracker] = {}
    for name in names:
        source, options, details = sources[name]
        details = {**details, **recorded}
        if source is not None:
            details["detector_options"] = dataclasses.asdict(options) if options else {}
        recorder = (
            RecordingDetector(lambda s=source, o=options: make_detector(s, o)) if source else None
        )
        for seed in range(seeds):
            seeded = dataclasses.replace(config, seed=seed)
            key = name if seed == 0 else f"{name}_seed{seed}"
            detector = ReplayedDetector(recorder) if recorder is not None and seed else recorder
            # the configuration the run uses, its seed included, is the one reported
            used = {**details, "config": dataclasses.asdict(seeded)}
            out[key] = OurTracker(
                lambda c=seeded, d=detector: MultiPersonTracker(c, detector=d),
                source is None,
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
    from tracking.detection import MotDetections

    return MotDetections.from_file(sequence.det_path)


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
) -> tuple[np.ndarray, float, list[tuple[TrackEstimate, ...]] | None]:
    """One run of a fresh tracker: result rows, seconds in ``update``, estimates if kept."""
    from tracking.gap_filling import GapFiller
    from tracking.tracks import FrameTracks

    detections = public_detections(sequence) if ours.public else None
    tracker = ours.factory()
    filler = GapFiller(ours.fill_gaps) if ours.fill_gaps > 0 else None
    rows = []
    estimates: list[tuple[TrackEstimate, ...]] | None = [] if keep_estimates else None
    seconds = 0.0
    for index in range(frames):
        frame = read_rgb(sequence.frame_paths[index])
        current = detections.for_frame(index) if detections is not None else None
        timestamp = sequence.timestamp(index)
        start = time.perf_counter()
        tracks = tracker.update(frame, timestamp, current)
        seconds += time.perf_counter() - start  # fps: update calls only, as the table says
        # filled frames' rows come after later frames' rows: TrackEval groups rows by frame
        filled = filler.push(FrameTracks(index, timestamp, tuple(tracks))) if filler else []
        rows.append(estimates_to_rows(index, tracks)[:, :7])
        rows += [estimates_to_rows(f.frame_index, f.tracks)[:, :7] for f in filled]
        if estimates is not None:
            estimates.append(tuple(tracks))
        progress.update(1)
    return np.concatenate(rows) if rows else np.zeros((0, 7)), seconds, estimates


def run_ours(
    ours: dict[str, OurTracker],
    outcome: Outcome,
    repeats: int,
    end_to_end_repeats: int,
    picture_sequence: str | None,
) -> None:
    for name, tracker in ours.items():
        outcome.details[name] = {"source": "ours", **tracker.details}
        count = repeats if tracker.public else end_to_end_repeats
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
                    runs = [
                        track_ours(tracker, sequence, frames, bar, keep and k == 0)
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


def summarize(outcome: Outcome, scored: dict[str, object], results: Path) -> dict[str, object]:
    """All figures as one JSON-ready dict: per tracker and sequence, best peers, differences."""
    scores: dict[str, dict] = scored.get("trackers", {})
    trackers = {
        t: {
            **outcome.details.get(t, {}),
            "sequences": tracker_figures(outcome, t, scores.get(t, {})),
        }
        for t in outcome.runs
    }
    keys = [s.name for s in outcome.sequences] + ([COMBINED] if len(outcome.sequences) > 1 else [])
    best: dict[str, dict] = {}
    versus: dict[str, dict[str, dict[str, float]]] = {}
    for key in keys:
        figures = {
            t: trackers[t]["sequences"][key]
            for t in PEERS
            if key in trackers.get(t, {}).get("sequences", {})
        }
        if not figures:
            continue
        best[key] = best_peers(figures)
        for tracker in (OURS, *END_TO_END):
            ours = trackers.get(tracker, {}).get("sequences", {}).get(key)
            if ours:
                versus.setdefault(tracker, {})[key] = versus_best(ours, best[key])
        for base in (OURS, *END_TO_END):
            seeded = [
                trackers[t]["sequences"][key]
                for t in trackers
                if (t == base or t.startswith(f"{base}_seed")) and key in trackers[t]["sequences"]
            ]
            if len(seeded) > 1:  # the mean over the particle filter's seeds
                numbers = [m for m, v in seeded[0].items() if isinstance(v, (int, float))]
                mean = {m: float(np.mean([r[m] for r in seeded])) for m in numbers}
                versus.setdefault(f"{base}_mean", {})[key] = versus_best(mean, best[key])
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
            "detections": "public det/det.txt for the peers and ours; ours_hog, ours_dpm and "
            "ours_cnn run their own detector",
            "coordinates": "MOTChallenge files are 1-based; ours gets 0-based boxes and writes "
            "1-based ones; the peers keep the file's",
            "trackeval": {k: v for k, v in scored.items() if k in ("trackeval", "config")},
            "scores": "percent; HOTA, DetA, AssA are means over IoU 0.05..0.95, MOTA, IDF1 and "
            "the counts at IoU 0.5",
            "fps": "frames / (median over repeats of the seconds in update calls)",
        },
        "trackers": trackers,
        "best_peer": best,
        "ours_vs_best_peer": versus,
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
        f"MOT: {len(sequences)} sequences, {frames} frames. Peers and 'ours' on the public "
        "detections; ours_hog, ours_dpm, ours_cnn run their own detector. Scores by TrackEval "
        "(HOTA, DetA, AssA over IoU 0.05..0.95; MOTA, IDF1, counts at IoU 0.5), in percent. "
        "fps: update calls only, median of the repeats.",
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

    best: dict[str, dict] = report["best_peer"]
    versus: dict[str, dict] = report["ours_vs_best_peer"]
    ours = list(versus)
    if best and ours:
        lines += [
            "Ours against the best peer per metric (ours - best, in points; IDSW: ours - fewest; "
            "fps: ours / fastest peer)",
            f"{'sequence':<{width}}  {'metric':<6} {'best peer':>17}  "
            + " ".join(f"{t:>10}" for t in ours),
        ]
        for key, metrics in best.items():
            for metric, ref in metrics.items():
                digits = 0 if metric == "IDSW" else 1
                ref_text = f"{ref['value']:.{digits}f} {ref['tracker']}"
                cells = []
                for tracker in ours:
                    diff = versus[tracker].get(key, {})
                    if metric == "fps":
                        ratio = diff.get("fps_ratio")
                        cells.append(f"{'-' if ratio is None else f'x{ratio:.3g}':>10}")
                    else:
                        cells.append(_cell(diff.get(metric), digits, 10, signed=True))
                lines.append(f"{key:<{width}}  {metric:<6} {ref_text:>17}  " + " ".join(cells))
            lines.append("")
    lines.append(f"result files: {report['results_dir']}")
    if report["notes"]:
        lines += ["", *report["notes"]]
    return "\n".join(lines)


# --------------------------------------------------------------------------------------------
# Picture

_PALETTE = (
    (230, 25, 75), (60, 180, 75), (255, 225, 25), (0, 130, 200), (245, 130, 48),
    (145, 30, 180), (70, 240, 240), (240, 50, 230), (210, 245, 60), (250, 190, 190),
    (0, 128, 128), (230, 190, 255), (170, 110, 40), (255, 250, 200), (128, 0, 0),
    (170, 255, 195), (128, 128, 0), (255, 215, 180), (0, 0, 128), (255, 255, 255),
)  # fmt: skip


def picture_frame(estimates: list[tuple[TrackEstimate, ...]]) -> int:
    """The frame (0-based) with the most tracks, at least ``PICTURE_TRAIL`` frames in."""
    first = min(PICTURE_TRAIL, len(estimates) - 1)
    counts = [len(e) for e in estimates[first:]]
    return first + int(np.argmax(counts))


def draw_tracks(
    frame: np.ndarray, estimates: list[tuple[TrackEstimate, ...]], index: int, caption: str
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
    for tracker in (OURS, "ours_dpm", "ours_cnn", "ours_hog"):
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
        description="Run our multi-person tracker and SORT, ByteTrack, OC-SORT, BoT-SORT on "
        "MOTChallenge sequences and score them with TrackEval."
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
        help="network of ours_cnn, an OpenVINO IR .xml (its .bin beside it) or an .onnx file "
        f"(default: the product's default, {DEFAULT_CNN_MODEL})",
    )
    parser.add_argument("--no-peers", action="store_true", help="skip SORT, ByteTrack...")
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
    that ``--no-peers``, ``--no-end-to-end`` or a missing ``--dpm`` or ``--cnn-model`` model
    leave out, are argument errors.
    """
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
    return None


def cnn_model_problem(path: Path) -> str | None:
    """Why ``ours_cnn`` cannot run the network at ``path`` (not a model file, missing, an IR
    without its weights), or None. Only the files are looked at, so that a bad path is told
    before anything runs; a file OpenVINO cannot read fails ``ours_cnn`` on every sequence."""
    if path.suffix.lower() not in CNN_SUFFIXES:
        return f"{path} is not a CNN model (an OpenVINO IR .xml or an .onnx file)"
    if not path.is_file():
        return f"there is no CNN model at {path}"
    weights = path.with_suffix(".bin")
    if path.suffix.lower() == ".xml" and not weights.is_file():
        return f"the CNN model {path} has no weights {weights.name} beside it"
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
    """``--list``: the tracker names, and what each of ours tracks on (models: missing or not)."""

    def model(kind: str, path: Path, problem: str | None) -> str:
        return f"{kind} {path}" if problem is None else f"{kind}: {problem}"

    dpm_problem = None if args.dpm.is_file() else f"there is no DPM model at {args.dpm}"
    sources = {
        OURS: "public detections det/det.txt",
        "ours_hog": "embedded HOG people detector",
        "ours_dpm": model("DPM", args.dpm, dpm_problem),
        "ours_cnn": model("CNN", args.cnn_model, cnn_model_problem(args.cnn_model)),
    }
    width = max(len(n) for n in sources)
    lines = ["peers: " + ", ".join(PEERS), "ours:  " + ", ".join([OURS, *END_TO_END])]
    lines += [f"  {name:<{width}}  {source}" for name, source in sources.items()]
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

    python = mot_python(args, outcome)
    if python is not None and peers:
        run_peers(python, peers, outcome, args.repeats, args.frames, args.peer_frame_rate)
    ours = make_ours(args, ours_names, outcome)
    picture_sequence = PICTURE_SEQUENCE if args.picture is not None else None
    run_ours(ours, outcome, args.repeats, args.end_to_end_repeats, picture_sequence)
    if not outcome.runs:
        print("error: no tracker produced results", file=sys.stderr)
        for note in outcome.notes:
            print(note, file=sys.stderr)
        return 1

    results = args.results or Path(tempfile.mkdtemp(prefix="vtrack-mot-results-"))
    write_results(outcome, results)
    scored, unscored = score(python, outcome, results)
    report = summarize(outcome, scored, results)
    if not scored_trackers(report):  # a run that scored nothing has not measured anything
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
