"""``benchmarks/holdout_people.py``: OTB sequences whose target is a person, as held-out material
for the multi-person trackers (issue 76)."""

from __future__ import annotations

import json

import numpy as np
import pytest

from tests.conftest import benchmark_module, documented_commands
from tracking.datasets.otb import find_otb_sequences
from tracking.evaluation.mot import read_mot_rows, read_sequence_info


@pytest.fixture(scope="module")
def holdout():
    with benchmark_module("holdout_people") as module:
        yield module


def test_the_sequences_are_those_whose_target_stands_upright(holdout, shared_data):
    chosen = {s.name for s in holdout.person_sequences(shared_data / "otb")}
    assert chosen  # the shared data has people among its targets
    for sequence in find_otb_sequences(shared_data / "otb"):
        boxes = sequence.ground_truth[holdout.labelled(sequence)]
        upright = np.median(boxes[:, 3] / boxes[:, 2]) >= holdout.MIN_PERSON_ASPECT
        assert (sequence.name in chosen) == upright, sequence.name


def test_a_sequence_laid_out_for_mot_reads_back_with_its_target(holdout, shared_data, tmp_path):
    sequence = holdout.person_sequences(shared_data / "otb")[0]
    folder = holdout.mot_folder(sequence, tmp_path, frame_rate=25.0)
    info = read_sequence_info(folder)
    assert (info.name, len(info), info.frame_rate) == (sequence.name, len(sequence), 25.0)
    assert [p.name for p in info.frame_paths] == [p.name for p in sequence.frame_paths]
    truth = read_mot_rows(info.gt_path, min_columns=6)
    labelled = np.flatnonzero(holdout.labelled(sequence))
    np.testing.assert_array_equal(truth[:, 0], labelled + 1)
    assert set(truth[:, 1]) == {1}
    # 1-based file units, as the trackers write theirs
    np.testing.assert_allclose(truth[:, 2:6], sequence.ground_truth[labelled] + [1, 1, 0, 0])


def test_the_person_is_covered_kept_and_switched_as_counted_by_hand(holdout):
    truth = np.array([[f, 1, 10 + 2 * f, 10, 20, 50] for f in (1, 2, 3, 4, 5)], dtype=float)
    rows = np.array(
        [
            [1, 5, 12, 10, 20, 50],  # track 5 on the person
            [2, 5, 14, 10, 40, 50],  # twice as wide about the same centre: box shape is not held
            [2, 6, 14, 12, 20, 50],  # against it; the better of the two covers
            [3, 6, 16, 10, 20, 50],  # track 6 takes over: a switch
            [4, 6, 60, 10, 20, 50],  # off the person: not covered
            [5, 5, 20, 10, 20, 50],  # track 5 again: a second switch
            [9, 6, 1, 1, 1, 1],  # a frame without the person
        ],
        dtype=float,
    )
    rows[1, 2] -= 10  # the wide box's left edge, its centre kept
    figures = holdout.target_identity(truth, rows)
    assert figures == {"covered": 0.8, "kept": 0.6, "switches": 2.0, "frames": 5.0}
    assert holdout.target_identity(truth, rows[:0])["covered"] == 0.0


@pytest.mark.slow
def test_the_benchmark_scores_ours_on_the_laid_out_sequences(holdout, tmp_path, capsys):
    refused = tmp_path / "env"  # no peers and no TrackEval: ours alone, scored here
    refused.mkdir()
    (refused / "something").write_text("not an environment\n")
    argv = ["--seeds", "1", "--frames", "30", "--results", str(tmp_path / "out"), "--json", "--",
            "--trackers", "ours", "--no-ours-reid", "--no-parity",
            "--mot-env", str(refused)]  # fmt: skip
    assert holdout.main(argv) == 0
    report = json.loads(capsys.readouterr().out)
    assert set(report["scores"]) == {"ours"}
    assert set(report["scores"]["ours"]) == set(report["sequences"])
    mean = report["summary"]["ours"]
    assert 0 <= mean["kept"] <= mean["covered"] <= 1
    assert mean["covered"] > 0.5  # the CNN's people followed in the first second


def test_the_documented_command_is_accepted(holdout):
    commands = documented_commands("holdout_people.py")
    assert commands  # docs/benchmarks.md gives the command of its table
    for argv in commands:
        assert holdout.parse_args(argv).seeds >= 1
