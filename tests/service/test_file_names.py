"""Files and folders of any name: colons (times in names), bytes that are not UTF-8 (names from
a Latin-1 system), spaces. ``vtrack`` in subprocesses (before, OpenCV crashed the process on a
name it could not encode) and a real service whose data folder has such a name."""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from devtools.testing import Server
from tests.service.conftest import FAST_OPTIONS, submit, wait_for_state

pytestmark = pytest.mark.slow

LATIN1 = os.fsdecode(b"cam\xe9ra")
"""``caméra`` as a Latin-1 system writes it: not UTF-8 (Python holds the byte as a
surrogate)."""


def vtrack(*args: str | Path, cwd: Path, encoding: str = "utf-8") -> subprocess.CompletedProcess:
    """``vtrack ARGS`` in ``cwd``, printing in ``encoding`` strictly, as Python does in a
    UTF-8 locale such as en_US.UTF-8 (in C and C.UTF-8 it escapes surrogates by itself)."""
    return subprocess.run(
        [sys.executable, "-m", "service.cli", *map(str, args)],
        capture_output=True,
        text=True,
        errors="surrogateescape",  # the names come back as the bytes they are
        timeout=300,
        cwd=cwd,
        env={**os.environ, "PYTHONIOENCODING": encoding},
    )


@pytest.mark.parametrize(
    "video, out_dir, encoding, printed",
    [
        # before: "not a video OpenCV can decode", then "Protocol not found" writing the mp4
        ("2026-11-26T08:00:00.avi", "2026-11-26T08:00:00", "utf-8", "2026-11-26T08:00:00"),
        # before: a segmentation fault, then a UnicodeEncodeError printing the folder
        (f"{LATIN1} 1.avi", f"r\u00e9sultats {LATIN1}", "utf-8", f"r\u00e9sultats {LATIN1}"),
        # an ASCII terminal; before: a UnicodeEncodeError once the results were written
        ("cam\u00e9ra.avi", "sortie \u00e9", "ascii", "sortie \\xe9"),
    ],
)
def test_analyze_reads_and_writes_files_of_any_name(
    pets_short, tmp_path, video, out_dir, encoding, printed
):
    shutil.copyfile(pets_short, tmp_path / video)
    result = vtrack(
        "analyze", video, "--out-dir", out_dir, "--format", "json,mp4,mcap", "--quiet",
        cwd=tmp_path, encoding=encoding,
    )  # fmt: skip
    assert result.returncode == 0, result.stderr
    assert sorted(p.name for p in (tmp_path / out_dir).iterdir()) == [
        "annotated.mp4",
        "tracks.mcap",
        "trajectories.json",
    ]
    assert f"json\t{printed}/trajectories.json" in result.stdout.splitlines()
    assert (tmp_path / out_dir / "annotated.mp4").stat().st_size > 1000


def test_track_reads_an_image_folder_of_any_name(shared_data, tmp_path):
    folder = tmp_path / f"Crossing {LATIN1}"
    (folder / "img").mkdir(parents=True)
    source = shared_data / "otb" / "Crossing"
    for index in range(1, 4):
        shutil.copyfile(source / "img" / f"{index:04d}.jpg", folder / "img" / f"{index:04d}.jpg")
    shutil.copyfile(source / "groundtruth_rect.txt", folder / "groundtruth_rect.txt")
    result = vtrack("track", folder.name, "--quiet", cwd=tmp_path)
    assert result.returncode == 0, result.stderr
    assert len(result.stdout.splitlines()) == 4  # header and three boxes


def test_a_service_whose_data_folder_is_not_named_in_utf8_takes_jobs(pets_short, tmp_path):
    # before: the upload's check crashed the whole service (OpenCV, segmentation fault)
    server = Server(tmp_path / f"donn\u00e9es {LATIN1}", workers=1).start()
    try:
        with server.client() as client:
            # a form sends a quote in a file name as %22 (before: kept so)
            name = 'cam\u00e9ra "1".avi'
            options = {**FAST_OPTIONS, "formats": ["json", "mp4"]}
            created = submit(client, pets_short, options, filename=name)
            assert created.status_code == 202, created.text
            job_id = created.json()["id"]
            done = wait_for_state(client, job_id, ("succeeded",))
            assert done["video_filename"] == name
            video = client.get(f"/v1/jobs/{job_id}/result?format=mp4")
            assert video.status_code == 200 and video.content[4:8] == b"ftyp"
    finally:
        server.stop()
