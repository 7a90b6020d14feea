"""``hysid bench interrupt``: Ctrl-C in a campaign of island processes, from the key to the exit.

Each run starts ``hysid campaign`` (two island processes over Zenoh, searching until stopped) in a process
group of its own, as a terminal runs a job, waits until both islands have stored history rows, and sends
SIGINT to the whole group, as Ctrl-C in a terminal does (the coordinator and its island processes all get
it). Measured from the key: ``stopping_s``, until the line ``stopping: waiting for N islands' last rows
(Ctrl-C again to leave now)`` (or ``every island's last rows are in``, where they came first);
``islands_in_s``, until the live progress says no island is alive (their last rows are in); ``reported_s``,
until the report is written and ``hysid: error: interrupted`` said; ``exit_s``, until the process has exited (status 130 expected, target 5 s);
and how the islands are recorded (``stopped`` expected, never ``lost``). Two models: ``thesis`` (fast
iterations) and ``baseline+bouc_wen`` (memetic islands, a force computed sample by sample: slow ones).

The ``leave_now`` run freezes one island (SIGSTOP), so that the coordinator waits for its last rows, sends
SIGINT to the coordinator alone and a second one once it says it stops: ``exit_s`` from the second key, the
database's status (``interrupted`` expected) and SQLite's integrity check.
"""

from __future__ import annotations

import os
import re
import signal
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path
from typing import Any

from hysid.bench.sites import query
from hysid_model.errors import HysidInputError

MODELS = ("thesis", "baseline+bouc_wen")
RUNS = 3
TARGET_S = 5.0
"""From the key to the exit."""
WAIT_S = 180.0
"""Longest wait for a campaign to search, say it stops, or exit (a bench gone wrong says so)."""
CAMPAIGN = ["--islands", "2", "--time-limit", "900", "--no-polish", "synth", "--points", "30"]


class Job:
    """``hysid campaign`` as a terminal's job (a process group of its own), its stderr lines timed as they come."""

    def __init__(self, out: Path, model: str) -> None:
        self.db = out / "campaign.sqlite"
        self.process = subprocess.Popen(
            [sys.executable, "-m", "hysid", "campaign", *CAMPAIGN, "--model", model, "--out", str(out)],
            stdout=subprocess.DEVNULL,
            stderr=subprocess.PIPE,
            text=True,
            start_new_session=True,
            preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL),  # Ctrl-C, also where this process ignores it
        )
        self.lines: list[tuple[float, str]] = []
        self.reader = threading.Thread(target=self._read, daemon=True)
        self.reader.start()

    def _read(self) -> None:
        assert self.process.stderr is not None
        for line in self.process.stderr:
            self.lines.append((time.monotonic(), line.rstrip("\n")))

    def wait_until(self, done: Any, what: str) -> None:
        deadline = time.monotonic() + WAIT_S
        while not done():
            if self.process.poll() is not None:
                raise RuntimeError(f"the campaign ended while waiting for {what}: {self.tail()}")
            if time.monotonic() > deadline:
                raise RuntimeError(f"no {what} within {WAIT_S:g} s")
            time.sleep(0.05)

    def searching(self) -> bool:
        return len(query(self.db, "SELECT DISTINCT island FROM history")) == 2

    def said(self, fragment: str, after: float = 0.0) -> float | None:
        return next((t for t, line in self.lines if fragment in line and t >= after), None)

    def exited(self) -> float:
        self.process.wait(timeout=WAIT_S)
        self.reader.join(timeout=10)
        return time.monotonic()

    def tail(self) -> str:
        return self.lines[-1][1] if self.lines else "no output"

    def end(self) -> None:
        if self.process.poll() is None:
            os.killpg(self.process.pid, signal.SIGKILL)
            self.process.wait()


def events(db: Path) -> dict[str, int]:
    """How the island runs ended: their last membership events, counted."""
    last = dict(query(db, "SELECT island, event FROM members ORDER BY id"))
    return {event: list(last.values()).count(event) for event in sorted(set(last.values()))}


