"""The ``hysid`` command (``python -m hysid`` too): Ctrl-C while hysid loads is one line, never a traceback.

Importing the command line (numpy, scipy, Zenoh) is the slow part of starting
a command; :mod:`hysid` itself is light (its names load on first use), so the
interrupt can be caught around that import.
"""

from __future__ import annotations

import sys


def main() -> int:
    try:
        from hysid.cli import main as run
    except KeyboardInterrupt:
        print("hysid: error: interrupted", file=sys.stderr)
        return 130
    return run()


if __name__ == "__main__":
    sys.exit(main())
