"""Uploads are probed in helper processes: a file on which the decoder hangs or crashes costs
that upload, never the service. Real helper processes, real files; a named pipe that never
delivers a byte is a decoder that waits for ever, and SIGSEGV sent to the helper meanwhile is a
decoder that crashes."""

from __future__ import annotations

import os
import signal
import threading
import time

import pytest

from devtools.testing import wait_for
from service.frames import FrameSourceError, open_frames
from service.jobs.probing import ProbeInterrupted, VideoProber


@pytest.fixture
def prober():
    prober = VideoProber(processes=2, timeout=3.0)
    yield prober
    prober.close()


def _helpers() -> set[int]:
    """Pids of this test's live probe helpers (children named vtrack-probe)."""
    import multiprocessing

    return {p.pid for p in multiprocessing.active_children() if p.name == "vtrack-probe"}


def test_a_video_is_probed_and_a_non_video_refused_with_its_reason(prober, pets_short, tmp_path):
    source = prober.probe(pets_short)
    assert (source.frame_count, source.width, source.height) == (8, 480, 360)
    junk = tmp_path / "junk.avi"
    junk.write_bytes(b"\x00not a video" * 500)
    for bad in (junk, pets_short.with_suffix(".none")):  # not a video; no such file
        with pytest.raises(FrameSourceError) as here:
            open_frames(bad)
        with pytest.raises(FrameSourceError) as refused:
            prober.probe(bad)
        assert (str(refused.value), refused.value.reason) == (str(here.value), here.value.reason)
    assert prober.probe(pets_short).frame_count == 8  # the same helper goes on
    assert len(_helpers()) == 1


def test_a_file_that_hangs_the_decoder_ends_after_the_timeout(prober, pets_short, tmp_path):
    never = tmp_path / "never.avi"
    os.mkfifo(never)  # opening it waits for a writer that never comes
    started = time.monotonic()
    with pytest.raises(FrameSourceError, match="took more than 3 s") as hung:
        prober.probe(never)
    assert 3 <= time.monotonic() - started < 10
    assert "did not read its first frame in 3 s" in hung.value.reason
    assert not _helpers()  # the hung helper was killed
    assert prober.probe(pets_short).frame_count == 8  # by a new one


def test_a_file_that_crashes_the_decoder_is_refused_and_the_next_one_probed(
    prober, pets_short, tmp_path
):
    prober.probe(pets_short)  # a helper is up
    (helper,) = _helpers()
    never = tmp_path / "never.avi"
    os.mkfifo(never)
    threading.Timer(0.5, os.kill, (helper, signal.SIGSEGV)).start()
    with pytest.raises(FrameSourceError, match=r"crashed on it \(killed by SIGSEGV\)") as crash:
        prober.probe(never)
    assert "a damaged or crafted file" in crash.value.reason
    assert prober.probe(pets_short).frame_count == 8
    assert _helpers() and helper not in _helpers()


def test_probes_at_once_use_at_most_the_helpers_allowed(pets_short, tmp_path):
    prober = VideoProber(processes=2, timeout=2.0)
    try:
        hanging = []
        for name in ("a.avi", "b.avi"):
            os.mkfifo(tmp_path / name)
            hanging.append(tmp_path / name)
        errors = []

        def probe(path):
            try:
                prober.probe(path)
            except FrameSourceError as error:
                errors.append(error)

        threads = [threading.Thread(target=probe, args=(p,)) for p in hanging]
        for thread in threads:
            thread.start()
        wait_for(lambda: len(_helpers()) == 2, 10, "a helper for each hanging probe")
        started = time.monotonic()
        assert prober.probe(pets_short).frame_count == 8  # waits for a helper to be free
        assert time.monotonic() - started >= 0.5
        for thread in threads:
            thread.join()
        assert len(errors) == 2
        assert len(_helpers()) == 1
    finally:
        prober.close()
    assert not _helpers()


def test_a_stop_signal_to_a_starting_helper_is_not_the_files_fault(prober, pets_short, tmp_path):
    # Ctrl-C or systemctl stop signal the service's whole process group; a helper still
    # starting (importing) does not ignore them yet
    outcome = []

    def probe():
        try:
            prober.probe(pets_short)
        except Exception as error:
            outcome.append(error)

    thread = threading.Thread(target=probe)
    thread.start()
    wait_for(_helpers, 30, "the helper to start", interval=0.002)
    (helper,) = _helpers()
    os.kill(helper, signal.SIGTERM)
    thread.join(30)
    (error,) = outcome
    assert isinstance(error, ProbeInterrupted) and "killed by SIGTERM" in str(error)
    assert prober.probe(pets_short).frame_count == 8
