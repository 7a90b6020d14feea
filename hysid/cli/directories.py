"""Where the command line writes: the ``--out`` policy (a new or empty directory, checked before any work) and the
campaign database an output directory holds."""

from __future__ import annotations

import datetime as dt
import os
from pathlib import Path

from coordinator.store import Store
from hysid.cli.options import FLAGS
from hysid_model.errors import HysidInputError

DB_NAME = "campaign.sqlite"
"""The database a campaign's output directory holds (``--db`` not given)."""


def campaign_database(path: Path) -> Path:
    """The database ``path`` names: itself, or for a campaign's output directory the ``campaign.sqlite`` in it."""
    if not path.is_dir():
        return path
    if (path / DB_NAME).is_file():
        return path / DB_NAME
    raise HysidInputError(f"{path}: a directory without {DB_NAME}; give the campaign database (--db of the campaign, or OUT/{DB_NAME})")


def report_dir(out: Path | None, kind: str, param: str = "out") -> Path:
    """Where a command writes: ``out`` if new or empty, else (not given) a new ``hysid-out/<kind>-<time>``.

    Every command that writes a directory (``fit``, ``diagnose``, ``synth``,
    ``campaign``, ``coordinator``, ``reproduce``, ``report``) checks it here
    before any work, so that a run never ends in an error after its work is
    done, and never overwrites an earlier report; a directory that cannot be
    written (read-only or full file system) fails here too. ``param`` names
    the option or argument in errors.
    """
    if out is None:
        stamp = dt.datetime.now().strftime("%Y%m%d-%H%M%S")
        base = Path("hysid-out") / f"{kind}-{stamp}"
        out, n = base, 1
        while out.exists():
            n += 1
            out = base.with_name(f"{base.name}-{n}")
        return check_writable(out, param)
    if out.exists() and not out.is_dir():
        raise HysidInputError("exists and is not a directory", param=param, value=out)
    if out.exists() and any(out.iterdir()):
        if (out / DB_NAME).is_file() and not (out / "report.md").exists():
            running = running_campaign(out / DB_NAME)
            if running is not None:
                raise HysidInputError(
                    f"is the output directory of campaign {running!r}, which is still running (its coordinator writes "
                    f"{out / DB_NAME}): two runs cannot share one {FLAGS.get(param, param)}; choose a new directory "
                    "(nothing was written)",
                    param=param,
                    value=out,
                )
            raise HysidInputError(
                f"holds the database of a campaign that did not finish ({out / DB_NAME}, no report.md): carry it on with "
                f"'hysid coordinator --resume --db {out / DB_NAME} --out NEW_DIR', or choose a new directory (nothing was written)",
                param=param,
                value=out,
            )
        raise HysidInputError("already exists and is not empty; choose a new directory (nothing was written)", param=param, value=out)
    return check_writable(out, param)


def running_campaign(db: Path) -> str | None:
    """The name of a campaign in ``db`` that did not stop and whose coordinator still commits (it did, within
    :data:`coordinator.queries.COORDINATOR_LEASE_S`), else None (also for a file that is no campaign database)."""
    try:
        store = Store.read_only(db)
    except HysidInputError:
        return None
    try:
        return next(
            (
                c["name"]
                for c in store.campaign_list()
                if c["status"] != "stopped" and store.last_commit(c["name"]) is not None and store.gone_since(c["name"]) is None
            ),
            None,
        )
    finally:
        store.close()


PROBE_BYTES = 64 << 10
"""What :func:`check_writable` writes: a disk with less room left is as good as full."""


def check_writable(directory: Path, param: str) -> Path:
    """``directory`` if it can be created and written (a probe file is written and removed, and
    directories made for it are removed again), else a one-line :class:`HysidInputError`."""
    made = [p for p in [directory, *directory.parents] if not p.exists()]
    probe = directory / f".hysid-probe-{os.getpid()}"
    try:
        directory.mkdir(parents=True, exist_ok=True)
        with open(probe, "wb") as f:
            f.write(bytes(PROBE_BYTES))
            f.flush()
            os.fsync(f.fileno())
    except OSError as exc:
        raise HysidInputError(f"cannot write there ({exc.strerror or exc}); nothing was run", param=param, value=directory) from None
    finally:
        try:
            probe.unlink(missing_ok=True)
            for p in made:
                p.rmdir()
        except OSError:
            pass
    return directory
