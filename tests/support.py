"""Helpers the tests share: one definition each (the fixtures are in conftest.py)."""

from __future__ import annotations

import importlib
import json
import subprocess
import sys
import textwrap
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path
from types import ModuleType
from typing import Any

import numpy as np

from hysid.bench.sites import query
from hysid_model.errors import HysidInputError
from hysid_model.loops import LoopSet
from hysid_model.synth import RawRecord
from island.polish import polish
from island.run import run

ROOT = Path(__file__).resolve().parents[1]
"""The clone's root, wherever it is."""
DAMPER = ROOT / "data" / "arts-friction-damper"
"""The real friction damper's ten records (CC BY-SA 4.0, see its README), kept with the clone."""

GA_SMALL = dict(initial_population=200, population=40, iterations=5)
"""A GA that runs in well under a second on the Synth set."""
PSO_SMALL = dict(initial_population=200, population=30, iterations=5)
"""A PSO that runs in well under a second on the Synth set."""
PSO_ISLANDS = ("--algos", "pso", "--population", "20", "--initial", "40")
"""Command-line options of small PSO islands (20 particles, 40 initial candidates): the campaign tests'."""


def sizes(population: int, initial: int, iterations: int) -> list[str]:
    """Command-line options of islands of ``population`` members drawn from ``initial`` candidates, ``iterations`` long."""
    return ["--population", str(population), "--initial", str(initial), "--iterations", str(iterations)]


def time_boxed(islands: int, seconds: float) -> list[str]:
    """Command-line options of a campaign of ``islands`` small islands (30 of 60, migrating every 5 iterations, no
    polish) that run until the coordinator's time limit of ``seconds``, so that all are members at once."""
    return ["--min-islands", str(islands), "--time-limit", str(seconds), *sizes(30, 60, 1_000_000), "--interval", "5", "--no-polish"]


def coordinator_args(endpoint: str, campaign: str, db: Path, out: Path) -> list[str]:
    """The arguments of ``hysid coordinator`` listening on ``endpoint`` for ``campaign``, its store ``db``, its report in ``out``."""
    return ["coordinator", "--listen", endpoint, "--campaign", campaign, "--db", str(db), "--out", str(out)]


def cell_average(u, theta: np.ndarray, before: np.ndarray, after: np.ndarray, jumps: np.ndarray) -> np.ndarray:
    """A piecewise-constant u (vectorized over phases) averaged over each sample's cell [theta - before,
    theta + after] ``(L, N)`` with its hat function (peak 1 at theta; for a sample at a reversal, a cell side
    of 0, in the middle of the other side), exactly: on every piece between the cell's ends, its peak and the
    jumps of u (``jumps`` ``(L, J)`` phases) the hat is linear, so its integral is the piece's length times its
    value at the midpoint. A cell of zero width is the point value."""
    out = u(theta)
    for l, n in np.ndindex(theta.shape):
        t, b, a = theta[l, n], before[l, n], after[l, n]
        peak = t - 0.5 * b if a == 0 else (t + 0.5 * a if b == 0 else t)
        inside = [t + np.mod(j - t + np.pi, 2 * np.pi) - np.pi for j in jumps[l]]
        edges = np.unique([t - b, peak, t + a] + [j for j in inside if t - b < j < t + a])
        mid, length = 0.5 * (edges[1:] + edges[:-1]), np.diff(edges)
        hat = np.where(mid < peak, (mid - (t - b)) / max(peak - (t - b), 1e-300), ((t + a) - mid) / max(t + a - peak, 1e-300)) * length
        if hat.sum() > 0:
            values = u(np.broadcast_to(mid, (theta.shape[0], mid.size)))[l]
            out[l, n] = np.dot(hat, values) / hat.sum()
    return out


@contextmanager
def importable(where: Path, name: str, source: str) -> Iterator[ModuleType]:
    """A user's module ``name`` written from ``source`` into ``where``, imported, and importable (``where`` on
    ``sys.path``) until the block ends."""
    (where / f"{name}.py").write_text(textwrap.dedent(source))
    sys.path.insert(0, str(where))
    try:
        yield importlib.import_module(name)
    finally:
        sys.path.remove(str(where))


