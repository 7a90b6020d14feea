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
