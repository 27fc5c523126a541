"""The MOT benchmark's own machinery: seeded runs, replayed detections, configuration options,
and what its command line refuses or reports as a failure."""

from __future__ import annotations

import contextlib
import dataclasses
import io
import json
import shutil
import sys
from pathlib import Path

import cv2
import numpy as np
import pytest

from service.models.catalog import DEFAULT_DETECTOR, model_path
from tests.conftest import benchmark_module, copy_mot_sequence, documented_commands
from tracking.detection import DPM_TRACKING_CONFIG, make_detector
from tracking.detection.cnn import MODEL_SUFFIXES, CnnConfig
from tracking.people import PeopleTrackerConfig


@pytest.fixture(scope="module")
def mot():
    with benchmark_module("mot") as module:  # it imports its sibling _mot_env
        yield module


class CountingDetector:
    """The embedded detector, counting its full-frame calls."""

    def __init__(self) -> None:
        self.inner = make_detector("default")
        self.part_names = self.inner.part_names
        self.calls = 0

    def detect(self, frame: np.ndarray):
        self.calls += 1
        return self.inner.detect(frame)


def _frame(shared_data: Path, index: int) -> np.ndarray:
    path = shared_data / "mot" / "PETS09-S2L1" / "img1" / f"{index:06d}.jpg"
    return cv2.cvtColor(cv2.imread(str(path)), cv2.COLOR_BGR2RGB)


def test_seeded_runs_replay_the_recorded_detections(mot, shared_data: Path) -> None:
    counting = CountingDetector()
    recorder = mot.RecordingDetector(lambda: counting)
    replayed = mot.ReplayedDetector(recorder)
    first, second = _frame(shared_data, 1), _frame(shared_data, 2)
    a = recorder.detect(first)
    assert len(a) > 0  # PETS09-S2L1 frame 1 has people
    recorder.detect(first)  # the recording run always detects: its timings include it
    assert counting.calls == 2
    again = replayed.detect(first.copy())  # the same pixels in another array
    assert counting.calls == 2
    np.testing.assert_array_equal(again.boxes, a.boxes)
    replayed.detect(second)  # not recorded yet: detected, and recorded
    replayed.detect(second)
    assert counting.calls == 3
    # A frame that differs in one pixel is detected anew.
    changed = first.copy()
    changed[0, 0, 0] ^= 1
    replayed.detect(changed)
    assert counting.calls == 4
    assert replayed.part_names == counting.part_names  # other attributes pass through


def test_seeded_runs_share_one_detector(mot, tmp_path: Path) -> None:
    config = PeopleTrackerConfig(report_missing=0.5)
    ours = mot.build_ours(["ours", "ours_hog"], tmp_path / "none.mat", 3, None, None, config)
    assert list(ours) == ["ours", "ours_seed1", "ours_seed2", "ours_hog", "ours_hog_seed1",
                          "ours_hog_seed2"]  # fmt: skip
    trackers = {name: entry.factory() for name, entry in ours.items()}
    assert [t.config.seed for t in trackers.values()] == [0, 1, 2, 0, 1, 2]
    for name, entry in ours.items():  # the configuration reported is the one the run uses
        assert entry.details["config"] == dataclasses.asdict(trackers[name].config), name
    assert all(t.config.report_missing == 0.5 for t in trackers.values())
    hog = [trackers[n]._detector for n in ("ours_hog", "ours_hog_seed1", "ours_hog_seed2")]
    assert isinstance(hog[0], mot.RecordingDetector)
    assert all(isinstance(d, mot.ReplayedDetector) for d in hog[1:])
    assert hog[1]._recorder is hog[2]._recorder is hog[0]
    assert trackers["ours"]._detector is None and ours["ours"].public
    assert ours["ours_hog_seed1"].details["seed"] == 1


def test_dpm_runs_at_its_tracking_operating_point(mot, tmp_path: Path) -> None:
    ours = mot.build_ours(["ours_dpm"], tmp_path / "none.mat")  # the model loads on first use
    assert ours["ours_dpm"].details["detector_options"] == dataclasses.asdict(DPM_TRACKING_CONFIG)
    args = mot.parse_args(["--dpm-config", '{"upscale": 1.3}'])  # fields over the preset
    assert args.dpm_config == dataclasses.replace(DPM_TRACKING_CONFIG, upscale=1.3)


