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
    assert list(ours) == ["ours@public", "ours_seed1@public", "ours_seed2@public", "ours_hog",
                          "ours_hog_seed1", "ours_hog_seed2"]  # fmt: skip
    trackers = {name: entry.factory() for name, entry in ours.items()}
    assert [t.config.seed for t in trackers.values()] == [0, 1, 2, 0, 1, 2]
    for name, entry in ours.items():  # the configuration reported is the one the run uses
        assert entry.details["config"] == dataclasses.asdict(trackers[name].config), name
    assert all(t.config.report_missing == 0.5 for t in trackers.values())
    hog = [trackers[n]._detector for n in ("ours_hog", "ours_hog_seed1", "ours_hog_seed2")]
    assert isinstance(hog[0], mot.RecordingDetector)
    assert all(isinstance(d, mot.ReplayedDetector) for d in hog[1:])
    assert hog[1]._recorder is hog[2]._recorder is hog[0]
    assert trackers["ours@public"]._detector is None and ours["ours@public"].source == "public"
    assert ours["ours_hog"].end_to_end and not ours["ours@public"].end_to_end
    assert ours["ours_hog_seed1"].details["seed"] == 1


def test_ours_runs_on_each_source_and_with_the_detections_aspect(mot, tmp_path: Path) -> None:
    """ours@<source> for each detection source; ours+detbox@<source>: box_aspect None."""
    ours = mot.build_ours(["ours"], tmp_path / "none.mat", 2, sources=("public", "cnn"),
                          parity=True)  # fmt: skip
    assert list(ours) == [
        "ours@public", "ours_seed1@public", "ours+detbox@public", "ours+detbox_seed1@public",
        "ours@cnn", "ours_seed1@cnn", "ours+detbox@cnn", "ours+detbox_seed1@cnn",
    ]  # fmt: skip
    for name, entry in ours.items():
        config = entry.factory().config
        assert entry.source == name.partition("@")[2] == entry.details["detection_source"]
        assert config.box_aspect == (None if "+detbox" in name else 0.41), name
        assert config.seed == (1 if "seed1" in name else 0)
    # a configuration that already reports the detections' aspect has no +detbox twin
    plain = PeopleTrackerConfig(box_aspect=None)
    assert list(mot.build_ours(["ours"], tmp_path / "none.mat", 1, None, None, plain,
                               parity=True)) == ["ours@public"]  # fmt: skip