def ask_sizes(opt, objective) -> list[int]:
    """Run ``opt`` to the end of its budget, ask by ask; the size of every batch it asked."""
    sizes = []
    while not opt.done:
        x = opt.ask()
        sizes.append(x.shape[0])
        opt.tell(x, objective(x))
    return sizes


def polished_to_truth(opt, objective, truth: np.ndarray) -> None:
    """After a thesis-budget search ``opt``: its best is 1000 x below its initial best, w0 within 0.2 %, and the
    polish from it reaches ``truth``."""
    x, f = opt.best()
    assert f[0] < 1e-3 * opt.history[0]
    assert abs(x[0, 2] / truth[2] - 1) < 2e-3
    result = polish(objective, x[0])
    assert result.success
    assert np.all(np.abs(result.theta / truth - 1) < 1e-6)


def drive(opt, objective):
    """Run ``opt`` to the end of its budget with the island loop (ask, evaluate, tell)."""
    run(opt, objective)
    return opt


def hysid(*args: str) -> list[str]:
    """The command line of ``hysid ARGS`` as a separate process."""
    return [sys.executable, "-m", "hysid", *args]


def committed_bench(name: str, definitions: str) -> dict:
    """The newest committed ``hysid bench NAME`` result (bench/results/NAME-*.json), which must have run today's
    ``definitions`` (the sha256 of the module defining its cases, seeds and criterion): else it is to be run again."""
    result = json.loads(sorted((ROOT / "bench" / "results").glob(f"{name}-*.json"))[-1].read_text())
    assert result["definitions"] == definitions, f"the definitions of hysid bench {name} changed since it ran: bash bench/run.sh {name}"
    return result


def stderr_read(command: list[str], **popen: Any) -> subprocess.Popen:
    """``command`` as a background process whose stderr (text) the test reads and whose stdout it drops."""
    return subprocess.Popen(command, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True, **popen)


def interruptible() -> None:
    """``Popen(preexec_fn=interruptible)``: SIGINT takes its default action in the child, which Python
    turns into Ctrl-C (KeyboardInterrupt), also when the test runner itself was started with SIGINT
    ignored (a background job of a non-interactive shell, as CI runners and nohup loops are): a
    test's SIGINT then reaches the process as a user's Ctrl-C would."""
    import signal

    signal.signal(signal.SIGINT, signal.SIG_DFL)


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


def ready(endpoint: str, campaign: str, timeout: float = 90.0, process: subprocess.Popen | None = None) -> None:
    """Wait until the coordinator of ``campaign`` answers its ``config`` query on ``endpoint`` (a
    coordinator process just started may not even listen yet): the readiness wait of every test
    that starts one, instead of a sleep. (It writes its secret before it answers.) With ``process``
    (the coordinator's), also done once it has ended: a short campaign can run to its end before
    the first look, and the caller reads how it ended. The session retries its connection every
    0.05-0.2 s, not Zenoh's 1-4 s, so that a coordinator listening only briefly is still seen."""
    from island.joining import replies
    from island.session import open_session, session_config

    deadline = time.monotonic() + timeout
    config = session_config("client", connect=[endpoint], connect_timeout_s=1.0)
    config.insert_json5("connect/retry", json.dumps({"period_init_ms": 50, "period_max_ms": 200, "period_increase_factor": 1.5}))

    def waited(what: str) -> bool:
        if process is not None and process.poll() is not None:
            return True
        if time.monotonic() > deadline:
            raise AssertionError(f"{what} of {campaign!r} on {endpoint} within {timeout} s")
        return False

    while True:
        try:
            session = open_session(config, endpoint)
            break
        except HysidInputError:
            if waited("no coordinator listening"):
                return
    try:
        while not replies(session, f"hysid/{campaign}/config", 2.0):
            if waited("no coordinator answered"):
                return
            time.sleep(0.1)
    finally:
        session.close()


def secret_of(db: Path, campaign: str):
    """The campaign secret a coordinator process keeps beside its database ``db``."""
    from island.secret import CampaignSecret, secret_path

    return CampaignSecret.read(secret_path(db, campaign))


def secret_file(db: Path, campaign: str) -> str:
    """``--secret-file`` of an island of the coordinator whose database is ``db``."""
    from island.secret import secret_path

    return str(secret_path(db, campaign))


