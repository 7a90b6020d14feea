"""The run loop (island.run): rows, callbacks, migrate hook, early stop and resume."""

from __future__ import annotations

import msgpack
import numpy as np
import pytest

from hysid_model.synth import TRUE_PARAMS
from island.ga import GA
from island.pso import PSO
from island.run import HistoryRow, run
from support import GA_SMALL, PSO_SMALL


@pytest.mark.parametrize("make", [lambda b: GA(b, 1, **GA_SMALL), lambda b: PSO(b, 1, **PSO_SMALL)])
def test_rows_follow_the_history_and_reach_the_callback(synth, make):
    model, objective = synth
    opt = make(model.bounds)
    seen: list[HistoryRow] = []
    rows = run(opt, objective, callback=seen.append)
    assert seen == rows
    assert [r.iteration for r in rows] == list(range(6))
    assert [r.best_fitness for r in rows] == opt.history
    assert rows[-1].evaluations == opt.evaluations
    assert np.all(np.diff([r.evaluations for r in rows]) > 0)
    assert np.all(np.diff([r.wall_s for r in rows]) >= 0)
    assert rows[0].as_dict() == {"iteration": 0, "best_fitness": opt.history[0], "evaluations": rows[0].evaluations, "wall_s": rows[0].wall_s}


def test_migrate_runs_between_iterations_and_can_inject(synth):
    model, objective = synth
    truth = model.from_dict(TRUE_PARAMS)
    opt = GA(model.bounds, 2, **GA_SMALL)
    calls = []

    def migrate(o):
        calls.append(o.iteration)
        if o.iteration == 2:
            assert o.inject(truth[None, :], objective(truth[None, :])) == 1

    rows = run(opt, objective, migrate=migrate)
    assert calls == [0, 1, 2, 3, 4]  # not after the last iteration
    assert rows[2].best_fitness > 1e-20 and rows[3].best_fitness < 1e-20
    assert np.array_equal(opt.best()[0][0], truth)


@pytest.mark.parametrize("cls, options", [(GA, GA_SMALL), (PSO, PSO_SMALL), (PSO, {**PSO_SMALL, "synchronous": True})])
def test_early_stop_then_checkpoint_and_resume_equals_an_uninterrupted_run(synth, cls, options):
    model, objective = synth
    reference = cls(model.bounds, 9, **options)
    run(reference, objective)
    opt = cls(model.bounds, 9, **options)
    first = run(opt, objective, should_stop=lambda: len(opt.history) >= 3)
    assert len(first) == 3 and not opt.done
    resumed = cls.from_state(msgpack.unpackb(msgpack.packb(opt.state_dict())))
    rest = run(resumed, objective)
    assert [r.iteration for r in rest] == [3, 4, 5]
    assert resumed.history == reference.history
    assert resumed.evaluations == reference.evaluations
    assert np.array_equal(resumed.best(10)[0], reference.best(10)[0])


def test_stop_before_start_does_nothing(synth):
    model, objective = synth
    opt = GA(model.bounds, 0, **GA_SMALL)
    assert run(opt, objective, should_stop=lambda: True) == []
    assert opt.evaluations == 0 and not opt.history