def test_cnn_runs_the_product_default_model(mot, shared_data: Path, tmp_path: Path) -> None:
    """ours_cnn is what a service job with detector 'auto' runs: the catalog's default network
    (from the shared data's models folder) with the CnnConfig defaults."""
    default = model_path(shared_data / "models", DEFAULT_DETECTOR)
    assert default == mot.DEFAULT_CNN_MODEL and default.is_file()
    assert mot.parse_args([]).cnn_model == default
    assert mot.CNN_SUFFIXES == MODEL_SUFFIXES
    other = tmp_path / "other.onnx"  # --cnn-model: another network; it loads on first use
    assert mot.parse_args(["--cnn-model", str(other)]).cnn_model == other
    ours = mot.build_ours(["ours_cnn"], tmp_path / "none.mat", 2, cnn_model=other)
    assert list(ours) == ["ours_cnn", "ours_cnn_seed1"]
    details = ours["ours_cnn"].details
    assert details["detector"] == str(other) and details["detections"] == "CNN other"
    assert details["detector_options"] == dataclasses.asdict(CnnConfig())
    assert details["config"] == dataclasses.asdict(PeopleTrackerConfig())  # the defaults
    recorder, replayed = (entry.detector for entry in ours.values())
    assert isinstance(recorder, mot.RecordingDetector)
    assert isinstance(replayed, mot.ReplayedDetector) and replayed._recorder is recorder


def test_a_missing_cnn_model_leaves_ours_cnn_out_with_a_note(mot, tmp_path: Path) -> None:
    """In a run of all trackers, as a missing DPM model is (named, it is refused: below)."""
    weightless = tmp_path / "net.xml"  # an IR without its .bin
    shutil.copyfile(mot.DEFAULT_CNN_MODEL, weightless)
    for path, problem in [
        (tmp_path / "none.xml", f"there is no CNN model at {tmp_path}/none.xml"),
        (weightless, f"the CNN model {weightless} has no weights net.bin beside it"),
    ]:
        args = mot.parse_args(["--cnn-model", str(path)])
        outcome = mot.Outcome(sequences=[], frames={})
        ours = mot.make_ours(args, ["ours", "ours_cnn"], outcome)
        assert list(ours) == ["ours", "ours_seed1", "ours_seed2", "ours_seed3"]
        assert outcome.notes == [f"note: ours_cnn left out: {problem} (--cnn-model)"]
        assert problem in mot.list_trackers(args)
    listed = mot.list_trackers(mot.parse_args([]))
    assert f"ours_cnn  CNN {mot.DEFAULT_CNN_MODEL}" in listed
    assert "ours:  ours, ours_hog, ours_dpm, ours_cnn" in listed


def test_config_options_are_checked(mot) -> None:
    args = mot.parse_args(["--tracker-config", '{"report_missing": 0.6, "particles": 64}'])
    assert args.tracker_config == PeopleTrackerConfig(report_missing=0.6, particles=64)
    for bad in ('{"no_such_field": 1}', '{"particles": 1}', "[1]", "not json"):
        with pytest.raises(SystemExit):
            mot.parse_args(["--tracker-config", bad])
    with pytest.raises(SystemExit):
        mot.parse_args(["--dpm-config", '{"nms_criterion": "area"}'])


@pytest.mark.slow
def test_filled_gaps_add_rows_and_keep_the_tracked_ones(mot, shared_data: Path) -> None:
    from tqdm import tqdm

    from tracking.evaluation.mot import check_unique_ids, read_sequence_info

    sequence = read_sequence_info(shared_data / "mot" / "PETS09-S2L1")
    rows = {}
    for fill in (0.0, 1.0):
        (ours,) = mot.build_ours(["ours"], Path("none.mat"), fill_gaps=fill).values()
        assert ours.details["fill_gaps"] == fill
        with tqdm(disable=True) as bar:
            rows[fill], _, _ = mot.track_ours(ours, sequence, 60, bar, False)
    check_unique_ids(rows[1.0])
    tracked = {tuple(r) for r in rows[0.0]}
    filled = [r for r in rows[1.0] if tuple(r) not in tracked]
    assert tracked <= {tuple(r) for r in rows[1.0]}
    # on the public detections of these 60 frames (7 fps) tracks break and come back
    assert len(filled) >= 3
    assert all(r[0] < 60 for r in filled)


