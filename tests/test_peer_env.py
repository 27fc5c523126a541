"""The benchmarks' peer environments (``benchmarks/_peer_env.py``) rebuild only what they made."""

from __future__ import annotations

import pytest

from tests.conftest import benchmark_module


def test_a_folder_the_benchmarks_did_not_make_is_left_alone(tmp_path):
    """``--peer-env .venv`` must not empty the project's own environment."""
    folder = tmp_path / "mine"
    folder.mkdir()
    (folder / "precious.txt").write_text("keep")
    with benchmark_module("_peer_env") as peer_env:
        refused = pytest.raises(peer_env.PeerEnvError, match=r"not empty.*left alone")
        with refused:
            peer_env.ensure_env(folder, ["nothing==1"], "pass", "the peer environment")
    assert [p.name for p in folder.iterdir()] == ["precious.txt"]
