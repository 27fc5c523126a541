"""Imported first by the fork server the service starts its workers from
(:func:`service.worker_processes.worker_context`), for one effect: it ignores SIGINT and SIGTERM.

Ctrl-C and a service manager's SIGTERM reach every process of the service's group. A fork
server that died of one would take its workers' exit statuses with it: to their supervisors,
every worker would look dead (exit code 255) while it still ran. Ignoring both, the fork server
lives until the service and the last of its workers are gone, and every worker it forks starts
with both ignored, as :func:`service.worker_processes.ignore_stop_signals` has them.
"""

import signal

signal.signal(signal.SIGINT, signal.SIG_IGN)
signal.signal(signal.SIGTERM, signal.SIG_IGN)
