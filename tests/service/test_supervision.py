"""Supervision that survives a death (issue 78): the fork server killed, the service killed.

Killing the fork server marked the running jobs failed while their workers still ran; the
orphans (parent PID 1) went on claiming jobs with no time limit, beyond the worker limit. Now its
workers die with it, their jobs run again, a new fork server serves, and never more than
``workers`` workers run. Killing the service takes its fork server and workers with it, a worker
stopped mid-frame too.
"""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

from service.jobs.store import JobStore
from service.worker_processes import ProcessWatch
from tests.conftest import REPO_ROOT, process_alive
from tests.service.conftest import (
    FAST_OPTIONS,
    submit,
    wait_for,
    wait_for_frames,
)


def _children(pid: int) -> set[int]:
    children = set()
    try:
        tasks = os.listdir(f"/proc/{pid}/task")
    except (FileNotFoundError, ProcessLookupError):  # the process ended
        return children
    for task in tasks:  # each thread's own children
        try:
            with open(f"/proc/{pid}/task/{task}/children") as listed:
                children.update(int(child) for child in listed.read().split())
        except (FileNotFoundError, ProcessLookupError):  # a thread that ended meanwhile
            continue
    return children


def _fork_server(service: int) -> int | None:
    """The fork server among the service's children, ``None`` while there is none."""
    for child in _children(service):
        try:
            with open(f"/proc/{child}/cmdline", "rb") as cmdline:
                if b"multiprocessing.forkserver" in cmdline.read():
                    return child
        except FileNotFoundError:
            continue
    return None


def _parent(pid: int | None) -> int | None:
    """The parent of process ``pid``, ``None`` once it has ended (or for ``None``)."""
    try:
        with open(f"/proc/{pid}/stat") as stat:
            return int(stat.read().rsplit(") ", 1)[1].split()[1])
    except (FileNotFoundError, ProcessLookupError, IndexError):
        return None


def _holding(database: Path, besides: int) -> set[int]:
    """Processes other than ``besides`` with ``database`` open: the service's job workers
    (stream workers too, of which these tests start none), wherever they are in the tree."""
    target = str(database)
    holders = set()
    for entry in os.listdir("/proc"):
        if not entry.isdigit() or int(entry) == besides:
            continue
        try:
            for fd in os.listdir(f"/proc/{entry}/fd"):
                if os.readlink(f"/proc/{entry}/fd/{fd}") == target:
                    holders.add(int(entry))
                    break
        except (FileNotFoundError, ProcessLookupError, PermissionError):
            continue
    return holders


def _worker_of(server, job: str) -> int:
    store = JobStore(server.data_dir / "jobs.sqlite3")
    try:
        return store.get(job).worker_pid
    finally:
        store.close()


@pytest.mark.slow
def test_the_fork_server_killed_its_workers_go_their_jobs_run_again_within_the_limit(
    make_server, long_video, pets_short
):
    server = make_server(workers=2)
    service = server.process.pid
    database = server.data_dir / "jobs.sqlite3"
    with server.client() as client:
        doomed = submit(client, long_video, FAST_OPTIONS).json()["id"]
        wait_for_frames(client, doomed, 3)
        fork_server = _fork_server(service)
        old = _children(fork_server)
        assert len(old) == 2 and _holding(database, service) == old
        os.kill(fork_server, signal.SIGKILL)
        # its workers die with it, at once: no orphan (parent PID 1) lives on
        wait_for(
            lambda: not any(process_alive(pid) for pid in old),
            10,
            "the fork server's workers to end with it",
            0.05,
        )
        waiting = [submit(client, pets_short, FAST_OPTIONS).json()["id"] for _ in range(3)]
        jobs = [doomed, *waiting]

        peak = {"workers": 0, "running": 0}

        def finished():
            # every look: no job failed, no worker beyond the limit, none outside the tree; the
            # states of one listing (one query): read job by job, a job that ends between two
            # reads and the next that starts would both count as running
            listed = client.get("/v1/jobs", params={"limit": 1000}).json()["jobs"]
            states = {job["id"]: job["state"] for job in listed if job["id"] in jobs}
            assert len(states) == len(jobs), states
            assert "failed" not in states.values(), states
            running = sum(state == "running" for state in states.values())
            workers = _holding(database, service)
            parents = {pid: _parent(pid) for pid in workers}
            # forked by a fork server of the service, not left to PID 1
            strays = {pid: ppid for pid, ppid in parents.items() if _parent(ppid) != service}
            assert not strays, f"workers whose parent is no child of the service: {strays}"
            peak["workers"] = max(peak["workers"], len(workers))
            peak["running"] = max(peak["running"], running)
            assert len(workers) <= 2 and running <= 2, (workers, states)
            return all(state == "succeeded" for state in states.values()) and states

        wait_for(finished, 120, "the jobs to succeed after the fork server's death", 0.1)
        assert _fork_server(service) not in (None, fork_server)  # a new one serves
        assert peak == {"workers": 2, "running": 2}
        status = client.get(f"/v1/jobs/{doomed}").json()
        assert status["attempts"] == 2 and status["error"] is None, status
        assert client.get(f"/v1/jobs/{doomed}/result").json()["frames_processed"] == 150
        assert client.get("/readyz").json()["workers_ready"] == 2
    log = server.log()
    assert f"job {doomed} queued again: the fork server {fork_server} died" in log
    assert f"the fork server {fork_server} had ended; a new one" in log


