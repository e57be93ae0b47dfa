"""The planners' dense problems are small (tens of variables): BLAS threads only add contention.

:func:`single_blas_thread` runs a planner function with one BLAS thread (threadpoolctl), whoever calls it: on a
loaded 2-core machine a gait cycle planned with OpenBLAS's default threads took 4-15 x as long.
"""

from __future__ import annotations

import functools
from collections.abc import Callable
from typing import ParamSpec, TypeVar

from threadpoolctl import ThreadpoolController

P = ParamSpec("P")
R = TypeVar("R")


@functools.cache
def _controller() -> ThreadpoolController:
    """One per process: building it scans the loaded libraries."""
    return ThreadpoolController()


def single_blas_thread(func: Callable[P, R]) -> Callable[P, R]:
    """``func`` run with BLAS limited to one thread (the caller's setting is restored afterwards)."""

    @functools.wraps(func)
    def wrapper(*args: P.args, **kwargs: P.kwargs) -> R:
        with _controller().limit(limits=1, user_api="blas"):
            return func(*args, **kwargs)

    return wrapper


__all__ = ["single_blas_thread"]
