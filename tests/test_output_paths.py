"""Output checks of the command-line tools (tracking.output_paths), on the real file system."""

from __future__ import annotations

from pathlib import Path

import pytest

from tracking.output_paths import output_file, output_folder, staged_output


def test_a_missing_folder_is_created_with_its_parents_and_left_empty(tmp_path):
    folder = tmp_path / "results" / "today"
    assert output_folder(folder) == folder
    assert folder.is_dir() and not any(folder.iterdir())  # the write probe is gone


def test_an_existing_folder_keeps_its_files(tmp_path):
    (tmp_path / "keep.txt").write_text("x")
    output_folder(tmp_path)
    assert [p.name for p in tmp_path.iterdir()] == ["keep.txt"]


def test_a_file_in_the_way_of_a_folder_is_reported(tmp_path):
    blocker = tmp_path / "results"
    blocker.write_text("a file")
    with pytest.raises(NotADirectoryError, match="results exists and is not a folder"):
        output_folder(blocker)
    with pytest.raises(OSError, match=r"cannot create the folder .*results/today"):
        output_folder(blocker / "today")
    assert blocker.read_text() == "a file"


@pytest.mark.skipif(not Path("/proc/self").is_dir(), reason="needs Linux's /proc")
def test_a_folder_that_refuses_writes_is_reported():
    # /proc refuses new files even to root, for whom permission bits do not count
    with pytest.raises(OSError, match="cannot write into the folder /proc"):
        output_folder("/proc")
    with pytest.raises(OSError, match=r"cannot write /proc/results\.json"):
        output_file("/proc/results.json")


def test_a_new_file_is_checked_without_being_left_behind(tmp_path):
    path = tmp_path / "out.json"
    assert output_file(path) == path
    assert not path.exists()


def test_an_existing_file_is_left_as_it_is(tmp_path):
    path = tmp_path / "out.json"
    path.write_text("previous results")
    output_file(path)
    assert path.read_text() == "previous results"


def test_a_file_in_a_missing_folder_or_a_folder_as_file_is_reported(tmp_path):
    with pytest.raises(FileNotFoundError, match=r"the folder .*typo does not exist"):
        output_file(tmp_path / "typo" / "out.json")
    assert not (tmp_path / "typo").exists()  # a mistyped folder is not created
    with pytest.raises(IsADirectoryError, match="is a folder: give a file name"):
        output_file(tmp_path)


def test_a_file_named_as_long_as_its_folder_allows_is_staged_beside_it(tmp_path):
    name = "b" * 246 + ".csv"  # 250 bytes: legal; ".<name>.partial" would not be
    target, partial = staged_output(tmp_path / name)
    assert target == tmp_path / name and partial.parent == tmp_path
    partial.write_text("rows")  # before: File name too long
    partial.replace(target)
    assert target.read_text() == "rows"
