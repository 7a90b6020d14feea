"""The ``hysid`` command (``python -m hysid`` too): Ctrl-C while hysid loads is one line, never a traceback.

Importing the command line (numpy, scipy, Zenoh) is the slow part of starting
a command; :mod:`hysid` itself is light (its names load on first use), so the
interrupt can be caught around that import.
"""

from __future__ import annotations

import gc
import signal
import sys
from collections.abc import Iterator
from contextlib import contextmanager

INTERRUPTED = 130
"""Exit status after Ctrl-C (128 + SIGINT), as shells report it (:data:`hysid.cli.options.INTERRUPTED`)."""


@contextmanager
def interrupt_after_loading() -> Iterator[None]:
    """Ctrl-C while the command line loads is raised once it has loaded: raised inside an import it may land in one of
    importlib's own callbacks, where Python prints it as ignored (a traceback) and the command runs on as if no key had
    been pressed. A SIGINT that whoever started hysid ignores or handles stays so."""
    if signal.getsignal(signal.SIGINT) is not signal.default_int_handler:
        yield
        return
    pressed: list[int] = []
    signal.signal(signal.SIGINT, lambda signum, frame: pressed.append(signum))
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, signal.default_int_handler)
    if pressed:
        raise KeyboardInterrupt


def main() -> int:
    try:
        with interrupt_after_loading():
            from hysid.cli import load_commands
            from hysid.cli import main as run

            load_commands(sys.argv[1:])  # the command's own modules, loaded here too

        status = run()
    except KeyboardInterrupt:  # while the command line loads, or builds itself before it handles Ctrl-C on its own
        print("hysid: error: interrupted", file=sys.stderr)
        status = INTERRUPTED
    if status == INTERRUPTED:
        # CPython (3.11-3.13) kills a ``python -m`` process with SIGINT at exit, whatever its status, if a Ctrl-C
        # ended a string exec on the way (dataclasses and namedtuples build their methods so while modules load),
        # even one caught since; a string exec of its own clears that mark, and the status stays 130.
        exec("")
    # The interpreter's last collection walks every object left (numpy, numba, Zenoh, a campaign's loops): 0.7-1.0 s
    # of a campaign's exit after Ctrl-C under load, 0.08 s with them frozen. What must be written is by now (files,
    # databases and sessions are closed where they were opened); objects not in cycles are still freed as modules go.
    gc.freeze()
    return status


if __name__ == "__main__":
    sys.exit(main())
