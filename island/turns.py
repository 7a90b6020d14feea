"""Turns at computing: at most ``n`` islands of a process compute at once, the others wait in the order they asked.

The islands a process hosts (:func:`island.host.run_islands`) take turns iteration by iteration
(:meth:`island.node.IslandNode.run` calls :meth:`Turns.next` after each one): they progress alike, and the
threads that speak for all of them (control, heartbeats, migrants) never wait behind dozens of computing
ones for Python's interpreter lock.
"""

from __future__ import annotations

import threading
from collections import deque

from hysid_model.errors import HysidInputError


class Turns:
    """At most ``n`` islands of a process compute at once; the others wait, in the order they asked (see
    the module docstring). Thread-safe."""

    def __init__(self, n: int) -> None:
        if n < 1:
            raise HysidInputError("must be at least 1", param="turns", value=n)
        self._free = n
        self._waiting: deque[threading.Event] = deque()
        self._lock = threading.Lock()

    def acquire(self) -> None:
        with self._lock:
            if self._free and not self._waiting:
                self._free -= 1
                return
            turn = threading.Event()
            self._waiting.append(turn)
        turn.wait()

    def release(self) -> None:
        """Hand the turn to the island that has waited longest (or free it)."""
        with self._lock:
            if self._waiting:
                self._waiting.popleft().set()
            else:
                self._free += 1

    def next(self) -> None:
        """Let the islands waiting go first, then compute again."""
        self.release()
        self.acquire()
