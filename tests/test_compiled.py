"""Ctrl-C during the compiled kernels is a KeyboardInterrupt, not numba's SystemError."""

from __future__ import annotations

import signal
import subprocess
import sys
import textwrap
import time

import pytest

from tests.conftest import REPO_ROOT, sigint_as_in_a_terminal

# Each program calls the library in a loop (its kernels take most of the time, so the interrupt
# lands in one) and says when it has been interrupted the way Python programs expect.
LOOP = """
print("running", flush=True)
try:
    while True:
        work()
except KeyboardInterrupt:
    print("interrupted", flush=True)
"""
HOG = """
import numpy as np
from tracking.features.hog import hog_feature_map
image = np.random.default_rng(0).integers(0, 256, (2000, 2000, 3), dtype=np.uint8)
hog_feature_map(image[:64, :64])
def work():
    hog_feature_map(image)
"""
DPM = """
import cv2
from tracking.detection.dpm.config import DpmConfig
from tracking.detection.dpm.detector import DpmDetector
from tracking.detection.dpm.model import load_dpm_model
frame = cv2.imread("{frame}")[:, :, ::-1]
frame = cv2.resize(frame, None, fx=2.0, fy=2.0)  # seconds per frame: room to land in a kernel
detector = DpmDetector(load_dpm_model("{model}"), DpmConfig(workers=1, cascade={cascade}))
detector.detect(frame[:200, :200])
def work():
    detector.detect(frame)
"""


def _interrupted(program: str) -> subprocess.CompletedProcess:
    """Run ``program``, press Ctrl-C once it is working, and return how it ended."""
    process = subprocess.Popen(
        [sys.executable, "-c", textwrap.dedent(program) + LOOP],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        cwd=REPO_ROOT,
        preexec_fn=sigint_as_in_a_terminal,
    )
    try:
        assert process.stdout.readline() == "running\n", process.stderr.read()
        # a pause, not a wait for a condition: the program gives no sign of being inside a
        # kernel, and the interrupt must land there (its first call returned before "running")
        time.sleep(0.5)
        process.send_signal(signal.SIGINT)
        stdout, stderr = process.communicate(timeout=60)
    finally:
        if process.poll() is None:
            process.kill()
            process.communicate()
    return subprocess.CompletedProcess(process.args, process.returncode, stdout, stderr)


def test_ctrl_c_in_the_hog_features_is_a_keyboard_interrupt():
    # before: SystemError: CPUDispatcher(<function _features ...>) returned a result with an
    # exception set (numba builds the returned list of maps by calling back into Python)
    ended = _interrupted(HOG)
    assert (ended.returncode, ended.stdout, ended.stderr) == (0, "interrupted\n", "")


@pytest.mark.parametrize("cascade", [False, True], ids=["exact", "cascade"])
def test_ctrl_c_in_the_dpm_detector_is_a_keyboard_interrupt(shared_data, cascade):
    # before: the same SystemError from exact_component, cascade_roots or the features
    program = DPM.format(
        frame=shared_data / "mot" / "PETS09-S2L1" / "img1" / "000001.jpg",
        model=shared_data / "dpm" / "INRIA" / "inriaperson_final.mat",
        cascade=cascade,
    )
    ended = _interrupted(program)
    assert (ended.returncode, ended.stdout, ended.stderr) == (0, "interrupted\n", "")
