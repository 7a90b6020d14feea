"""Ctrl-C while a coordinator runs its campaign: the first asks it to stop, a second leaves at once.

Python turns SIGINT into a ``KeyboardInterrupt`` wherever the main thread
happens to be, possibly halfway through handling a message or writing a batch
of rows. :class:`CtrlC` takes SIGINT over for the run loop
(:func:`coordinator.loop.serve`): the first only sets :attr:`CtrlC.asked`, which
the loop reads between two messages (it then stops the campaign and waits for
the islands' last rows); the second raises ``KeyboardInterrupt`` at once (the
loop leaves without waiting, the database rolled back to its last commit and
marked interrupted). Outside the main thread, or where SIGINT is not Python's
default (ignored, or a handler of the caller's), nothing is taken over.
"""

from __future__ import annotations

import signal
import threading
from collections.abc import Callable
from types import FrameType, TracebackType
from typing import Any

INTERRUPTED = "interrupted"
"""The stop reason of a campaign the user stopped (Ctrl-C), or that a database fault ended."""


class CtrlC:
    """A context manager: inside it the first SIGINT sets :attr:`asked` and calls ``on_first`` (quick, in the
    main thread between two bytecodes: say, what an island's goodbye is to record from now on), a second
    raises ``KeyboardInterrupt``."""

    def __init__(self, on_first: Callable[[], None] | None = None) -> None:
        self.asked = False
        """The user pressed Ctrl-C once (the campaign is to stop)."""
        self.on_first = on_first
        self._previous: Any = None

    def __enter__(self) -> CtrlC:
        if threading.current_thread() is threading.main_thread() and signal.getsignal(signal.SIGINT) is signal.default_int_handler:
            self._previous = signal.signal(signal.SIGINT, self._pressed)
        return self

    def _pressed(self, signum: int, frame: FrameType | None) -> None:
        if self.asked:
            raise KeyboardInterrupt
        self.asked = True
        if self.on_first is not None:
            self.on_first()

    def __exit__(self, kind: type[BaseException] | None, exc: BaseException | None, tb: TracebackType | None) -> None:
        if self._previous is not None:
            signal.signal(signal.SIGINT, self._previous)
            self._previous = None
