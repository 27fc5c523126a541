"""Imported first by the fork server the service starts its workers from
(:func:`service.worker_processes.worker_context`), for two effects: it ignores SIGINT and
SIGTERM, and it ties the fork server's life to the service's and each worker's to the fork
server's.

Ctrl-C and a service manager's SIGTERM reach every process of the service's group. A fork
server that died of one would take its workers' exit statuses with it: to their supervisors,
every worker would look dead (exit code 255) while it still ran. Ignoring both, the fork server
lives until the service is gone, and every worker it forks starts with both ignored, as
:func:`service.worker_processes.ignore_stop_signals` has them.

When the service dies (``kill -9``), its fork server gets
:data:`~service.worker_processes.SERVICE_DEATH_SIGNAL` and ends; when the fork server dies (``kill
-9``, the OOM killer), every process it forked gets SIGKILL. Both are parent-death signals
(:func:`~service.worker_processes.set_parent_death_signal`), set at the earliest moment: here as
the fork server starts, and in each worker inside the ``fork()`` that made it, before it reads
what it is to run. :mod:`service.worker_processes` explains the design.
"""

import os
import signal

from service.worker_processes import SERVICE_DEATH_SIGNAL, set_parent_death_signal

signal.signal(signal.SIGINT, signal.SIG_IGN)
signal.signal(signal.SIGTERM, signal.SIG_IGN)

_SERVICE_PID = os.getppid()
"""The service process: the fork server's parent (a thread of it started the fork server)."""
_FORK_SERVER_PID = os.getpid()
_forked = False  # set in each process the fork server forks, and so in what they fork


def _service_gone(signum: int, frame: object) -> None:
    """The parent-death signal: the fork server ends if its parent is another process now, not
    if only the thread of the service that started it ended (its parent is then another
    thread of the same process, with the same pid)."""
    if os.getppid() != _SERVICE_PID:
        os._exit(0)  # its workers get SIGKILL (_die_with_fork_server)


def _die_with_fork_server() -> None:
    """In a process just forked: SIGKILL when the fork server ends. Only in the fork server's
    own children: what a worker forks is the worker's business."""
    global _forked
    if _forked:
        return
    _forked = True
    signal.signal(SERVICE_DEATH_SIGNAL, signal.SIG_DFL if _before is None else _before)
    set_parent_death_signal(signal.SIGKILL)
    if os.getppid() != _FORK_SERVER_PID:  # it ended before the signal was set: none comes
        os.kill(os.getpid(), signal.SIGKILL)


_before = signal.signal(SERVICE_DEATH_SIGNAL, _service_gone)
# The service may have died before _SERVICE_PID was read (this module is imported a second or
# so after the fork server started): that is caught by the fork server's own end, when the last
# holder of its "alive" pipe, the service and each of the workers, is gone; a worker forked in
# that moment finds its service gone as it starts (service_alive).
if set_parent_death_signal(SERVICE_DEATH_SIGNAL) and os.getppid() != _SERVICE_PID:
    os._exit(0)
os.register_at_fork(after_in_child=_die_with_fork_server)
