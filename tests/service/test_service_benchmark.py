"""``benchmarks/service.py``: a real service on loopback, DPM jobs side by side, one JSON object."""

from __future__ import annotations

import json
import subprocess
import sys

import pytest

from tests.conftest import BENCHMARKS, REPO_ROOT


@pytest.mark.slow
def test_times_jobs_side_by_side_with_the_dpm(shared_data, pets_short):
    options = {"detector": {"name": "dpm"}, "formats": ["json", "mot"]}
    command = [sys.executable, str(BENCHMARKS / "service.py"), "--video", str(pets_short)]
    command += ["--options", json.dumps(options), "--jobs", "2", "--json"]
    command += ["--dpm-model", str(shared_data / "dpm" / "INRIA" / "inriaperson_final.mat")]
    gt = shared_data / "mot" / "PETS09-S2L1" / "gt" / "gt.txt"
    command += ["--ground-truth", str(gt), "--gt-scale", "0.625"]
    result = subprocess.run(command, cwd=REPO_ROOT, capture_output=True, text=True, timeout=300)
    assert result.returncode == 0, result.stderr
    report = json.loads(result.stdout)
    assert report["jobs"] == 2 and report["frames"] == 8
    assert len(report["job_tracking_s"]) == 2
    assert report["tracking_s"] == max(report["job_tracking_s"]) > 0
    assert set(report["result_bytes"]) == {"json", "mot"}
    assert report["upload_to_result_s"] >= report["tracking_s"]
    # the downloaded tracks scored against the clip's 8 frames of ground truth: tracks are
    # confirmed after 3 detections, so the first frames find nobody and HOTA stays low
    assert 0 < report["det_a"] <= 100 and 0 < report["hota"] <= 100


@pytest.mark.parametrize(
    ("arguments", "message"),
    [
        (["--ground-truth", "missing/gt.txt"], "--ground-truth: no file"),
        (["--gt-scale", "0"], "--gt-scale must be positive, got 0.0"),
    ],
)
def test_bad_ground_truth_options_are_refused(pets_short, arguments, message):
    command = [sys.executable, str(BENCHMARKS / "service.py"), "--video", str(pets_short)]
    result = subprocess.run(
        command + arguments, cwd=REPO_ROOT, capture_output=True, text=True, timeout=60
    )
    assert result.returncode == 2
    assert message in result.stderr


def test_a_refused_upload_says_why(pets_short):
    # no model configured: the service refuses a DPM job, and the benchmark shows its reason
    command = [sys.executable, str(BENCHMARKS / "service.py"), "--video", str(pets_short)]
    command += ["--options", json.dumps({"detector": {"name": "dpm"}}), "--json"]
    result = subprocess.run(command, cwd=REPO_ROOT, capture_output=True, text=True, timeout=120)
    assert result.returncode != 0
    assert "VTRACK_DPM_MODEL" in result.stderr


def test_fewer_than_one_job_is_refused(pets_short):
    command = [sys.executable, str(BENCHMARKS / "service.py"), "--video", str(pets_short)]
    result = subprocess.run(
        [*command, "--jobs", "0"], cwd=REPO_ROOT, capture_output=True, text=True, timeout=60
    )
    assert result.returncode == 2
    assert "--jobs must be at least 1, got 0" in result.stderr