class Lines:
    """Every line a process writes to one of its pipes, collected by a thread (read while it runs)."""

    def __init__(self, pipe) -> None:
        import threading

        self.lines: list[str] = []
        self.thread = threading.Thread(target=self._read, args=(pipe,), daemon=True)
        self.thread.start()

    def _read(self, pipe) -> None:
        for line in pipe:
            self.lines.append(line)

    def text(self) -> str:
        return "".join(self.lines)

    def wait_for(self, fragment: str, timeout: float) -> None:
        wait_for(lambda: fragment in self.text(), timeout, f"{fragment!r} in the output")


class Peer:
    """A hand-driven party over Zenoh, from its own session, for broken or hostile ones: given the
    campaign ``secret`` it joins like an island (a member that lies), without it it is an outsider;
    then it sends whatever a test wants under any key of the campaign."""

    def __init__(self, endpoint: str, campaign: str, island: str, *, secret=None, algo: str = "pso", seed: int = 0) -> None:
        from island.joining import join
        from island.sealing import Counter
        from island.session import open_session, session_config

        self.campaign, self.island = campaign, island
        self.session = open_session(session_config("client", connect=[endpoint], connect_timeout_s=60.0), endpoint)
        self.credentials = join(self.session, campaign, island, algo, seed, secret, 30.0) if secret is not None else None
        self.seq = Counter()
        self.entities: list = []

    def put(self, kind: str, payload: bytes, key_island: str | None = None) -> None:
        """Publish on ``hysid/<campaign>/<kind>/<island>`` (``kind`` alone when it has no island part)."""
        island = key_island or self.island
        self.session.put(f"hysid/{self.campaign}/{kind}/{island}" if kind in ("migrants", "history", "join") else f"hysid/{self.campaign}/{kind}", payload)

    def publisher(self, kind: str, key_island: str | None = None):
        """A publisher that blocks rather than drops (every message of a flood arrives)."""
        import zenoh

        return self.session.declare_publisher(f"hysid/{self.campaign}/{kind}/{key_island or self.island}", congestion_control=zenoh.CongestionControl.BLOCK)

    def token(self, island: str | None = None) -> None:
        self.entities.append(self.session.liveliness().declare_token(f"hysid/{self.campaign}/members/{island or self.island}"))

    def close(self) -> None:
        """Leave (again: a no-op): its token goes with its session, and a coordinator records it lost
        within LEAVE_GRACE_S instead of waiting STALE_S for a member it still hears nothing from."""
        entities, self.entities = self.entities, []
        for entity in entities:
            entity.undeclare()
        self.session.close()


def screen_of(argv: list[str], timeout: float, until: Callable[[str], bool] | None = None, columns: int = 160) -> tuple[int | None, str]:
    """Run ``argv`` on a pseudo-terminal (stdout and stderr) of ``columns`` columns; returns its exit
    status (None if it was still running when ``until(text so far)`` held) and everything it wrote."""
    import fcntl
    import os
    import pty
    import select
    import struct
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


FS = 3000.0
"""Sample rate of :func:`record`."""


def record(label: str, freq: float, x0: float, seed: int, cycles: int = 10) -> RawRecord:
    """A small raw record: a sine displacement with noise, a phase-shifted force with a third harmonic and noise."""
    rng = np.random.default_rng(seed)
    t = np.arange(int(cycles / freq * FS)) / FS
    theta = 2 * np.pi * freq * t + 0.3
    force = 2e4 * x0 * (np.sin(theta + 0.5) + 0.1 * np.sin(3 * theta)) + 0.02 * rng.standard_normal(t.size)
    return RawRecord(label, freq, x0, t, x0 * np.sin(theta) + 1e-3 * x0 * rng.standard_normal(t.size), force, 0.02)


def same_loops(loops: LoopSet, reference: LoopSet) -> None:
    """The same loops as the reference, up to the 12 significant digits the CSV records keep."""
    assert loops.labels == reference.labels
    np.testing.assert_allclose(loops.freq_hz, reference.freq_hz, rtol=1e-9)
    np.testing.assert_allclose(loops.x0, reference.x0, rtol=1e-8)
    np.testing.assert_allclose(loops.top, reference.top, rtol=1e-6, atol=1e-9 * np.abs(reference.top).max())
    np.testing.assert_allclose(loops.bottom, reference.bottom, rtol=1e-6, atol=1e-9 * np.abs(reference.bottom).max())
