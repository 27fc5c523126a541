"""``benchmarks/otb.py`` on real OTB sequences: which sequences a command names, what its
command line refuses, the means per set of sequences, and OpenCV's MIL as a peer."""

from __future__ import annotations

import json
import sys

import numpy as np
import pytest

from tests.conftest import benchmark_module


@pytest.fixture(scope="module")
def otb():
    with benchmark_module("otb") as module:
        yield module


def _peer_env_ready() -> bool:
    """Whether the OpenCV peer environment (.venv-peers) is built with its current requirements
    (the test uses it, and will not spend minutes making it)."""
    with benchmark_module("_peer_env") as module:
        marker = module.DEFAULT_PEER_ENV / module.MARKER_FILE
        try:
            return json.loads(marker.read_text()) == {"requirements": module.peer_requirements()}
        except (OSError, ValueError, module.PeerEnvError):
            return False


@pytest.mark.slow
@pytest.mark.parametrize("names", [["Crossing,Deer"], ["Crossing", "Deer"], ["Crossing,", "Deer"]])
def test_sequences_are_named_with_spaces_or_commas(otb, shared_data, capsys, names):
    """As detection.py and mot.py take them (space-separated), or comma-separated."""
    code = otb.main(
        ["--data", str(shared_data / "otb"), "--trackers", "mosse_gray", "--no-peers", "--json",
         "--sequences", *names]
    )  # fmt: skip
    assert code == 0
    report = json.loads(capsys.readouterr().out)
    assert sorted(report["trackers"]["mosse_gray"]["sequences"]) == ["Crossing", "Deer"]


def test_plots_without_matplotlib_fail_before_tracking(otb, tmp_path, monkeypatch, capsys):
    monkeypatch.setitem(sys.modules, "matplotlib", None)  # import fails as if not installed
    with pytest.raises(SystemExit) as exit_info:
        otb.parse_args(["--plots", str(tmp_path)])
    assert exit_info.value.code == 2
    assert "--plots" in capsys.readouterr().err


@pytest.mark.slow
def test_set_means_are_the_means_over_the_runs_of_their_sequences(
    otb, shared_data, tmp_path, capsys
):
    """Each set is reported over the sequences of it that ran (``Name@frame`` runs with
    ``Name``), with the same means as over all sequences; a sequence in no set goes to "other"."""
    for name, source in [("Deer", "Deer"), ("Football1", "Football1"), ("Skiing", "Skiing"),
                         ("Unlisted", "Deer")]:  # fmt: skip
        (tmp_path / name).symlink_to(shared_data / "otb" / source)
    code = otb.main(
        ["--data", str(tmp_path), "--trackers", "mosse_gray", "--no-peers", "--json",
         "--sequences", "Deer,Football1,Unlisted", "--starts", "0,0.5"]
    )  # fmt: skip
    assert code == 0
    captured = capsys.readouterr()
    report = json.loads(captured.out)
    sets = {n: (e["sequences"], e["of"], e["runs"]) for n, e in report["sets"].items()}
    assert sets == {
        "first five": (["Deer"], 5, ["Deer", "Deer@36"]),
        "added later": (["Football1"], 5, ["Football1", "Football1@38"]),
        "other": (["Unlisted"], 1, ["Unlisted", "Unlisted@36"]),
    }
    per_sequence = report["trackers"]["mosse_gray"]["sequences"]
    for entry in report["sets"].values():
        means = entry["trackers"]["mosse_gray"]["mean"]
        for figure in ("dp", "op", "auc", "cle", "fps"):
            expected = np.mean([per_sequence[run][figure] for run in entry["runs"]])
            assert means[figure] == pytest.approx(expected), figure
    assert 'Means over the set "added later": 1 of 5 sequences, 2 runs' in captured.err


def test_mil_is_an_opencv_peer(otb, capsys):
    assert "mil" in otb.DEFAULT_PEERS
    assert otb.main(["--list"]) == 0
    peers = capsys.readouterr().out.split("peers: ")[1]
    assert "mil" in peers.strip().split(", ")


@pytest.mark.slow
@pytest.mark.skipif(not _peer_env_ready(), reason="the peer environment .venv-peers is not built")
def test_mil_runs_in_the_peer_environment(otb, shared_data, capsys):
    """OpenCV's MIL on Deer (71 frames): a box per frame, its default parameters recorded."""
    code = otb.main(
        ["--data", str(shared_data / "otb"), "--trackers", "mil", "--sequences", "Deer", "--json"]
    )
    assert code == 0
    report = json.loads(capsys.readouterr().out)
    mil = report["trackers"]["mil"]
    assert mil["source"] == "opencv"
    assert mil["complete"]
    assert mil["params"]["featureSetNumFeatures"] == 250  # OpenCV's default TrackerMIL_Params
    assert mil["sequences"]["Deer"]["frames"] == 71
    assert report["sets"]["first five"]["trackers"]["mil"]["mean"] == mil["mean"]