# --------------------------------------------------------------------------------- command line


def _refused_env(folder: Path) -> Path:
    """A --mot-env folder the benchmark will not use (not empty, not made by it): no peers, no
    TrackEval, and no pip run."""
    folder.mkdir()
    (folder / "something").write_text("not an environment\n")
    return folder


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        # named trackers that another option leaves out: refused, not dropped
        (["--no-end-to-end", "--trackers", "ours_hog"],
         "--trackers asks for ours_hog, which --no-end-to-end leaves out"),
        (["--no-peers", "--trackers", "sort"],
         "--trackers asks for sort, which --no-peers leaves out"),
        (["--trackers", "ours_hog,sort", "--no-peers"],
         "--trackers asks for sort, which --no-peers leaves out"),
        (["--trackers", "ours_dpm", "--dpm", "{tmp}/none.mat"],
         "--trackers asks for ours_dpm but there is no DPM model at {tmp}/none.mat"),
        (["--trackers", "ours,ours_cnn", "--cnn-model", "{tmp}/none.xml"],
         "--trackers asks for ours_cnn but there is no CNN model at {tmp}/none.xml"),
        (["--trackers", "ours_cnn", "--cnn-model", "{tmp}/model.mat"],
         "--trackers asks for ours_cnn but {tmp}/model.mat is not a CNN model"),
        (["--no-end-to-end", "--trackers", "ours_cnn"],
         "--trackers asks for ours_cnn, which --no-end-to-end leaves out"),
        # an unknown name: the valid ones listed
        (["--trackers", "foo"],
         "unknown tracker foo; choose from sort, bytetrack, ocsort, botsort, ours, ours_hog, "
         "ours_dpm, ours_cnn"),
        (["--trackers", ","], "--trackers names no tracker"),
        (["--seeds", "0"], "--seeds must be at least 1, got 0"),  # as --repeats 0 is
    ],
)  # fmt: skip
def test_bad_tracker_arguments_are_argument_errors(
    mot, shared_data, tmp_path, capsys, argv, message
):
    # were an argument let through, the run would stay short and create no environment
    short = ["--data", str(shared_data / "mot"), "--sequences", "TUD-Stadtmitte", "--frames", "2",
             "--repeats", "1", "--mot-env", str(_refused_env(tmp_path / "env"))]  # fmt: skip
    with pytest.raises(SystemExit) as stopped:
        mot.main([*short, *(a.format(tmp=tmp_path) for a in argv)])
    assert stopped.value.code == 2  # argparse's error, before anything runs
    last = capsys.readouterr().err.splitlines()[-1]
    assert last.partition(": error: ")[2].startswith(message.format(tmp=tmp_path))


@pytest.mark.parametrize(
    ("argv", "peers", "ours"),
    [
        (["--trackers", "ours_hog,sort"], ["sort"], ["ours_hog"]),
        (["--trackers", "ours_cnn,ours"], [], ["ours", "ours_cnn"]),
        (["--no-peers", "--no-end-to-end"], [], ["ours"]),  # all that the options leave in
        (
            [],
            ["sort", "bytetrack", "ocsort", "botsort"],
            ["ours", "ours_hog", "ours_dpm", "ours_cnn"],
        ),
    ],
)
def test_selection_runs_what_was_asked(mot, argv, peers, ours):
    assert mot.select(mot.parse_args(argv)) == (peers, ours)


def test_no_picture_unless_asked(mot, tmp_path, drawing_packages):
    """A quick run must not overwrite the committed docs/images/mot.png."""
    assert mot.parse_args([]).picture is None
    assert mot.parse_args(["--picture", str(tmp_path / "m.png")]).picture == tmp_path / "m.png"


def test_picture_without_pillow_fails_before_tracking(mot, tmp_path, monkeypatch, capsys):
    monkeypatch.setitem(sys.modules, "PIL", None)  # import fails as if not installed
    with pytest.raises(SystemExit) as exit_info:
        mot.parse_args(["--picture", str(tmp_path / "m.png")])
    assert exit_info.value.code == 2
    assert "--picture" in capsys.readouterr().err


