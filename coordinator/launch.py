"""The campaign launcher: a coordinator and N islands on this machine, to a stop rule.

Islands run as separate processes (``hysid island``) connected over Zenoh to a
coordinator in this process, listening on a free loopback port; each is handed
a member secret of its own in its environment (its island id is the member's
name): whoever reads one process' secret is one member, bounded like any other
(:mod:`coordinator.admission`). With
``single_node`` (or automatically, with a :class:`HysidWarning`, when Zenoh
cannot open a session here) the islands are threads of this process
exchanging migrants in memory (:class:`island.memory.MemoryBus`); the
coordinator, the database and the outcome are the same.
"""

from __future__ import annotations

import math
import os
import socket
import subprocess
import sys
import tempfile
import threading
import time
import warnings
from collections.abc import Callable
from pathlib import Path
from typing import TextIO

from coordinator.interrupt import INTERRUPTED
from coordinator.links import MemoryLink, ZenohLink
from coordinator.loop import serve
from coordinator.outcome import CampaignOutcome
from coordinator.progress import CampaignProgress
from coordinator.state import Coordinator
from hysid_model.errors import HysidInputError, HysidWarning
from hysid_model.model import Model
from hysid_model.user_terms import module_roots
from island.host import IslandSpec
from island.memory import MemoryBus, MemoryTransport
from island.node import IslandNode
from island.secret import SECRET_ENV, SECRET_FILE_ENV, CampaignSecret
from island.session import open_session, session_config
from island.wire import MAX_MEMBERS

ISLAND_EXIT_WAIT_S = 15.0
"""After the campaign stopped, how long its island processes are given to exit before they are killed."""
INTERRUPTED_EXIT_WAIT_S = 0.5
"""The same after Ctrl-C: their last rows are in (or were given up on), and the user waits."""
MEMORY_WAIT_S = 5.0
"""How long an island thread waits for room in the coordinator's inbox before its message is dropped."""
MEMORY_HISTORY_EVERY_S = 0.02
"""How often an island thread sends its history: in memory a message costs little, and the
coordinator's count of evaluations (budget, the share of a mixed campaign) follows the islands closely."""


def island_specs(n: int, algos: list[str], seed: int) -> list[IslandSpec]:
    """``n`` islands ``island-0`` .. ``island-<n-1>`` cycling through ``algos``, seeds ``seed .. seed+n-1``. An island
    is named by its index, not its algorithm: a mixed campaign's share may move it to another (its algorithms are
    shown beside its name, ``island-0 (ga -> pso)``)."""
    if isinstance(n, bool) or not isinstance(n, int) or n < 1:
        raise HysidInputError("a campaign needs at least one island", param="islands", value=n)
    if n > MAX_MEMBERS:
        raise HysidInputError(f"a campaign admits at most {MAX_MEMBERS} islands", param="islands", value=n)
    return [IslandSpec(f"island-{i}", algos[i % len(algos)], seed + i) for i in range(n)]


def free_port() -> int:
    """A TCP port on loopback that nobody listens on right now."""
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def run_single_node(coordinator: Coordinator, specs: list[IslandSpec], on_progress: Callable[[CampaignProgress], None] | None = None) -> str:
    """Every island as a thread of this process, admitted by the coordinator; returns the stop reason."""
    stop = threading.Event()
    bus = MemoryBus(
        coordinator.name,
        [s.id for s in specs],
        lambda key, data: coordinator.receive(key, data, wait_s=MEMORY_WAIT_S),
        stop,
        admit=lambda island, algo, seed, key: coordinator.admit(island, algo, seed, key, member=island),  # each a member, as processes
        assigned=lambda island: coordinator.sharing.assigned.get((island, coordinator.current.get(island, ""))),
        coordinator=coordinator.secret.coordinator,
    )
    nodes = [
        IslandNode(s.id, s.algo, s.seed, coordinator.config, coordinator.config.objective(coordinator.loops), history_every_s=MEMORY_HISTORY_EVERY_S)
        for s in specs
    ]
    coordinator.membership.stale_s = math.inf  # threads of this process: nobody can pose as them, and a slow iteration is no loss
    transports = [bus.transport(node.island, node.algo, node.seed) for node in nodes]
    errors: list[BaseException] = []

    def work(node: IslandNode, transport: MemoryTransport) -> None:
        try:
            node.run(transport)
        except BaseException as exc:  # re-raised in the main thread below
            errors.append(exc)
            stop.set()
        finally:
            transport.close()
            coordinator.member(node.island, False, wait_s=None)

    for node in nodes:
        coordinator.member(node.island, True, wait_s=None)
    threads = [threading.Thread(target=work, args=pair, name=f"island-{pair[0].island}", daemon=True) for pair in zip(nodes, transports)]
    for t in threads:
        t.start()
    try:
        reason = serve(coordinator, MemoryLink(stop), on_progress)
    finally:
        stop.set()
        for t in threads:
            t.join()
    if errors:
        raise errors[0]
    return reason


