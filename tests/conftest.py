"""Shared fixtures: where the third-party reference data lives; the benchmark scripts as modules.

With ``-n 2`` (pytest-xdist, the README's test command) two workers share the machine; tests
marked ``realtime`` run alone (:func:`pytest_runtest_protocol`).

Tests read `../shared/data` beside the checkout (CI puts it there) or the folder named by
``VTRACK_SHARED_DATA``. A missing folder fails loudly rather than skipping: a test that cannot see
its data has not shown anything.
"""

from __future__ import annotations

import contextlib
import fcntl
import importlib.util
import os
import shlex
import shutil
import signal
import sys
import tempfile
from collections.abc import Iterator
from pathlib import Path
from types import ModuleType

import pytest

REPO_ROOT = Path(__file__).resolve().parents[1]
BENCHMARKS = REPO_ROOT / "benchmarks"


def sigint_as_in_a_terminal() -> None:
    """For ``subprocess.Popen(preexec_fn=...)`` of a program the test presses Ctrl-C in: SIGINT
    as in a terminal, also where the tests run as a background job, which ignores SIGINT and
    hands that on to every program it starts."""
    signal.signal(signal.SIGINT, signal.SIG_DFL)


def process_alive(pid: int) -> bool:
    """Whether process ``pid`` runs: a zombie (dead, not yet reaped) and a process reaped
    between the two looks count as gone."""
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    try:
        with open(f"/proc/{pid}/stat") as stat:
            return stat.read().split(") ", 1)[1][0] != "Z"  # the name may hold spaces
    except FileNotFoundError:
        return False


def copy_mot_sequence(shared_data: Path, folder: Path, frames: int) -> Path:
    """The first ``frames`` frames of TUD-Stadtmitte with its gt/ and det/ (to break a copy)."""
    source = shared_data / "mot" / "TUD-Stadtmitte"
    (folder / "img1").mkdir(parents=True)
    for index in range(1, frames + 1):
        name = f"img1/{index:06d}.jpg"
        shutil.copyfile(source / name, folder / name)
    text = (source / "seqinfo.ini").read_text()
    (folder / "seqinfo.ini").write_text(text.replace("seqLength=179", f"seqLength={frames}"))
    for part in ("gt/gt.txt", "det/det.txt"):
        (folder / part).parent.mkdir()
        shutil.copyfile(source / part, folder / part)
    return folder


def documented_commands(script: str) -> list[list[str]]:
    """The arguments of every ``python benchmarks/<script>`` command in docs/benchmarks.md, the
    current results (lines joined at a trailing backslash, comments and backticks dropped).
    docs/benchmarks-history.md is history: its commands may name options that are gone."""
    text = (REPO_ROOT / "docs" / "benchmarks.md").read_text().replace("\\\n", " ")
    commands = []
    for line in text.splitlines():
        start = line.find(f"python benchmarks/{script}")
        if start >= 0:
            command = line[start:].split(" #")[0].split("`")[0]
            commands.append(shlex.split(command)[2:])
    return commands


@contextlib.contextmanager
def benchmark_module(name: str) -> Iterator[ModuleType]:
    """``benchmarks/<name>.py`` loaded as a module (the scripts are not a package), with its
    folder on the import path for its siblings; both undone afterwards."""
    sys.path.insert(0, str(BENCHMARKS))
    spec = importlib.util.spec_from_file_location(f"{name}_benchmark", BENCHMARKS / f"{name}.py")
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module  # dataclasses look their module up
    try:
        spec.loader.exec_module(module)
        yield module
    finally:
        sys.modules.pop(spec.name, None)
        sys.path.remove(str(BENCHMARKS))


@pytest.fixture
def drawing_packages(monkeypatch: pytest.MonkeyPatch) -> None:
    """Empty stand-ins for Pillow and matplotlib where they are not installed (they come with the
    bench extra, not the test set-up), for tests of the benchmarks' command lines: a drawing
    option is refused unless its package imports (``benchmarks/_drawing.py``)."""
    for name in ("PIL", "matplotlib"):
        if importlib.util.find_spec(name) is None:
            monkeypatch.setitem(sys.modules, name, ModuleType(name))


def _shared_data_root() -> Path:
    configured = os.environ.get("VTRACK_SHARED_DATA")
    return Path(configured) if configured else REPO_ROOT.parent / "shared" / "data"


@pytest.fixture(scope="session")
def shared_data() -> Path:
    """Root of the shared reference data (MOT, OTB, Color Names, DPM models, video)."""
    root = _shared_data_root()
    if not (root / "README.md").is_file():
        pytest.fail(f"shared reference data not found at {root}; set VTRACK_SHARED_DATA")
    return root


class _CpuShare:
    """Who may use the machine, across the xdist workers of one run: a writer-preferring
    readers-writer lock on two files. Most tests share it; a ``realtime`` test (a camera at its
    frame rate, a tracker that must keep pace, delays measured in milliseconds) has it alone,
    since a test beside it on the other core would take the time it measures."""

    def __init__(self, folder: Path) -> None:
        self.folder = folder
        folder.mkdir(exist_ok=True)
        # the gate keeps new sharers out while a realtime test waits for the running ones
        self._gate = open(folder / "gate", "a")  # noqa: SIM115 - held for the worker's life
        self._share = open(folder / "share", "a")  # noqa: SIM115

    @contextlib.contextmanager
    def held(self, alone: bool) -> Iterator[None]:
        fcntl.flock(self._gate, fcntl.LOCK_EX)
        fcntl.flock(self._share, fcntl.LOCK_EX if alone else fcntl.LOCK_SH)
        if not alone:
            fcntl.flock(self._gate, fcntl.LOCK_UN)
        try:
            yield
        finally:
            fcntl.flock(self._share, fcntl.LOCK_UN)
            if alone:
                fcntl.flock(self._gate, fcntl.LOCK_UN)


_cpu_share: _CpuShare | None = None


def pytest_collection_modifyitems(items: list[pytest.Item]) -> None:
    """Modules with ``realtime`` tests last. pytest-xdist hands out modules in this order
    (``--no-loadscope-reorder`` in pyproject.toml: by default it sends the modules with the
    most tests first, which put the live stream modules early). A realtime test in the middle
    of the run waits for the test running on the other worker (the Dockerfile replay: over a
    minute) while neither core does anything else, and the other worker then waits for it.
    Last, they wait only for each other."""
    realtime = {item.path for item in items if item.get_closest_marker("realtime")}
    items.sort(key=lambda item: item.path in realtime)  # stable: each module keeps its order


@pytest.hookimpl(hookwrapper=True, tryfirst=True)
def pytest_runtest_protocol(item: pytest.Item, nextitem: pytest.Item | None):
    """Around setup, call and teardown (module fixtures start and stop in them): under
    pytest-xdist, the share of the machine :class:`_CpuShare` gives this test."""
    global _cpu_share
    run = os.environ.get("PYTEST_XDIST_TESTRUNUID")  # the same in every worker of a run
    if run is None:
        yield
        return
    if _cpu_share is None:
        _cpu_share = _CpuShare(Path(tempfile.gettempdir()) / f"vtrack-tests-{run}")
    with _cpu_share.held(alone=item.get_closest_marker("realtime") is not None):
        yield


def pytest_sessionfinish(session: pytest.Session) -> None:
    """The lock files go with the run: a worker still running holds them open."""
    if _cpu_share is not None:
        shutil.rmtree(_cpu_share.folder, ignore_errors=True)
