"""The staged hand-over at an island's round boundary, whatever the coordinator's lag.

With the staged share (:mod:`island.share`) the coordinator moves a run of the exploring algorithm (the GA)
to the converging one (the PSO) once its history shows the end of its first round
(:func:`island.share.handover_iteration`). An island that searched on while the coordinator lagged behind its
histories (a loaded machine, a coordinator busy with a burst of messages) would run its exploring algorithm
round after round and take the order late, or together with the budget's stop, and end as it began. So an
exploring island waits at that boundary, its history sent, until the coordinator's order comes
(:func:`await_handover`), then carries its search on with the converging algorithm: what a user of a staged
campaign expects, the GA's first round, then the PSO, holds under any lag. The wait ends early at a stop
order (or a coordinator silent for longer than the island waits, :mod:`island.transports`), and after
:data:`HANDOVER_WAIT_S` at most (a coordinator that will not move this run: it searches on as it is).
"""

from __future__ import annotations

import time
from collections.abc import Callable

from island.turns import Turns

HANDOVER_WAIT_S = 30.0
"""The longest an exploring island waits at its round boundary for the coordinator's hand-over."""
HANDOVER_POLL_S = 0.01
"""How often the waiting island looks at what the coordinator assigns it."""


def await_handover(
    algo: str,
    assigned: Callable[[], str | None],
    stop_requested: Callable[[], bool],
    turns: Turns | None = None,
    timeout_s: float = HANDOVER_WAIT_S,
) -> None:
    """While ``assigned()`` (what the coordinator assigns this run) is still ``algo``: wait until it names
    another algorithm, ``stop_requested()`` holds or ``timeout_s`` passed. None
    from ``assigned()`` (nobody assigns this run anything: islands without a coordinator, or a roster that
    does not list the run yet) is not waited on. ``turns``: the island's computing turn is given to the other
    islands of its process while it waits (:class:`island.turns.Turns`)."""
    if assigned() != algo:
        return
    deadline = time.monotonic() + timeout_s
    if turns is not None:
        turns.release()
    try:
        while assigned() == algo and not stop_requested() and time.monotonic() < deadline:
            time.sleep(HANDOVER_POLL_S)
    finally:
        if turns is not None:
            turns.acquire()
