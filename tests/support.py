"""Helpers the tests share: one definition each (the fixtures are in conftest.py)."""

from __future__ import annotations

import sqlite3
import sys
import time
from collections.abc import Callable
from pathlib import Path

from island.run import run

GA_SMALL = dict(initial_population=200, population=40, iterations=5)
"""A GA that runs in well under a second on the Synth set."""
PSO_SMALL = dict(initial_population=200, population=30, iterations=5)
"""A PSO that runs in well under a second on the Synth set."""


def drive(opt, objective):
    """Run ``opt`` to the end of its budget with the island loop (ask, evaluate, tell)."""
    run(opt, objective)
    return opt


def hysid(*args: str) -> list[str]:
    """The command line of ``hysid ARGS`` as a separate process."""
    return [sys.executable, "-m", "hysid", *args]


def query(db: Path, sql: str, *params) -> list[tuple]:
    """Read a campaign database, also while a coordinator writes it ([] until its tables exist)."""
    if not db.exists():
        return []
    with sqlite3.connect(db, timeout=10) as con:
        try:
            return con.execute(sql, params).fetchall()
        except sqlite3.OperationalError as exc:
            if "no such table" in str(exc):
                return []
            raise


def rows_of(db: Path, island: str) -> int:
    """History rows of an island."""
    found = query(db, "SELECT count(*) FROM history WHERE island = ?", island)
    return found[0][0] if found else 0


def events(db: Path, island: str | None = None) -> list:
    """Membership events in order: ``(island, event)`` pairs, or one island's events."""
    if island is None:
        return query(db, "SELECT island, event FROM members ORDER BY id")
    return [e for (e,) in query(db, "SELECT event FROM members WHERE island = ? ORDER BY id", island)]


def history_iterations(db: Path) -> dict[str, list[int]]:
    """The stored iterations of every island."""
    out: dict[str, list[int]] = {}
    for island, it in query(db, "SELECT island, iteration FROM history ORDER BY island, run, iteration"):
        out.setdefault(island, []).append(it)
    return out


def wait_for(predicate: Callable[[], bool], timeout: float, what: str, step: float = 0.05) -> float:
    """Seconds until ``predicate()`` held; fails after ``timeout``."""
    start = time.monotonic()
    while not predicate():
        if time.monotonic() - start > timeout:
            raise AssertionError(f"timed out after {timeout} s waiting for {what}")
        time.sleep(step)
    return time.monotonic() - start


def screen_of(argv: list[str], timeout: float, until: Callable[[str], bool] | None = None, columns: int = 160) -> tuple[int | None, str]:
    """Run ``argv`` on a pseudo-terminal (stdout and stderr) of ``columns`` columns; returns its exit
    status (None if it was still running when ``until(text so far)`` held) and everything it wrote."""
    import fcntl
    import os
    import pty
    import select
    import struct
    import subprocess
    import termios

    master, slave = pty.openpty()
    fcntl.ioctl(slave, termios.TIOCSWINSZ, struct.pack("HHHH", 50, columns, 0, 0))
    env = {**os.environ, "TERM": "xterm-256color", "COLUMNS": str(columns)}
    proc = subprocess.Popen(argv, stdin=slave, stdout=slave, stderr=slave, env=env, close_fds=True)
    os.close(slave)
    chunks: list[bytes] = []
    deadline = time.monotonic() + timeout
    try:
        while time.monotonic() < deadline:
            ready, _, _ = select.select([master], [], [], 0.1)
            if ready:
                try:
                    data = os.read(master, 65536)
                except OSError:  # the child closed the terminal
                    break
                if not data:
                    break
                chunks.append(data)
                if until is not None and until(b"".join(chunks).decode(errors="replace")):
                    return None, b"".join(chunks).decode(errors="replace")
            elif proc.poll() is not None and not select.select([master], [], [], 0)[0]:
                break
        else:
            raise AssertionError(f"{argv[3:]} still running after {timeout} s")
        return proc.wait(timeout=30), b"".join(chunks).decode(errors="replace")
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
        os.close(master)
