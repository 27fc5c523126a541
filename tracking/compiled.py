"""Calling the numba-compiled kernels from Python so that Ctrl-C stays a KeyboardInterrupt."""

from __future__ import annotations

from collections.abc import Callable
from typing import ParamSpec, TypeVar

__all__ = ["call_kernel"]

P = ParamSpec("P")
R = TypeVar("R")


def call_kernel(kernel: Callable[P, R], *args: P.args, **kwargs: P.kwargs) -> R:
    """``kernel(*args, **kwargs)``, for a compiled kernel that returns a tuple or a list.

    Numba builds such a result by calling back into Python for each array in it. A Ctrl-C
    (SIGINT) that arrived while the kernel ran is raised in that call, and numba reports the
    failed call as ``SystemError: CPUDispatcher(...) returned a result with an exception set``
    caused, through one or more such errors, by the KeyboardInterrupt: a traceback where the
    user asked to stop. A kernel runs for most of a frame's time, so this is where an
    interrupt usually lands. It is raised again as what it is; the kernel's result is
    dropped, as it would be anyway.
    """
    try:
        return kernel(*args, **kwargs)
    except SystemError as error:
        cause: BaseException | None = error
        while isinstance(cause, SystemError):  # one per level of numba's calls
            cause = cause.__cause__
        if isinstance(cause, KeyboardInterrupt):
            raise KeyboardInterrupt from None
        raise
