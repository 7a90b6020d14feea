"""The campaign database's tables, what a database of an earlier hysid gets when it is opened, and whether a file
has a table or a column (:func:`has_table`, :func:`has_column`: one opened read-only is not upgraded).

Tables: ``campaigns`` (configuration message with the loop set, status, stop reason, final result),
``members`` (join / leave / lost / back events), ``history`` (the islands' convergence rows, keyed by
island, run and iteration so that a row sent twice is stored once), ``thinned`` (the stretches of a run's
history whose rows the coordinator did not keep, over capacity, and how many: :mod:`coordinator.thinning`),
``islands`` (each island run's algorithm, evaluations and migration counters), ``migrations`` (every
migrant message handled), ``superseded`` (per island, migrant messages a newer one replaced before they
were handled), ``unfollowed`` (when, with how many islands alive, the coordinator stopped following
migrant messages: :data:`coordinator.intake.FOLLOWS_MIGRANTS_UP_TO`), ``rejected`` (every message that
failed validation, with the reason), ``best`` (the global best, as re-evaluated by the coordinator),
``runs`` (every run admitted, its public key and the member it joined for), ``moves`` (the share's moves) and ``commits`` (the
coordinator's heartbeat: when it last committed, from which process on which host, and the campaign's
elapsed time).

No key is kept here (:mod:`coordinator.keys`): a database of an earlier hysid whose ``secrets`` table holds
them has them moved out to key files when it is opened for writing (:func:`move_keys_out`).
"""

from __future__ import annotations

import contextlib
import functools
import sqlite3

from coordinator.keys import CampaignKeys, key_path

SCHEMA = """
CREATE TABLE IF NOT EXISTS campaigns (
    name TEXT PRIMARY KEY, dataset TEXT NOT NULL, config BLOB NOT NULL, created REAL NOT NULL,
    status TEXT NOT NULL, stop_reason TEXT, ended REAL, result TEXT);
CREATE TABLE IF NOT EXISTS members (
    id INTEGER PRIMARY KEY, campaign TEXT NOT NULL, island TEXT NOT NULL, event TEXT NOT NULL, t REAL NOT NULL);
CREATE TABLE IF NOT EXISTS history (
    campaign TEXT NOT NULL, island TEXT NOT NULL, run TEXT NOT NULL, iteration INTEGER NOT NULL,
    best_fitness REAL NOT NULL, evaluations INTEGER NOT NULL, wall_s REAL NOT NULL, t REAL NOT NULL,
    PRIMARY KEY (campaign, island, run, iteration));
CREATE TABLE IF NOT EXISTS islands (
    campaign TEXT NOT NULL, island TEXT NOT NULL, run TEXT NOT NULL, algo TEXT NOT NULL, seed INTEGER NOT NULL,
    iterations INTEGER NOT NULL, evaluations INTEGER NOT NULL, best_fitness REAL NOT NULL, best_x BLOB NOT NULL,
    sent INTEGER NOT NULL, received INTEGER NOT NULL, taken INTEGER NOT NULL, rejected INTEGER NOT NULL,
    final INTEGER NOT NULL, unlisted INTEGER NOT NULL DEFAULT 0, PRIMARY KEY (campaign, island, run));
CREATE TABLE IF NOT EXISTS migrations (
    id INTEGER PRIMARY KEY, campaign TEXT NOT NULL, island TEXT NOT NULL, run TEXT NOT NULL,
    iteration INTEGER NOT NULL, n INTEGER NOT NULL, best_claimed REAL NOT NULL, sent_at REAL NOT NULL, t REAL NOT NULL,
    seq INTEGER);
CREATE TABLE IF NOT EXISTS rejected (
    id INTEGER PRIMARY KEY, campaign TEXT NOT NULL, key TEXT NOT NULL, reason TEXT NOT NULL,
    detail TEXT NOT NULL, size INTEGER NOT NULL, t REAL NOT NULL, n INTEGER NOT NULL DEFAULT 1);
CREATE TABLE IF NOT EXISTS best (
    campaign TEXT PRIMARY KEY, island TEXT NOT NULL, x BLOB NOT NULL, fitness REAL NOT NULL,
    evaluations INTEGER NOT NULL, t REAL NOT NULL);
CREATE TABLE IF NOT EXISTS runs (
    campaign TEXT NOT NULL, island TEXT NOT NULL, run TEXT NOT NULL, key BLOB NOT NULL, algo TEXT NOT NULL,
    seed INTEGER NOT NULL, joined REAL NOT NULL, member TEXT NOT NULL DEFAULT '', PRIMARY KEY (campaign, island, run));
CREATE TABLE IF NOT EXISTS moves (
    id INTEGER PRIMARY KEY, campaign TEXT NOT NULL, island TEXT NOT NULL, run TEXT NOT NULL, src TEXT NOT NULL,
    dst TEXT NOT NULL, evaluations INTEGER NOT NULL, credit TEXT NOT NULL, t REAL NOT NULL);
CREATE TABLE IF NOT EXISTS commits (
    campaign TEXT PRIMARY KEY, t REAL NOT NULL, elapsed_s REAL NOT NULL DEFAULT 0, pid INTEGER, host TEXT);
CREATE TABLE IF NOT EXISTS thinned (
    campaign TEXT NOT NULL, island TEXT NOT NULL, run TEXT NOT NULL, first INTEGER NOT NULL, last INTEGER NOT NULL,
    rows INTEGER NOT NULL, t REAL NOT NULL);
CREATE TABLE IF NOT EXISTS superseded (
    campaign TEXT NOT NULL, island TEXT NOT NULL, messages INTEGER NOT NULL, PRIMARY KEY (campaign, island));
CREATE TABLE IF NOT EXISTS unfollowed (campaign TEXT PRIMARY KEY, islands INTEGER NOT NULL, up_to INTEGER NOT NULL, t REAL NOT NULL);
"""
UPGRADES = (
    ("migrations", "seq"),
    ("rejected", "n"),
    ("commits", "elapsed_s"),
    ("commits", "pid"),
    ("commits", "host"),
    ("islands", "unlisted"),
    ("runs", "member"),
)
"""Columns added since the first schema, as (table, column): a database written by an earlier hysid gets them on open,
declared as :data:`SCHEMA` declares them (:func:`upgrade`)."""
INDEXES = """
CREATE UNIQUE INDEX IF NOT EXISTS migration_once ON migrations (campaign, island, run, seq);
CREATE INDEX IF NOT EXISTS thinned_runs ON thinned (campaign, island, run, first);
"""
"""A migrant message (sender run and number) is stored once, also when it is replayed after a restart; a run's
thinned stretches are found in order."""


