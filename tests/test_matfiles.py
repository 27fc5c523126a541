"""Reading users' MATLAB files: every failure is a ValueError that says why."""

from pathlib import Path

import numpy as np
import pytest
import scipy.io

from tracking.matfiles import read_mat

# The start of a file written by MATLAB's save -v7.3: header text, subsystem offset, version
# 0x0200, endianness, then the HDF5 superblock at byte 512.
_V73_TEXT = b"MATLAB 7.3 MAT-file, Platform: GLNXA64, HDF5 schema 1.00 ."
V73_FILE = (_V73_TEXT.ljust(116) + bytes(8) + b"\x00\x02IM").ljust(512, b"\x00") + (
    b"\x89HDF\r\n\x1a\n" + bytes(56)
)


def test_reads_a_v5_file(tmp_path: Path):
    path = tmp_path / "a.mat"
    scipy.io.savemat(path, {"w": np.arange(3.0)})
    np.testing.assert_array_equal(read_mat(path)["w"], [[0.0, 1.0, 2.0]])


@pytest.mark.parametrize(
    ("content", "message"),
    [
        (V73_FILE, r"v7\.3 \(HDF5\).*save -v7"),  # says how to save it again
        (b"\x00garbage" * 64, "not a readable MATLAB v5/v7 file"),
        (b"", "not a readable MATLAB v5/v7 file"),
    ],
)
def test_unreadable_files_raise_value_error_with_the_reason(tmp_path: Path, content, message):
    path = tmp_path / "m.mat"
    path.write_bytes(content)
    with pytest.raises(ValueError, match=message):
        read_mat(path)
