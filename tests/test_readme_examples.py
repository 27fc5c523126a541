"""The README's upload example and the Python examples of docs/usage.md run as written, on real
frames."""

from __future__ import annotations

import contextlib
import io
import json
import re
import shlex
import subprocess

import cv2
import numpy as np
import pytest

from api_schemas.tracks import Trajectories
from devtools.clips import cut_video
from devtools.testing import Server, wait_for
from tests.conftest import REPO_ROOT
from tests.service.conftest import PETS_VIDEO

PETS = ("mot", "PETS09-S2L1")


def _examples() -> list[str]:
    """The ``python`` blocks of docs/usage.md's section on using the trackers from Python."""
    usage = (REPO_ROOT / "docs" / "usage.md").read_text()
    section = usage.split("## Using the trackers from Python", 1)[1].split("\n## ", 1)[0]
    return re.findall(r"```python\n(.*?)```", section, flags=re.DOTALL)


def _upload_example() -> list[str]:
    """The ``curl`` lines of the README's quick start: upload, status, result."""
    readme = (REPO_ROOT / "README.md").read_text()
    section = readme.split("## Quick start", 1)[1].split("\n## ", 1)[0]
    blocks = re.findall(r"```bash\n(.*?)```", section, flags=re.DOTALL)
    return [line for block in blocks for line in block.splitlines() if line.startswith("curl ")]


def _pets_frames(shared_data, count: int) -> list[np.ndarray]:
    folder = shared_data.joinpath(*PETS, "img1")
    return [cv2.imread(str(p))[:, :, ::-1].copy() for p in sorted(folder.glob("*.jpg"))[:count]]


def test_the_readme_has_both_examples():
    assert [("CorrelationTracker" in e, "MultiPersonTracker" in e) for e in _examples()] == [
        (True, False),
        (False, True),
    ]


def test_the_single_target_example_follows_the_box_it_is_given(shared_data):
    frames = _pets_frames(shared_data, 10)
    truth = np.loadtxt(shared_data.joinpath(*PETS, "gt", "gt.txt"), delimiter=",")
    first = truth[(truth[:, 0] == 1) & (truth[:, 1] == truth[truth[:, 0] == 1][0, 1])][0]
    namespace = {"first_frame_rgb": frames[0], "frames": frames[1:]}
    namespace.update(zip("xywh", map(float, first[2:6]), strict=True))
    exec(_examples()[0], namespace)
    box = namespace["out"].box
    assert abs(box.x - first[2]) < first[4] and abs(box.y - first[3]) < first[5]


def test_the_people_example_prints_the_people_of_a_video(shared_data, tmp_path):
    video = tmp_path / "street.avi"
    frames = _pets_frames(shared_data, 12)
    writer = cv2.VideoWriter(str(video), cv2.VideoWriter_fourcc(*"MJPG"), 7.0, (768, 576))
    for frame in frames:
        writer.write(frame[:, :, ::-1])
    writer.release()
    code = _examples()[1].replace('"street.avi"', repr(str(video)))
    printed = io.StringIO()
    with contextlib.redirect_stdout(printed):
        exec(code, {})
    rows = [line.split(" ", 2) for line in printed.getvalue().splitlines()]
    # PETS09-S2L1 starts with several people walking: tracks are confirmed within 12 frames
    assert rows and {int(index) for index, _, _ in rows} <= set(range(12))
    assert len({track for _, track, _ in rows}) >= 2
    assert all(rest.startswith("Box(") for _, _, rest in rows)


def test_the_people_example_says_when_it_cannot_read_the_video(tmp_path):
    code = _examples()[1].replace('"street.avi"', repr(str(tmp_path / "missing.avi")))
    # before: it printed nothing, as for a video without people
    with pytest.raises(SystemExit, match="cannot read"):
        exec(code, {})


def test_the_readme_upload_example_returns_the_tracks(shared_data, tmp_path):
    """The README's three curl commands, against a real service, on a cut of the same video
    (its 8 first frames, so that the job takes seconds)."""
    upload, status, result = _upload_example()
    video = cut_video(shared_data / PETS_VIDEO, tmp_path / "pets_8.avi", 8)
    server = Server(tmp_path / "data", workers=1).start()
    try:

        def run(line: str, job_id: str = "") -> str:
            line = line.replace("http://127.0.0.1:8000", server.url).replace("JOB_ID", job_id)
            line = line.replace("../shared/data/video/pets09_s2l1_480x360.avi", str(video))
            argv = shlex.split(line.split(" #")[0])
            done = subprocess.run(argv, cwd=tmp_path, capture_output=True, text=True, timeout=60)
            assert done.returncode == 0, done.stderr
            return done.stdout

        job = json.loads(run(upload))
        assert job["state"] in ("queued", "running")

        def finished() -> dict | None:
            body = json.loads(run(status, job["id"]))
            return body if body["state"] in ("succeeded", "failed", "cancelled") else None

        final = wait_for(finished, 120, "the README's job to finish", interval=0.2)
        assert final["state"] == "succeeded", final
        run(result, job["id"])
    finally:
        server.stop()
    tracks = Trajectories.model_validate_json((tmp_path / "tracks.json").read_text())
    assert tracks.frames_processed == 8
