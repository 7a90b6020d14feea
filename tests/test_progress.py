"""Progress on stderr: a bar with an ETA on a terminal, a plain line per tenth otherwise, nothing with --json."""

from __future__ import annotations

import io
import re
from itertools import pairwise

import numpy as np
import pytest

import hysid
from hysid.cli import main
from hysid.cli.progress import PLAIN_STEPS, Progress
from hysid.diagnosis.tally import MEMORY_FIT_WEIGHT, Tally
from hysid.report import jsondoc
from support import hysid as hysid_argv
from support import screen_of

FEW_POINTS = ["--points", "20"]  # what progress shows does not depend on the loops' size: 20 points a branch, not 100
# a campaign's lines end before its report: drawn without figures
SMALL = ["--islands", "2", "--population", "20", "--initial", "40", "--iterations", "10", *FEW_POINTS, "--no-figures"]
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
    assert main(["fit", "synth", *FEW_POINTS, "--no-figures", "--out", str(tmp_path / "f")]) == 0  # its lines end before the report
    err = capsys.readouterr().err.splitlines()
    assert 1 <= len(err) <= PLAIN_STEPS and all(PLAIN.fullmatch(line) for line in err)
    assert err[-1].startswith("fitting: 100% (19/19)") and "run 1/1, best " in err[-1]
    assert main(["fit", "synth", *FEW_POINTS, "--no-figures", "--json", "--out", str(tmp_path / "g")]) == 0
    assert capsys.readouterr().err == ""
    assert main(["campaign", "--single-node", *SMALL, "--out", str(tmp_path / "c")]) == 0
    err = capsys.readouterr().err
    assert "| evaluations " in err and "| best " in err and "members 2" in err  # the coordinator's lines
    assert main(["campaign", "--single-node", *SMALL, "--json", "--out", str(tmp_path / "d")]) == 0
    assert capsys.readouterr().err == ""


def test_a_diagnosis_tally_never_falls_and_is_done_only_at_the_end():
    """Work expected, found larger, then smaller, and work nobody expected: the share done only grows, stays
    below 1 until finish, and done/total is that share."""
    calls = []
    tally = Tally(lambda done, total, what: calls.append((done, total, what)))
    tally.expect(10)
    for k in range(3):
        tally.done(f"fit {k}")
    tally.expect(20)  # a round found more contenders than expected
    tally.done("heavy fit", MEMORY_FIT_WEIGHT)
    tally.expect(-40)  # the rounds that never came
    for k in range(3):
        tally.done(f"more than expected {k}")
    tally.finish("done")
    shares = [done / total for done, total, _ in calls]
    assert all(b > a for a, b in pairwise(shares)) and max(shares[:-1]) < 1.0 == shares[-1]
    heavy = 3 + MEMORY_FIT_WEIGHT
    assert [done for done, _, _ in calls] == [1, 2, 3, heavy, heavy + 1, heavy + 2, heavy + 3, heavy + 3]  # the work done, in fits
    assert calls[0][1] == pytest.approx(11.0) and calls[-1][1] == 6 + MEMORY_FIT_WEIGHT  # 10 fits and the closing unit at first


@pytest.mark.slow  # over 3 s
def test_diagnose_reports_each_fit_without_changing_the_result():
    """Honest progress: an estimate of the fits from the start (the held-out checks and gaps among them) whose share done
    never falls and is 1 only once the diagnosis is done (it went 1/2, 1/6, ... and 100 % at the last gap). 30 points a
    branch, as the bar's diagnosis below: the steps and their order are those of 100 (8.3 against 10.2 CPU-s a diagnosis)."""
    loops = hysid.load("synth", noise_pct=5.0, noise_seed=2, n_points=30)
    subset = loops.subset(np.arange(0, loops.n_loops, 4))
    calls = []
    watched = hysid.diagnose(subset, progress=lambda done, total, what: calls.append((done, total, what)))
    plain = hysid.diagnose(subset)
    assert jsondoc.dumps(watched.to_dict()) == jsondoc.dumps(plain.to_dict())  # NaN (an error not given) as null: equal
    shares = [done / total for done, total, _ in calls]
    assert all(b > a for a, b in pairwise(shares)) and max(shares[:-1]) < 1.0 == shares[-1]
    assert calls[0][2] == "start model baseline fitted" and calls[0][1] > 20  # the whole diagnosis expected from the start
    whats = [c[2] for c in calls]
    assert any("refitted with amplitude_dependent_frequency" in w for w in whats) and "gap after step 2" in whats
    assert "step 1: amplitude_dependent_frequency checked on held-out frequencies" in whats
    assert whats[-1] == "diagnosis done: baseline+amplitude_dependent_frequency+amplitude_dependent_damping, adequate"


@pytest.mark.slow
@pytest.mark.parametrize(
    "argv, label, total",
    [
        (["fit", "synth", "--runs", "2", *FEW_POINTS], "fitting", "/38"),
        (["campaign", "--single-node", *SMALL], "campaign", "/20"),
        (["diagnose", "synth", "--points", "30"], "diagnosing", "/"),
    ],
)
def test_a_bar_with_an_eta_on_a_terminal(argv, label, total, tmp_path):
    code, screen = screen_of(hysid_argv(*argv, "--out", str(tmp_path / "o")), 300)
    assert code == 0, screen
    bar = [frame for frame in re.sub(r"\x1b\[[0-9;?]*[A-Za-z]", "", screen).split("\r") if frame.startswith(label)]
    assert bar and any("ETA" in frame and total in frame for frame in bar), screen[-2000:]
    assert any(re.search(r"ETA\s+\d+:\d\d:\d\d", frame) for frame in bar)
    if label == "diagnosing":  # the share shown never falls, and the report's figures are part of the work
        shares = [int(m[1]) for frame in bar if (m := re.search(r"\s(\d+)%\s", frame))]
        assert shares == sorted(shares) and any("writing the report" in frame for frame in bar), bar
