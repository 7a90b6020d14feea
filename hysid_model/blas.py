"""BLAS on one thread for the small dense solves of the polish and of loop extraction.

Their matrices are a few columns wide; on a busy 2-core machine a second OpenBLAS
thread made each SVD 60 x slower (1 ms -> 68 ms for 1800 x 7). ``threadpoolctl``'s
``threadpool_limits`` finds the BLAS libraries anew at every use by reading the
process' memory map (about 2 ms, more than a whole refinement of a memory model
costs in an island); a :class:`threadpoolctl.ThreadpoolController` made once does
it once (16 us per use).
"""

from __future__ import annotations

import functools
from collections.abc import Callable
from contextlib import AbstractContextManager
from typing import Any, TypeVar

from threadpoolctl import ThreadpoolController

F = TypeVar("F", bound=Callable[..., Any])
_controller: ThreadpoolController | None = None


def one_blas_thread() -> AbstractContextManager[Any]:
    """A context in which every BLAS library the process has loaded runs on one thread.

    The libraries are found on first use, after ``scipy.linalg`` is imported (scipy ships its own OpenBLAS,
    which numpy's import does not load)."""
    global _controller
    if _controller is None:
        import scipy.linalg  # noqa: F401  (loads scipy's BLAS, so that the controller sees it)

        _controller = ThreadpoolController()
    return _controller.limit(limits=1, user_api="blas")


def on_one_blas_thread(function: F) -> F:
    """``function`` run inside :func:`one_blas_thread`."""

    @functools.wraps(function)
    def wrapper(*args: Any, **kwargs: Any) -> Any:
        with one_blas_thread():
            return function(*args, **kwargs)

    return wrapper  # type: ignore[return-value]