@pytest.mark.parametrize(
    ("gt", "message"),
    [
        (None, "{seq} has no ground truth gt/gt.txt, so no tracker can be scored on it"),
        ("1,1,10,20\n", "{seq}/gt/gt.txt:1: expected at least 6 columns, got 4"),
    ],
)
def test_a_sequence_without_usable_ground_truth_is_refused_before_tracking(
    mot, shared_data, tmp_path, capsys, gt, message
):
    sequence = copy_mot_sequence(shared_data, tmp_path / "SEQ", 3)
    if gt is None:
        shutil.rmtree(sequence / "gt")
    else:
        (sequence / "gt" / "gt.txt").write_text(gt)
    results = tmp_path / "results"
    code = mot.main(
        ["--sequences", str(sequence), "--trackers", "ours", "--no-peers", "--seeds", "1",
         "--repeats", "1", "--mot-env", str(_refused_env(tmp_path / "env")),
         "--results", str(results)]
    )  # fmt: skip
    assert code == 2
    assert capsys.readouterr().err == f"error: {message.format(seq=sequence)}\n"
    assert not results.exists()  # nothing was tracked


@pytest.fixture(scope="module")
def unscored_run(mot, shared_data, tmp_path_factory):
    """``ours`` with two seeds on 3 frames, with a --mot-env the benchmark refuses: it tracks,
    but nothing can score it. (exit status, stdout, stderr)"""
    tmp = tmp_path_factory.mktemp("unscored")
    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        code = mot.main(
            ["--data", str(shared_data / "mot"), "--sequences", "TUD-Stadtmitte", "--frames", "3",
             "--trackers", "ours", "--no-peers", "--seeds", "2", "--repeats", "1",
             "--mot-env", str(_refused_env(tmp / "env")), "--results", str(tmp / "results"),
             "--json"]
        )  # fmt: skip
    return code, out.getvalue(), err.getvalue()


def test_a_run_that_scores_nothing_fails(unscored_run):
    code, out, err = unscored_run
    assert code == 1
    why = "no tracker was scored: TrackEval's environment is unavailable (see the notes)"
    assert err.splitlines()[-1] == f"error: {why}"
    report = json.loads(out)  # the report is still written: the trackers did run
    assert report["error"] == why
    assert set(report["trackers"]) == {"ours", "ours_seed1"}


def test_seeded_runs_report_the_configuration_they_used(unscored_run):
    trackers = json.loads(unscored_run[1])["trackers"]
    assert trackers["ours"]["config"]["seed"] == 0 and "seed" not in trackers["ours"]
    assert trackers["ours_seed1"]["config"]["seed"] == trackers["ours_seed1"]["seed"] == 1


def test_ours_cnn_tracks_end_to_end(mot, shared_data, tmp_path, capsys) -> None:
    """A few frames of ours_cnn and a seeded run: tracks from the CNN's detections, and the
    report names the model and the calibration it ran with."""
    code = mot.main(
        ["--data", str(shared_data / "mot"), "--sequences", "PETS09-S2L1", "--frames", "3",
         "--trackers", "ours_cnn", "--seeds", "2", "--repeats", "1", "--no-peers",
         "--mot-env", str(_refused_env(tmp_path / "env")), "--results", str(tmp_path / "r"),
         "--json"]
    )  # fmt: skip
    assert code == 1  # tracked, but nothing could score it
    trackers = json.loads(capsys.readouterr().out)["trackers"]
    assert set(trackers) == {"ours_cnn", "ours_cnn_seed1"}
    calibration = make_detector(mot.DEFAULT_CNN_MODEL).calibration  # whichever it is now
    for entry in trackers.values():
        assert entry["detector"] == str(mot.DEFAULT_CNN_MODEL)
        assert entry["calibration"] == dataclasses.asdict(calibration)
        # tracks are confirmed on their 3rd frame: the people found in frames 1-3 (3 now)
        assert entry["sequences"]["PETS09-S2L1"]["boxes"] > 0


def test_the_documented_commands_are_accepted(mot, drawing_packages):
    """docs/benchmarks.md's commands still parse: none names a tracker its options leave out."""
    commands = documented_commands("mot.py")
    assert len(commands) >= 15
    for argv in commands:
        mot.parse_args(argv)
