"""``benchmarks/otb.py`` on real OTB sequences: which sequences a command names, and what its
command line refuses."""

from __future__ import annotations

import json
import sys

import pytest

from tests.conftest import benchmark_module


@pytest.fixture(scope="module")
def otb():
    with benchmark_module("otb") as module:
        yield module


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
