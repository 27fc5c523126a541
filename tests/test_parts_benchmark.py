"""``benchmarks/parts.py``: how often the pose network places each part of a tracked person."""

from __future__ import annotations

import json

import pytest

from tests.conftest import benchmark_module


@pytest.fixture(scope="module")
def parts():
    with benchmark_module("parts") as module:
        yield module


@pytest.mark.slow
def test_the_benchmark_counts_measured_parts_of_unoccluded_people(parts, capsys):
    assert parts.main(["--frames", "8", "--json"]) == 0
    figures = json.loads(capsys.readouterr().out)
    assert figures["frames"] == 8 and figures["person_frames"] > 10
    for group in parts.GROUPS:
        # a group measured in every keypoint is measured in any of them
        assert 0 <= figures["measured_all"][group] <= figures["measured_any"][group] <= 1
    assert figures["measured_any"]["hips"] > 0.5  # the pose network finds PETS people's hips
    assert figures["ratio_to_real_time"] > 0
    # the machine the speed was measured on, so that two machines' figures are told apart
    machine = figures["machine"]
    assert machine["cpu"] and machine["cpu_count"] >= 1 and machine["openvino"]
    assert set(machine["cpu_flags"]) <= {
        "avx2", "avx512f", "avx512_vnni", "avx512_bf16", "amx_bf16", "amx_int8"
    }  # fmt: skip


def test_missing_models_are_an_argument_error(parts, tmp_path, capsys):
    with pytest.raises(SystemExit) as exit_info:
        parts.main(["--models", str(tmp_path)])
    assert exit_info.value.code == 2
    assert "models not found" in capsys.readouterr().err
