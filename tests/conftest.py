"""Shared fixtures."""

import signal
import subprocess
from collections.abc import Callable, Iterator
from pathlib import Path

import numpy as np
import pytest

from hysid.bench.objective import distorted_synth
from hysid_model.model import build_model
from hysid_model.objective import Objective
from hysid_model.synth import MEQ_KG, synth_loops


@pytest.fixture(scope="module")
def synth():
    """The thesis model and its objective on the noiseless Synth set."""
    model = build_model("thesis").fix(meq=MEQ_KG)
    return model, Objective(synth_loops(0), model)


@pytest.fixture(scope="module")
def ideal():
    """Every seventh loop of the noiseless Synth set, 40 points per branch (the kernels' and Bouc-Wen's tests)."""
    return synth_loops(0.0, 0, 40).subset(np.arange(0, 120, 7))


@pytest.fixture(scope="module")
def distorted():
    """Every eleventh loop of the Synth set under a distorted displacement (the kernels' and Bouc-Wen's tests)."""
    return distorted_synth().subset(np.arange(0, 120, 11))


@pytest.fixture
def spawn() -> Iterator[Callable[..., subprocess.Popen]]:
    """Start ``hysid ARGS`` processes (text pipes); whatever is still running at the end is killed (only ours, by pid)."""
    from support import hysid, interruptible

    started: list[subprocess.Popen] = []

    def start(*args: str) -> subprocess.Popen:
        p = subprocess.Popen(hysid(*args), stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, preexec_fn=interruptible)
        started.append(p)
        return p

    yield start
    for p in started:
        if p.poll() is None:
            p.send_signal(signal.SIGCONT)
            p.kill()
        p.communicate(timeout=30)


@pytest.fixture(scope="session")
def certs(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """CA, coordinator certificate for 127.0.0.1/localhost, client certificates island-1 and island-2
    (deploy/tls/make-certs.sh; the deploy tests only read them)."""
    from deploy_support import make_certs, require_openssl

    require_openssl()
    outdir = tmp_path_factory.mktemp("certs")
    done = make_certs(outdir, "-s", "127.0.0.1", "-s", "localhost", "island-1", "island-2")
    assert done.returncode == 0, done.stderr
    return outdir