def test_ours_also_runs_with_the_reid_network(mot, tmp_path: Path) -> None:
    """ours+reid@<source>: the tracker with the re-identification network, as a job with the
    model installed runs; its twin with the detections' aspect too."""
    ours = mot.build_ours(["ours"], tmp_path / "none.mat", 1, parity=True,
                          reid_model=mot.DEFAULT_REID_MODEL)  # fmt: skip
    assert list(ours) == ["ours@public", "ours+reid@public", "ours+detbox@public",
                          "ours+detbox+reid@public"]  # fmt: skip
    for name, entry in ours.items():
        tracker = entry.factory()
        assert (tracker._reid is not None) == name.endswith("+reid@public"), name
        assert entry.details["reid_model"] == (
            str(mot.DEFAULT_REID_MODEL) if "+reid" in name else None
        )


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
    # the defaults, with the CNN boxes' own aspect as a service job runs it
    assert details["config"] == dataclasses.asdict(PeopleTrackerConfig(box_aspect=None))
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
        args = mot.parse_args(["--cnn-model", str(path), "--no-parity", "--no-ours-reid"])
        outcome = mot.Outcome(sequences=[], frames={}, sources={"public": mot.public_source([])})
        ours = mot.make_ours(args, ["ours", "ours_cnn"], outcome)
        assert list(ours) == ["ours@public", "ours_seed1@public", "ours_seed2@public",
                              "ours_seed3@public"]  # fmt: skip
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
            detections = mot.public_detections(sequence)
            rows[fill], _, _ = mot.track_ours(ours, sequence, 60, bar, False, detections)
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
         "unknown tracker foo; choose from sort, bytetrack, ocsort, botsort, deepocsort, "
         "strongsort, botsort_reid, ours, ours_hog, ours_dpm, ours_cnn"),
        (["--no-peers", "--trackers", "strongsort"],
         "--trackers asks for strongsort, which --no-peers leaves out"),
        (["--trackers", "ours,deepocsort", "--reid-model", "{tmp}/none.xml"],
         "--trackers asks for deepocsort but there is no re-identification model at "
         "{tmp}/none.xml"),
        # detection sources: unknown ones, and the CNN's without its model
        (["--detections", "public,foo"],
         "argument --detections: unknown detection source foo; choose from public, cnn"),
        (["--detections", "cnn", "--cnn-model", "{tmp}/none.xml"],
         "--detections asks for cnn but there is no CNN model at {tmp}/none.xml"),
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
        (["--trackers", "strongsort,ours,sort"], ["sort", "strongsort"], ["ours"]),
        (
            [],
            ["sort", "bytetrack", "ocsort", "botsort", "deepocsort", "strongsort", "botsort_reid"],
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
             "--no-ours-reid", "--trackers", "ours", "--no-peers", "--seeds", "2", "--repeats", "1",
             "--detections", "public", "--no-parity",
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
    assert set(report["trackers"]) == {"ours@public", "ours_seed1@public"}


def test_seeded_runs_report_the_configuration_they_used(unscored_run):
    trackers = json.loads(unscored_run[1])["trackers"]
    first, seeded = trackers["ours@public"], trackers["ours_seed1@public"]
    assert first["config"]["seed"] == 0 and "seed" not in first
    assert seeded["config"]["seed"] == seeded["seed"] == 1


def test_ours_cnn_tracks_end_to_end(mot, shared_data, tmp_path, capsys) -> None:
    """A few frames of ours_cnn and a seeded run: tracks from the CNN's detections, and the
    report names the model and the calibration it ran with."""
    code = mot.main(
        ["--data", str(shared_data / "mot"), "--sequences", "PETS09-S2L1", "--frames", "3",
         "--no-ours-reid", "--trackers", "ours_cnn", "--seeds", "2", "--repeats", "1", "--no-peers",
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
    assert len(commands) >= 8  # the targets', the fair comparison's, CNN's and DPM pyramids'
    for argv in commands:
        mot.parse_args(argv)


# ------------------------------------------------------------------ same detections, same boxes


def test_parity_rows_are_the_peers_rows_through_our_own_box_rule(mot, monkeypatch) -> None:
    """<peer>+aspect@<source>: the peer's rows with each box through the function our tracker
    reports its boxes with (tracking.people.motion.with_aspect), nothing else changed."""
    import tracking.people.motion as motion_module

    rng = np.random.default_rng(3)
    rows = np.column_stack([
        np.repeat([1, 2], 3), np.tile([4, 5, 6], 2), rng.uniform(1, 500, (6, 2)),
        rng.uniform(20, 60, 6), rng.uniform(60, 200, 6), rng.uniform(0, 1, 6),
    ])  # fmt: skip
    outcome = mot.Outcome(sequences=[], frames={"S": 2})
    outcome.details["sort@cnn"] = {"family": "peer", "base": "sort", "detection_source": "cnn"}
    outcome.add("sort@cnn", "S", mot.Run(rows, [0.5], 2))
    calls = []
    rule = motion_module.with_aspect

    def spy(boxes, aspect):
        calls.append(aspect)
        return rule(boxes, aspect)

    monkeypatch.setattr(motion_module, "with_aspect", spy)
    mot.add_parity_rows(outcome, 0.41)
    assert calls == [0.41]  # our tracker's rule, called, not a copy of it
    parity = outcome.runs["sort+aspect@cnn"]["S"]
    np.testing.assert_array_equal(parity.rows[:, [0, 1, 6]], rows[:, [0, 1, 6]])
    np.testing.assert_array_equal(parity.rows[:, 2:6], rule(rows[:, 2:6], 0.41))
    np.testing.assert_allclose(parity.rows[:, 4], 0.41 * rows[:, 5])  # width 0.41 x height
    centre = rows[:, 2] + rows[:, 4] / 2
    np.testing.assert_allclose(parity.rows[:, 2] + parity.rows[:, 4] / 2, centre)
    assert parity.seconds == [0.5]  # the peer's own time: the rule is not tracking
    details = outcome.details["sort+aspect@cnn"]
    assert details["of"] == "sort@cnn" and details["base"] == "sort+aspect"
    assert details["detection_source"] == "cnn" and "postprocess" in details
    # a second pass adds nothing: +aspect rows are not peers' own rows
    mot.add_parity_rows(outcome, 0.41)
    assert sorted(outcome.runs) == ["sort+aspect@cnn", "sort@cnn"]


def test_the_fed_digest_is_one_function_in_every_process(mot) -> None:
    """The peer scripts run in other environments and import nothing from here: their digest
    of the boxes they were given is a copy of mot.fed_digest, which must stay the same."""
    import ast
    import inspect

    def body(source: str) -> str:
        (function,) = [
            node
            for node in ast.parse(source).body
            if isinstance(node, ast.FunctionDef) and node.name == "fed_digest"
        ]
        function.body = function.body[1:]  # without the docstring
        return ast.unparse(function)

    ours = body(inspect.getsource(mot.fed_digest))
    peers = Path(mot.__file__).parent / "peers"
    assert body((peers / "_sequences.py").read_text()) == ours
    rows = np.array([[1, 10.0, 20.0, 30.0, 60.0], [2, 11.0, 20.0, 30.0, 60.0]])
    assert mot.fed_digest(rows) == mot.fed_digest(rows + 1e-6)  # 1e-4 px
    assert mot.fed_digest(rows) != mot.fed_digest(rows[::-1])


def _file_digest(mot, path: Path, frames: int) -> str:
    """fed_digest of a detection file's rows of frames 1..frames, in file order."""
    rows = np.loadtxt(path, delimiter=",", ndmin=2)
    rows = rows[(rows[:, 0] <= frames) & (rows[:, 4] > 0) & (rows[:, 5] > 0)]
    return mot.fed_digest(rows[np.argsort(rows[:, 0], kind="stable")][:, [0, 2, 3, 4, 5]])


@pytest.mark.slow
def test_ours_runs_on_each_source(mot, shared_data, tmp_path, capsys) -> None:
    """3 frames of ours on both sources: the CNN's detections are written once as a
    MOTChallenge file and reused, ours gets exactly that file's boxes (and of the public one),
    with the probability the detector would hand ours_cnn; ours+detbox reports other boxes."""
    results = tmp_path / "r"
    argv = ["--data", str(shared_data / "mot"), "--sequences", "TUD-Stadtmitte", "--frames", "3",
            "--no-ours-reid", "--trackers", "ours", "--seeds", "1", "--repeats", "1", "--no-peers",
            "--mot-env", str(_refused_env(tmp_path / "env")), "--results", str(results),
            "--json"]  # fmt: skip
    assert mot.main(argv) == 1  # tracked, but nothing could score it
    report = json.loads(capsys.readouterr().out)
    assert set(report["trackers"]) == {
        "ours@public", "ours+detbox@public", "ours@cnn", "ours+detbox@cnn",
    }  # fmt: skip
    cnn = results / "detections" / "TUD-Stadtmitte" / "cnn.txt"
    files = {
        "public": shared_data / "mot" / "TUD-Stadtmitte" / "det" / "det.txt",
        "cnn": cnn,
    }
    assert report["sources"]["cnn"]["files"]["TUD-Stadtmitte"] == str(cnn)
    assert report["sources"]["cnn"]["detector_options"]["threshold"] == 0.1
    for name, entry in report["trackers"].items():
        source = name.partition("@")[2]
        assert entry["fed_digest"]["TUD-Stadtmitte"] == _file_digest(mot, files[source], 3)
        boxes = np.loadtxt(results / name / "TUD-Stadtmitte.txt", delimiter=",", ndmin=2)
        aspect = boxes[:, 4] / boxes[:, 5]
        if "+detbox" in name:  # the detections' aspect, not ours
            assert np.abs(aspect - 0.41).max() > 0.03, name
        else:
            np.testing.assert_allclose(aspect, 0.41, atol=0.005)
    rows = np.loadtxt(cnn, delimiter=",", ndmin=2)
    assert set(rows[:, 0]) == {1, 2, 3} and rows[:, 6].min() >= 0.1 and rows[:, 6].max() <= 1
    # the boxes and the calibrated probability the detector itself gives, from the file
    config = dataclasses.replace(CnnConfig(), threshold=0.1)
    found = make_detector(mot.DEFAULT_CNN_MODEL, config).detect(_tud_frame(shared_data, 1))
    outcome = mot.Outcome(sequences=[], frames={})
    args = mot.parse_args(["--detections", "cnn", "--results", str(results)])
    sequence = mot.read_sequence_info(shared_data / "mot" / "TUD-Stadtmitte")
    outcome.sequences, outcome.frames = [sequence], {"TUD-Stadtmitte": 3}
    mot.prepare_sources(args, outcome, results, ["cnn"])
    assert outcome.sources["cnn"].details["made"] == {"TUD-Stadtmitte": "reused"}
    given = mot.ours_detections(outcome.sources["cnn"], sequence).for_frame(0)
    np.testing.assert_allclose(given.boxes, found.boxes, atol=1e-3)
    np.testing.assert_allclose(given.probabilities, found.probabilities, atol=1e-5)
    peers_score = 1 / (1 + np.exp(-found.scores))  # what the peers read: the confidence
    np.testing.assert_allclose(rows[rows[:, 0] == 1, 6], peers_score, atol=1e-6)


def _tud_frame(shared_data: Path, index: int) -> np.ndarray:
    path = shared_data / "mot" / "TUD-Stadtmitte" / "img1" / f"{index:06d}.jpg"
    return cv2.cvtColor(cv2.imread(str(path)), cv2.COLOR_BGR2RGB)


def _env_ready(name: str) -> bool:
    """Whether the benchmark's environment ``name`` (_mot_env, _reid_env) is built with its
    current requirements (the test uses it, and will not spend minutes making it)."""
    with benchmark_module(name) as module:
        env = {"_mot_env": "DEFAULT_MOT_ENV", "_reid_env": "DEFAULT_REID_ENV"}[name]
        wanted = {"_mot_env": "MOT_REQUIREMENTS", "_reid_env": "REID_REQUIREMENTS"}[name]
        marker = getattr(module, env) / "vtrack-peer-env.json"
        try:
            return json.loads(marker.read_text()) == {"requirements": getattr(module, wanted)}
        except (OSError, ValueError):
            return False


@pytest.mark.slow
@pytest.mark.skipif(
    not (_env_ready("_mot_env") and _env_ready("_reid_env")),
    reason="the peers' environments (.venv-mot, .venv-reid) are not built",
)
def test_every_tracker_of_a_source_gets_the_same_detections(mot, shared_data, tmp_path, capsys):
    """SORT, Deep OC-SORT (with our re-id embeddings) and ours on 5 frames of both sources: the
    same boxes for all of a source (their digests), parity rows for each peer, and the fair
    comparison against the peers' rows and their +aspect rows."""
    results = tmp_path / "r"
    code = mot.main(
        ["--data", str(shared_data / "mot"), "--sequences", "TUD-Stadtmitte", "--frames", "5",
         "--no-ours-reid", "--trackers", "sort,deepocsort,ours", "--seeds", "2", "--repeats", "1",
         "--results", str(results), "--json"]
    )  # fmt: skip
    assert code == 0
    report = json.loads(capsys.readouterr().out)
    peers = ["sort", "deepocsort", "sort+aspect", "deepocsort+aspect"]
    ours = ["ours", "ours_seed1", "ours+detbox", "ours+detbox_seed1"]
    assert set(report["trackers"]) == {f"{t}@{s}" for t in peers + ours for s in ("public", "cnn")}
    for source in ("public", "cnn"):
        digests = {
            t: e["fed_digest"]["TUD-Stadtmitte"]
            for t, e in report["trackers"].items()
            if t.endswith(f"@{source}")
        }
        assert len(set(digests.values())) == 1, digests
        for peer in ("sort", "deepocsort"):  # +aspect: the peer's rows through our rule
            raw = np.loadtxt(results / f"{peer}@{source}" / "TUD-Stadtmitte.txt", delimiter=",")
            fair = np.loadtxt(results / f"{peer}+aspect@{source}" / "TUD-Stadtmitte.txt",
                              delimiter=",")  # fmt: skip
            # both files round to 0.01: x' = x + (w - 0.41 h) / 2 carries x's, half w's and
            # 0.41 half h's rounding, and the file rounds x' again (at most 0.0135 apart)
            np.testing.assert_allclose(fair[:, :7], mot.aspect_rows(raw[:, :7], 0.41), atol=0.0136)
        best = report["best_peer"][source]["TUD-Stadtmitte"]
        assert best["HOTA"]["tracker"] in {f"{p}@{source}" for p in peers}
        raw_best = report["best_raw_peer"][source]["TUD-Stadtmitte"]["HOTA"]
        assert raw_best["tracker"] in {f"sort@{source}", f"deepocsort@{source}"}
        assert best["HOTA"]["value"] >= raw_best["value"]
        versus = report["ours_vs_best_peer"][source]
        assert set(versus) == {f"ours@{source}", f"ours_mean@{source}", f"ours+detbox@{source}",
                               f"ours+detbox_mean@{source}"}  # fmt: skip
    embeddings = np.load(results / "detections" / "TUD-Stadtmitte" / "cnn.reid.npy")
    rows = np.loadtxt(results / "detections" / "TUD-Stadtmitte" / "cnn.txt", delimiter=",")
    assert embeddings.shape == (len(rows), 256)
    norms = np.linalg.norm(embeddings[rows[:, 0] <= 5], axis=1)
    np.testing.assert_allclose(norms, 1, atol=1e-4)  # our network's L2-normalised vectors
    assert report["trackers"]["deepocsort@cnn"]["source"] == "boxmot"
