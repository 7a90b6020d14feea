"""Progress on stderr: a bar with an ETA on a terminal, a plain line per tenth otherwise, nothing with --json."""

from __future__ import annotations

import io
import re

import numpy as np
import pytest

import hysid
from hysid.cli import main
from hysid.cli.progress import PLAIN_STEPS, Progress
from support import hysid as hysid_argv, screen_of

SMALL = ["--islands", "2", "--population", "20", "--initial", "40", "--iterations", "10"]
PLAIN = re.compile(r"(\w+): (\d+)% \((\d+)/(\d+)\), (\d+:\d\d) elapsed(, about \d+:\d\d left)?(; .*)?")


def test_plain_lines_at_each_tenth_with_the_time_left():
    stream = io.StringIO()  # not a terminal
    with Progress("reproducing", 32, stream=stream) as progress:
        for i in range(32):
            progress.advance(f"run {i + 1}")
    lines = stream.getvalue().splitlines()
    assert len(lines) == PLAIN_STEPS
    parsed = [PLAIN.fullmatch(line) for line in lines]
    assert all(parsed) and [int(m[2]) for m in parsed] == sorted(int(m[2]) for m in parsed)
    assert lines[-1].startswith("reproducing: 100% (32/32), ") and lines[-1].endswith("elapsed; run 32")
    assert all(m[6] for m in parsed[:-1])  # an ETA until the end
    quiet = io.StringIO()
    with Progress("x", 3, enabled=False, stream=quiet) as progress:
        progress.advance()
    assert quiet.getvalue() == ""


@pytest.mark.slow
def test_fit_and_campaign_print_plain_progress_off_a_terminal_and_nothing_with_json(tmp_path, capsys):
    assert main(["fit", "synth", "--out", str(tmp_path / "f")]) == 0
    err = capsys.readouterr().err.splitlines()
    assert 1 <= len(err) <= PLAIN_STEPS and all(PLAIN.fullmatch(line) for line in err)
    assert err[-1].startswith("fitting: 100% (19/19)") and "run 1/1, best " in err[-1]
    assert main(["fit", "synth", "--json", "--out", str(tmp_path / "g")]) == 0
    assert capsys.readouterr().err == ""
    assert main(["campaign", "--single-node", *SMALL, "--out", str(tmp_path / "c")]) == 0
    err = capsys.readouterr().err
    assert "| evaluations " in err and "| best " in err and "members 2" in err  # the coordinator's lines
    assert main(["campaign", "--single-node", *SMALL, "--json", "--out", str(tmp_path / "d")]) == 0
    assert capsys.readouterr().err == ""


@pytest.mark.slow  # over 3 s
def test_diagnose_reports_each_fit_without_changing_the_result():
    loops = hysid.load("synth", noise_pct=5.0, noise_seed=2)
    subset = loops.subset(np.arange(0, loops.n_loops, 4))
    calls = []
    watched = hysid.diagnose(subset, cross_validate=False, progress=lambda done, total, what: calls.append((done, total, what)))
    plain = hysid.diagnose(subset, cross_validate=False)
    assert watched.to_dict() == plain.to_dict()
    assert [c[0] for c in calls] == list(range(1, len(calls) + 1)) and all(done <= total for done, total, _ in calls)
    assert calls[-1][:2] == (len(calls), len(calls)) and calls[-1][2] == "gap after step 2"
    assert calls[0][2] == "start model baseline fitted" and any("refitted with amplitude_dependent_frequency" in c[2] for c in calls)


@pytest.mark.slow
@pytest.mark.parametrize(
    "argv, label, total",
    [(["fit", "synth", "--runs", "2"], "fitting", "/38"), (["campaign", "--single-node", *SMALL], "campaign", "/20"),
     (["diagnose", "synth", "--points", "30"], "diagnosing", "/")],
)
def test_a_bar_with_an_eta_on_a_terminal(argv, label, total, tmp_path):
    code, screen = screen_of(hysid_argv(*argv, "--out", str(tmp_path / "o")), 300)
    assert code == 0, screen
    bar = [frame for frame in re.sub(r"\x1b\[[0-9;?]*[A-Za-z]", "", screen).split("\r") if frame.startswith(label)]
    assert bar and any("ETA" in frame and total in frame for frame in bar), screen[-2000:]
    assert any(re.search(r"ETA\s+\d+:\d\d:\d\d", frame) for frame in bar)
