"""Score MOTChallenge result files with TrackEval (HOTA, CLEAR MOT, identity); print JSON.

A standalone script for the MOT peer environment (``trackeval``; see ``benchmarks/_mot_env.py``):
it imports nothing from the project. ``benchmarks/mot.py`` runs it in a subprocess:

    .venv-mot/bin/python benchmarks/peers/trackeval_score.py --gt GT_DIR --results RESULTS_DIR
        --sequence NAME:FRAMES [...] --tracker NAME [...]

It evaluates with TrackEval's own dataset class, ``MotChallenge2DBox``, on this layout:

    GT_DIR/<sequence>/gt/gt.txt          ground truth (rows of frames 1..FRAMES only)
    RESULTS_DIR/<tracker>/<sequence>.txt  results, frame,id,x,y,w,h,conf,-1,-1,-1

with ``SKIP_SPLIT_FOL`` (no ``MOT15-train`` level), ``TRACKER_SUB_FOLDER`` empty and the
sequence lengths given directly (``SEQ_INFO``), so no seqmap or ``seqinfo.ini`` is needed.

``BENCHMARK`` is ``MOT15``. For MOT15 TrackEval does no class-based preprocessing: it keeps every
ground-truth row whose 7th column (the "consider" flag) is not 0, and removes no result box. This
is the only mode that works for ground truth whose class column (8th) is -1, as in the
PETS09-S2L1 and TUD-Stadtmitte files here: with MOT16/17 preprocessing TrackEval rejects class
-1 ("invalid gt classes"), and would keep only class 1 (pedestrian) and drop result boxes that
match distractors (static person, reflection, person on vehicle...).

Metrics: ``HOTA`` (HOTA, DetA, AssA, LocA: means over the 19 localisation thresholds
0.05..0.95), ``CLEAR`` (MOTA, MOTP, IDSW, MT/PT/ML, FP, FN, Frag at IoU 0.5) and ``Identity``
(IDF1, IDP, IDR at IoU 0.5), per sequence and combined over the sequences (TrackEval's
``COMBINED_SEQ``). Scores are in percent, counts are integers.

Output (stdout): ``{"trackeval", "config", "trackers": {name: {sequence or "COMBINED_SEQ":
{metric: value}}}, "errors": {name: message}}``.
"""

from __future__ import annotations

import argparse
import contextlib
import io
import json
import sys
from pathlib import Path

import numpy as np
import trackeval

CLASS = "pedestrian"
PERCENT = {
    "HOTA": ("HOTA", "HOTA"),
    "DetA": ("HOTA", "DetA"),
    "AssA": ("HOTA", "AssA"),
    "LocA": ("HOTA", "LocA"),
    "DetRe": ("HOTA", "DetRe"),
    "DetPr": ("HOTA", "DetPr"),
    "AssRe": ("HOTA", "AssRe"),
    "AssPr": ("HOTA", "AssPr"),
    "MOTA": ("CLEAR", "MOTA"),
    "MOTP": ("CLEAR", "MOTP"),
    "Recall": ("CLEAR", "CLR_Re"),
    "Precision": ("CLEAR", "CLR_Pr"),
    "IDF1": ("Identity", "IDF1"),
    "IDP": ("Identity", "IDP"),
    "IDR": ("Identity", "IDR"),
}
COUNTS = {
    "IDSW": ("CLEAR", "IDSW"),
    "MT": ("CLEAR", "MT"),
    "PT": ("CLEAR", "PT"),
    "ML": ("CLEAR", "ML"),
    "FP": ("CLEAR", "CLR_FP"),
    "FN": ("CLEAR", "CLR_FN"),
    "TP": ("CLEAR", "CLR_TP"),
    "Frag": ("CLEAR", "Frag"),
    "GT_IDs": ("Count", "GT_IDs"),
    "IDs": ("Count", "IDs"),
    "GT_Dets": ("Count", "GT_Dets"),
    "Dets": ("Count", "Dets"),
}


def figures(result: dict[str, dict[str, object]]) -> dict[str, float | int]:
    """The reported figures of one tracker on one sequence (or combined)."""
    out: dict[str, float | int] = {}
    for name, (metric, field) in PERCENT.items():
        # HOTA fields are arrays over the localisation thresholds: their mean is the score
        out[name] = 100.0 * float(np.mean(result[metric][field]))
    for name, (metric, field) in COUNTS.items():
        out[name] = int(result[metric][field])
    return out


