"""When a supervisor replaces a dead worker: not while the service stops, and a worker that a
stop signal ended only once the service has had time to say that it stops. How a worker knows
that its service is gone, though the service is not its parent."""

from __future__ import annotations

import signal
import subprocess
import sys
import threading
import time

from devtools.testing import wait_for
from service.worker_processes import StopSignalDeaths, service_alive


def test_a_crash_is_replaced_at_once_and_a_stop_signal_death_after_the_grace():
    deaths = StopSignalDeaths(threading.Event(), grace=0.3)
    assert deaths.replace_now(100, -signal.SIGKILL)
    assert deaths.replace_now(101, 1)  # an exception in the worker
    assert not deaths.replace_now(102, -signal.SIGTERM)  # maybe the group's stop signal
    assert not deaths.replace_now(103, -signal.SIGINT)
    time.sleep(0.35)  # the grace runs out: the time passing is what is tested
    # no stop came: the signal was for that worker alone
    assert deaths.replace_now(102, -signal.SIGTERM)
    assert deaths.replace_now(103, -signal.SIGINT)


def test_nothing_is_replaced_once_the_service_stops():
    stop = threading.Event()
    deaths = StopSignalDeaths(stop, grace=0.3)
    assert not deaths.replace_now(102, -signal.SIGTERM)
    stop.set()
    time.sleep(0.35)  # the grace runs out: the time passing is what is tested
    assert not deaths.replace_now(102, -signal.SIGTERM)
    assert not deaths.replace_now(100, -signal.SIGKILL)


def test_a_worker_sees_its_service_end_though_it_is_not_its_parent():
    service = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(60)"])
    try:
        alive = service_alive(service.pid)
        assert alive() and alive()
    finally:
        service.kill()
    wait_for(lambda: not alive(), 10, "the service's end to be seen")  # before it is reaped
    service.wait()
    assert not service_alive(service.pid)()  # gone before the worker looked