def first_ctrl_c(model: str, workdir: Path) -> dict[str, Any]:
    job = Job(workdir, model)
    try:
        job.wait_until(job.searching, "history of both islands")
        key = time.monotonic()
        os.killpg(job.process.pid, signal.SIGINT)
        end = job.exited()
    finally:
        job.end()
    since = {
        what: None if t is None else t - key
        for what, t in (
            ("stopping_s", job.said("stopping: ")),
            ("islands_in_s", job.said("members 0 (", after=key)),
            ("reported_s", job.said("hysid: error: interrupted")),
        )
    }
    return {
        **since,
        "exit_s": end - key,
        "returncode": job.process.returncode,
        "stopping_line": next((line for _, line in job.lines if "stopping:" in line), None),
        "islands": events(job.db),
    }


def second_ctrl_c(workdir: Path) -> dict[str, Any]:
    job = Job(workdir, MODELS[0])
    try:
        job.wait_until(job.searching, "history of both islands")
        island = int(Path(f"/proc/{job.process.pid}/task/{job.process.pid}/children").read_text().split()[0])
        os.kill(island, signal.SIGSTOP)  # a frozen island: its last rows never come
        job.process.send_signal(signal.SIGINT)
        job.wait_until(lambda: job.said("stopping: waiting for") is not None, "the stopping line")
        key = time.monotonic()
        job.process.send_signal(signal.SIGINT)
        end = job.exited()
    finally:
        job.end()
    status = query(job.db, "SELECT status, stop_reason FROM campaigns")
    return {
        "exit_s": end - key,
        "returncode": job.process.returncode,
        "status": status[0][0] if status else None,
        "stop_reason": status[0][1] if status else None,
        "integrity": query(job.db, "PRAGMA integrity_check")[0][0],
        "islands": events(job.db),
        "frozen_island_gone": not Path(f"/proc/{island}").exists(),
    }


def run(runs: int = RUNS) -> dict[str, Any]:
    """Ctrl-C in a campaign of island processes: from the key to the 'stopping' line and to the exit (target 5 s), a second Ctrl-C."""
    if runs < 1:
        raise HysidInputError("must be at least 1", param="runs", value=runs)
    cases = []
    with tempfile.TemporaryDirectory(prefix="hysid-bench-interrupt-") as tmp:
        for model in MODELS:
            done = [first_ctrl_c(model, Path(tmp) / f"{re.sub(r'[^a-z]', '-', model)}-{k}") for k in range(runs)]
            cases.append({"model": model, "runs": done, "max_exit_s": max(r["exit_s"] for r in done)})
        leave_now = second_ctrl_c(Path(tmp) / "leave-now")
    ok = all(
        r["returncode"] == 130 and r["exit_s"] < TARGET_S and r["stopping_s"] is not None and set(r["islands"]) == {"stopped"}
        for case in cases
        for r in case["runs"]
    )
    ok = ok and leave_now["returncode"] == 130 and leave_now["status"] == "interrupted" and leave_now["integrity"] == "ok"
    return {"target_s": TARGET_S, "cases": cases, "leave_now": leave_now, "ok": ok}


def to_text(result: dict[str, Any]) -> str:
    lines = [f"Ctrl-C in a campaign of 2 island processes, SIGINT to its process group (target: exit 130 within {result['target_s']:g} s)"]
    for case in result["cases"]:
        lines.append(f"  {case['model']}:")
        for r in case["runs"]:
            timed = ", ".join(
                f"{what} {'never' if r[key] is None else format(r[key], '.2f') + ' s'}"
                for what, key in (("'stopping'", "stopping_s"), ("islands in", "islands_in_s"), ("reported", "reported_s"))
            )
            lines.append(f"    {timed}, exit {r['returncode']} after {r['exit_s']:.2f} s, islands {r['islands']}")
    n = result["leave_now"]
    lines.append(
        f"  a second Ctrl-C, one island frozen: exit {n['returncode']} after {n['exit_s']:.2f} s, database {n['status']} "
        f"({n['stop_reason']}), integrity {n['integrity']}, islands {n['islands']}, frozen island gone: {n['frozen_island_gone']}"
    )
    lines.append(f"ok: {result['ok']}")
    return "\n".join(lines)
