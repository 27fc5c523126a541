"""``benchmarks/otb.py`` on real OTB sequences: which sequences a command names."""

from __future__ import annotations

import json

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