def island_command(endpoint: str, campaign: str, spec: IslandSpec) -> list[str]:
    """``hysid island`` for ``spec`` with this interpreter; ``-P`` keeps the working directory off
    ``sys.path``, so that a folder named ``hysid`` there (e.g. a clone's parent) cannot shadow the package.
    Its member secret goes in the environment (:func:`island_environment`), never on the command line."""
    return [
        sys.executable,
        "-P",
        "-m",
        "hysid",
        "island",
        "--connect",
        endpoint,
        "--campaign",
        campaign,
        "--algo",
        spec.algo,
        "--seed",
        str(spec.seed),
        "--id",
        spec.id,
        "--quiet",
    ]


def island_environment(secret: CampaignSecret, model: Model) -> dict[str, str]:
    """This process' environment for an island process: its ``secret`` (:data:`island.secret.SECRET_ENV`),
    and the directories of ``model``'s own terms' modules added to ``PYTHONPATH``: an island process imports
    them by their model string (``-P`` keeps its working directory off its path)."""
    env = {k: v for k, v in os.environ.items() if k != SECRET_FILE_ENV}
    env[SECRET_ENV] = secret.text()
    roots = [r for r in module_roots(model.terms) if r not in env.get("PYTHONPATH", "").split(os.pathsep)]
    if roots:
        env["PYTHONPATH"] = os.pathsep.join(([env["PYTHONPATH"]] if env.get("PYTHONPATH") else []) + roots)
    return env


def run_processes(
    coordinator: Coordinator, specs: list[IslandSpec], endpoint: str, link: ZenohLink, on_progress: Callable[[CampaignProgress], None] | None = None
) -> str:
    """One ``hysid island`` process per spec, connected to ``endpoint``; returns the stop reason."""
    with tempfile.TemporaryDirectory(prefix="hysid-islands-") as logs:
        procs = []
        for spec in specs:
            log = open(Path(logs) / f"{spec.id}.log", "w+")  # noqa: SIM115 (the island's stderr while it runs; closed with it below)
            env = island_environment(coordinator.keys.member_secret(spec.id), coordinator.objective.model)  # a member of its own
            procs.append((spec, subprocess.Popen(island_command(endpoint, coordinator.name, spec), stdout=subprocess.DEVNULL, stderr=log, env=env), log))

        def all_exited() -> str | None:
            codes = [p.poll() for _, p, _ in procs]
            if any(c is None for c in codes):
                return None
            failed = [f"{s.id} (exit {c}: {tail(log)})" for (s, _, log), c in zip(procs, codes) if c != 0]
            return "every island process exited" + (f"; failed: {'; '.join(failed)}" if failed else "")

        try:
            reason = serve(coordinator, link, on_progress, extra_stop=all_exited)
        except KeyboardInterrupt:  # a second Ctrl-C leaves at once: the islands too (also one frozen)
            for _, p, _ in procs:
                if p.poll() is None:
                    p.kill()
            raise
        finally:
            deadline = time.monotonic() + (INTERRUPTED_EXIT_WAIT_S if coordinator.stop_reason == INTERRUPTED else ISLAND_EXIT_WAIT_S)
            for _, p, log in procs:
                try:
                    p.wait(timeout=max(deadline - time.monotonic(), 0.1))
                except subprocess.TimeoutExpired:
                    p.kill()
                    p.wait()
                log.close()
    return reason


def tail(log: TextIO) -> str:
    log.flush()
    log.seek(0)
    lines = [line.strip() for line in log.read().splitlines() if line.strip()]
    return lines[-1][:300] if lines else "no output"


def run_campaign(
    coordinator: Coordinator,
    specs: list[IslandSpec],
    *,
    single_node: bool = False,
    on_progress: Callable[[CampaignProgress], None] | None = None,
    polish: bool = True,
    endpoint: str | None = None,
) -> CampaignOutcome:
    """Run the islands (processes over Zenoh, else threads) to a stop rule; the polished outcome.

    The coordinator listens on ``endpoint`` (default: a free loopback port).
    """
    session = None
    if not single_node:
        endpoint = endpoint or f"tcp/127.0.0.1:{free_port()}"
        try:
            session = open_session(session_config("router", listen=[endpoint]), f"listen {endpoint}")
        except HysidInputError as exc:
            warnings.warn(HysidWarning(f"{exc}; running every island in this process instead (single node)", "single_node_fallback"), stacklevel=2)
    if session is None:
        run_single_node(coordinator, specs, on_progress=on_progress)
    else:
        link = ZenohLink(session, coordinator)
        try:
            assert endpoint is not None  # set with the session
            run_processes(coordinator, specs, endpoint, link, on_progress)
        finally:
            link.close()
            session.close()
    return coordinator.outcome(polish_best=polish)
