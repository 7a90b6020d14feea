"""The environment fails, not the user: a read-only or full output directory, a database that cannot
be written, numbers too large to run. One line, before the work where it can be known; otherwise a
clean stop that keeps what was stored and marks the campaign interrupted.

Read-only and full file systems are real tmpfs mounts (root only; skipped otherwise).
"""

from __future__ import annotations

import os
import sqlite3
import subprocess
from collections.abc import Callable, Iterator
from pathlib import Path

import pytest

from coordinator.launch import free_port
from coordinator.store import Store
from hysid.cli import main
from support import PSO_ISLANDS, coordinator_args, hysid, stderr_read


@pytest.fixture
def mount(tmp_path: Path) -> Iterator[Callable[..., Path]]:
    """``mount(name, size=..., readonly=..., files=...)``: a tmpfs under tmp_path, unmounted afterwards."""
    mounted: list[Path] = []

    def make(name: str, *, size: str = "1m", readonly: bool = False, files: dict[str, bytes] | None = None, fill: bool = False) -> Path:
        if os.geteuid() != 0:
            pytest.skip("mounting a read-only or small file system needs root")
        target = tmp_path / name
        target.mkdir()
        done = subprocess.run(["mount", "-t", "tmpfs", "-o", f"size={size}", "tmpfs", str(target)], capture_output=True, text=True)
        if done.returncode:
            pytest.skip(f"cannot mount a tmpfs here: {done.stderr.strip()}")
        mounted.append(target)
        for rel, data in (files or {}).items():
            (target / rel).write_bytes(data)
        if fill:  # take every free block
            try:
                with open(target / "filler", "wb") as f:
                    while True:
                        f.write(bytes(4096))
                        f.flush()
            except OSError:
                pass
        if readonly:
            subprocess.run(["mount", "-o", "remount,ro", str(target)], check=True)
        return target

    yield make
    for target in reversed(mounted):
        subprocess.run(["umount", "-l", str(target)], check=False)


def one_line_error(args: list[str], capsys) -> str:
    assert main(args) == 2
    err = capsys.readouterr().err
    assert err.startswith("hysid: error: ") and "Traceback" not in err and err.count("\n") == 1, err
    return err


@pytest.mark.parametrize("kind", ["read-only", "full"])
@pytest.mark.parametrize("command", [["fit", "synth"], ["campaign", "--single-node"], ["coordinator"], ["reproduce", "thesis"]])
def test_an_output_directory_that_cannot_be_written_is_refused_before_any_work(kind, command, mount, capsys):
    place = mount("out", readonly=kind == "read-only", fill=kind == "full", size="64k")
    err = one_line_error([*command, "--out", str(place / "report")], capsys)
    assert f"--out {place / 'report'}: cannot write there" in err and "nothing was run" in err
    assert not (place / "report").exists()


def test_a_database_that_cannot_be_written_is_refused_before_any_work(mount, tmp_path, capsys):
    place = mount("db", readonly=True)
    err = one_line_error(["coordinator", "--db", str(place / "new.sqlite"), "--out", str(tmp_path / "o1")], capsys)
    assert f"--db {place}: cannot write there" in err
    stored = tmp_path / "c.sqlite"
    Store(stored).create_campaign("default", "synth", b"cfg")
    read_only = mount("ro", files={"c.sqlite": stored.read_bytes()}, readonly=True)
    err = one_line_error(["coordinator", "--resume", "--db", str(read_only / "c.sqlite"), "--out", str(tmp_path / "o2")], capsys)
    assert "c.sqlite: not a usable campaign database" in err
    assert not (tmp_path / "o1").exists() and not (tmp_path / "o2").exists()


@pytest.mark.parametrize(
    "args, words",
    [
        (["campaign", "--islands", str(10**9)], "--islands 1000000000: a campaign admits at most 4096 islands"),
        (["campaign", "--population", str(10**12), "--initial", str(10**12)], "population must be at most 1,000,000"),
        (["campaign", "--iterations", str(2**60)], "iterations must be at most"),
        (["campaign", "--seed", str(2**70)], "--seed 1180591620717411303424: must be an integer from 0 to 2**62"),
        (["campaign", "--interval", str(10**30)], "--interval"),
        (["coordinator", "--min-islands", str(10**6)], "--min-islands 1000000: must be an integer from 1 to 4096"),
        (["campaign", "--time-limit", "nan"], "--time-limit nan: must be a positive number of seconds"),
        (["campaign", "--target", "inf"], "--target inf: must be a finite fitness"),
        (["island", "--wait", "nan"], "--wait nan: must be from 0 to 86400 seconds"),
        (["island", "--seed", str(2**64)], "--seed 18446744073709551616: seeds must be from 0 to 2**62"),
    ],
)
def test_numbers_too_large_to_run_are_one_line_errors_before_any_work(args, words, tmp_path, capsys):
    assert words in one_line_error(args + ([] if args[0] == "island" else ["--out", str(tmp_path / "o")]), capsys)
    assert not (tmp_path / "o").exists()


@pytest.mark.slow
def test_a_database_disk_that_fills_up_mid_run_stops_the_campaign_cleanly(mount, tmp_path):
    place = mount("db", size="3m")
    db, endpoint = place / "c.sqlite", f"tcp/127.0.0.1:{free_port()}"
    coordinator = subprocess.Popen(
        hysid(
            *coordinator_args(endpoint, "full", db, tmp_path / "out"),
            "--quiet",
            *PSO_ISLANDS,
            "--iterations",
            "10000000",
            "--time-limit",
            "120",
        ),
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    islands = [
        stderr_read(
            hysid("island", "--connect", endpoint, "--campaign", "full", "--id", name, "--quiet", "--wait", "10", "--secret-file", f"{db}-full.secret"),
        )
        for name in ("a", "b")
    ]
    try:
        _, err = coordinator.communicate(timeout=150)
        island_errs = [p.communicate(timeout=60)[1] for p in islands]
    finally:
        for p in (coordinator, *islands):
            p.kill()
    errors = [line for line in err.splitlines() if line.startswith("hysid: error:")]
    assert coordinator.returncode == 2 and len(errors) == 1 and err.endswith(errors[0] + "\n") and "Traceback" not in err, err
    assert "hysid: error: campaign 'full' stopped: cannot write the campaign database" in errors[0] and "database or disk is full" in errors[0]
    assert "what was committed before is kept" in errors[0]
    assert all(p.returncode == 0 for p in islands), island_errs  # told to stop; they did
    with sqlite3.connect(f"file:{db}?mode=ro", uri=True) as reader:
        status, reason = reader.execute("SELECT status, stop_reason FROM campaigns").fetchone()
        rows = reader.execute("SELECT count(*) FROM history").fetchone()[0]
    assert rows > 100  # what was committed before the disk filled is kept
    assert status == "interrupted" and "it is marked interrupted" in err and "database or disk is full" in reason
    print(f"disk full after {rows} history rows; campaign status {status!r}: {reason}")
