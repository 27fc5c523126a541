"""Live tracking of camera frames published on Zenoh (docs/architecture.md §7).

Each stream runs in its own worker process (:mod:`service.streams.worker`) with its own Zenoh
session; :class:`~service.streams.manager.StreamManager` starts, supervises and stops them.
"""