@pytest.mark.slow
def test_the_service_killed_its_fork_server_and_workers_end_a_stopped_one_too(
    make_server, long_video
):
    # Workers used to leave only when they next looked at their service, between frames: never
    # one stopped (SIGSTOP) or stuck inside a frame, and the fork server stayed while one lived.
    server = make_server(workers=2)
    with server.client() as client:
        job = submit(client, long_video, FAST_OPTIONS).json()["id"]
        wait_for_frames(client, job, 3)
    fork_server = _fork_server(server.process.pid)
    workers = _children(fork_server)
    assert len(workers) == 2
    os.kill(_worker_of(server, job), signal.SIGSTOP)
    server.kill()
    left = {fork_server, *workers}
    try:
        wait_for(
            lambda: not any(process_alive(pid) for pid in left),
            5,
            "the fork server and the workers to end with their service",
            0.05,
        )
    finally:
        for pid in filter(process_alive, left):  # not to outlive the test, stopped
            os.kill(pid, signal.SIGKILL)


_FORK_SERVER_SCRIPT = textwrap.dedent(
    """
    import os, signal, threading, time
    from service.worker_processes import ProcessWatch, fork_server_pid, worker_context

    context = worker_context()
    context.set_forkserver_preload(["service.fork_server"])  # the tracking code is not needed

    def one_worker():
        worker = context.Process(target=os.getpid)
        worker.start()
        worker.join(60)
        return worker.exitcode

    # started by a thread that ends once the fork server runs: Linux sends the fork server its
    # parent-death signal then, and it must not take that for the service's death
    thread = threading.Thread(target=one_worker)
    thread.start()
    thread.join()
    first = fork_server_pid()
    print("after the thread", first, one_worker(), fork_server_pid(), flush=True)

    sleeper = context.Process(target=time.sleep, args=(60,))
    sleeper.start()
    watch = ProcessWatch(sleeper.pid)
    os.kill(first, signal.SIGKILL)
    started = time.monotonic()
    print("worker ended", watch.wait(10), time.monotonic() - started < 5, flush=True)
    sleeper.join(10)
    print("reported", sleeper.exitcode, flush=True)
    # ensure_running sees the fork server's pid ended (it is its zombie child) and starts one
    code = one_worker()
    print("restarted", code, fork_server_pid() not in (None, first), flush=True)
    """
)


def test_the_fork_server_outlives_the_thread_that_started_it_and_restarts_after_its_death():
    done = subprocess.run(
        [sys.executable, "-c", _FORK_SERVER_SCRIPT],
        cwd=REPO_ROOT,
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert done.returncode == 0, done.stderr
    lines = done.stdout.splitlines()
    first, code, same = lines[0].split()[3:]
    assert code == "0" and same == first, lines  # the same fork server forked a second worker
    assert lines[1:] == ["worker ended True True", "reported 255", "restarted 0 True"], lines


def test_a_process_watch_sees_the_end_not_the_reaping_and_kills_only_its_process():
    # a worker's supervisor is not its parent: it sees the end (a zombie has ended) without
    # reaping, and its kill cannot reach a process that took the pid since
    child = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(60)"])
    watch = ProcessWatch(child.pid)
    try:
        assert watch.alive() and not watch.wait(0.05)
        watch.kill()
        assert watch.wait(10) and not watch.alive()
        assert child.poll() is None or child.returncode == -signal.SIGKILL  # maybe not reaped
        child.wait(10)
        watch.kill()  # nothing to kill: no error, nobody else's process
        assert not watch.alive()
    finally:
        watch.close()
        child.kill()
        child.wait()
    gone = ProcessWatch(child.pid)  # opened after the end
    assert not gone.alive() and gone.wait(0)
    gone.close()