def evaluate(
    gt: Path, results: Path, sequences: dict[str, int], trackers: list[str]
) -> tuple[dict[str, object], dict[str, dict[str, dict]], dict[str, str]]:
    eval_config = {
        "USE_PARALLEL": False,
        "BREAK_ON_ERROR": False,
        "RETURN_ON_ERROR": False,
        "LOG_ON_ERROR": None,
        "PRINT_RESULTS": False,
        "PRINT_ONLY_COMBINED": False,
        "PRINT_CONFIG": False,
        "TIME_PROGRESS": False,
        "DISPLAY_LESS_PROGRESS": True,
        "OUTPUT_SUMMARY": False,
        "OUTPUT_EMPTY_CLASSES": False,
        "OUTPUT_DETAILED": False,
        "PLOT_CURVES": False,
    }
    dataset_config = {
        "GT_FOLDER": str(gt),
        "TRACKERS_FOLDER": str(results),
        "OUTPUT_FOLDER": str(gt / "_trackeval_output"),
        "TRACKERS_TO_EVAL": trackers,
        "CLASSES_TO_EVAL": [CLASS],
        "BENCHMARK": "MOT15",
        "SPLIT_TO_EVAL": "train",
        "DO_PREPROC": True,
        "TRACKER_SUB_FOLDER": "",
        "OUTPUT_SUB_FOLDER": "",
        "SEQ_INFO": dict(sequences),
        "SKIP_SPLIT_FOL": True,
        "PRINT_CONFIG": False,
    }
    metric_config = {"THRESHOLD": 0.5, "PRINT_CONFIG": False}
    evaluator = trackeval.Evaluator(eval_config)
    dataset = trackeval.datasets.MotChallenge2DBox(dataset_config)
    metrics = [
        trackeval.metrics.HOTA(),
        trackeval.metrics.CLEAR(metric_config),
        trackeval.metrics.Identity(metric_config),
    ]
    raw, messages = evaluator.evaluate([dataset], metrics)
    by_tracker = raw[dataset.get_name()]
    scores: dict[str, dict[str, dict]] = {}
    errors: dict[str, str] = {}
    for tracker in trackers:
        result = by_tracker.get(tracker)
        if result is None:
            errors[tracker] = str(messages[dataset.get_name()].get(tracker, "not evaluated"))
            continue
        scores[tracker] = {seq: figures(r[CLASS]) for seq, r in result.items()}
    config = {
        "dataset": "MotChallenge2DBox",
        **{k: dataset_config[k] for k in ("BENCHMARK", "DO_PREPROC", "CLASSES_TO_EVAL")},
        "metrics": ["HOTA", "CLEAR", "Identity"],
        "iou_threshold_clear_identity": metric_config["THRESHOLD"],
    }
    return config, scores, errors


def _sequence(text: str) -> tuple[str, int]:
    name, _, frames = text.rpartition(":")
    if not name or not frames.isdigit() or int(frames) < 1:
        raise argparse.ArgumentTypeError(f"expected NAME:FRAMES, got {text!r}")
    return name, int(frames)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--gt", type=Path, required=True, help="GT_DIR/<seq>/gt/gt.txt")
    parser.add_argument("--results", type=Path, required=True, help="RESULTS_DIR/<tracker>/")
    parser.add_argument("--sequence", type=_sequence, action="append", required=True)
    parser.add_argument("--tracker", action="append", required=True)
    args = parser.parse_args(argv)
    # TrackEval prints its progress to stdout: keep stdout for the JSON, show the chatter only
    # when something went wrong
    chatter = io.StringIO()
    with contextlib.redirect_stdout(chatter):
        config, scores, errors = evaluate(
            args.gt, args.results, dict(args.sequence), list(args.tracker)
        )
    if errors:
        sys.stderr.write(chatter.getvalue())
    report = {"trackeval": trackeval.__version__, "config": config}
    json.dump({**report, "trackers": scores, "errors": errors}, sys.stdout)
    sys.stdout.write("\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