def has_table(db: sqlite3.Connection, table: str) -> bool:
    """Whether the database has ``table`` (a file of an earlier hysid opened read-only may lack it)."""
    return db.execute("SELECT 1 FROM sqlite_master WHERE type = 'table' AND name = ?", (table,)).fetchone() is not None


def has_column(db: sqlite3.Connection, table: str, column: str) -> bool:
    """Whether ``table`` has ``column`` (a file of an earlier hysid opened read-only may lack it)."""
    return column in {row[1] for row in db.execute(f"PRAGMA table_info({table})")}


@functools.cache
def upgrade(table: str, column: str) -> str:
    """The ``ALTER TABLE`` that adds ``column`` to ``table`` of an earlier hysid's database with the declaration
    :data:`SCHEMA` gives it (type, ``NOT NULL``, ``DEFAULT``), as SQLite reads it from a fresh copy of the schema."""
    with contextlib.closing(sqlite3.connect(":memory:")) as fresh:
        fresh.executescript(SCHEMA)
        _, name, kind, not_null, default, _ = next(row for row in fresh.execute(f"PRAGMA table_info({table})") if row[1] == column)
    return f"ALTER TABLE {table} ADD COLUMN {name} {kind}" + (" NOT NULL" if not_null else "") + ("" if default is None else f" DEFAULT {default}")


def prepare(db: sqlite3.Connection) -> None:
    """Create the tables, and add to a database of an earlier hysid the columns it lacks."""
    db.executescript(SCHEMA)
    for table, column in UPGRADES:
        if not has_column(db, table, column):
            db.execute(upgrade(table, column))
    db.executescript(INDEXES)


def move_keys_out(db: sqlite3.Connection, path: str) -> int:
    """Move the keys a database of an earlier hysid kept in its ``secrets`` table (at ``path``) to owner-only key
    files beside it (:func:`coordinator.keys.key_path`), then drop the table and rebuild the file (``VACUUM``,
    the journal emptied), so that no byte of them stays in it; returns how many campaigns' keys moved."""
    if not has_table(db, "secrets"):
        return 0
    moved = 0
    if has_column(db, "secrets", "admission") and has_column(db, "secrets", "signing"):
        for campaign, admission, signing in db.execute("SELECT campaign, admission, signing FROM secrets").fetchall():
            if admission and signing:  # a campaign of protocol 3 held only a key no island speaks any more
                CampaignKeys(campaign, bytes(admission), bytes(signing)).with_members_key().keep(key_path(path, campaign))
                moved += 1
    db.execute("PRAGMA secure_delete = ON")
    db.execute("DROP TABLE secrets")
    db.commit()
    db.execute("VACUUM")
    db.execute("PRAGMA wal_checkpoint(TRUNCATE)")
    return moved
