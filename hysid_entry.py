"""The ``hysid`` command's entry point (``python -m hysid_entry`` too): Ctrl-C while hysid loads is one line.

It lives outside the ``hysid`` package because importing that package (numpy,
scipy, Zenoh) is the slow part of starting a command; an interrupt then ends
with ``hysid: error: interrupted`` and exit status 130, never a traceback.
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
