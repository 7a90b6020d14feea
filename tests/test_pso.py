"""The thesis PSO (island.pso): constriction, bounded moves, async/sync Pg, ring, budget, checkpoints, migrants, Synth."""

from __future__ import annotations

import msgpack
import numpy as np
import pytest

from hysid_model.errors import HysidInputError
from hysid_model.synth import TRUE_PARAMS
from island.pso import PSO, bounded_move, constriction
from support import PSO_SMALL as SMALL
from support import ask_sizes, drive, polished_to_truth


def initialised(model, objective, **options):
    pso = PSO(model.bounds, 7, **{**SMALL, **options})
    x = pso.ask()
    pso.tell(x, objective(x))
    return pso


def test_constriction_factor_eq_3_8():
    assert constriction(2.05, 2.05) == pytest.approx(0.729843788, abs=1e-9)
    assert pytest.approx(0.7298, abs=5e-5) == PSO(np.array([[0.0, 1.0]]), 0).K
    with pytest.raises(HysidInputError, match="exceed 4"):
        PSO(np.array([[0.0, 1.0]]), 0, phi1=2.0, phi2=2.0)


def test_out_of_bounds_coordinate_stays_and_loses_its_velocity():
    bounds = np.array([[0.0, 1.0], [0.0, 1.0], [0.0, 1.0]])
    x = np.array([[0.5, 0.9, 0.1]])
    v = np.array([[0.2, 0.2, -0.2]])
    new_x, new_v = bounded_move(x, v, bounds)
    assert new_x[0] == pytest.approx([0.7, 0.9, 0.1])
    assert np.array_equal(new_v, [[0.2, 0.0, 0.0]])
    landing_on_bound = bounded_move(np.array([[0.5]]), np.array([[0.5]]), bounds[:1])  # open bounds: 1.0 is out
    assert landing_on_bound[0][0, 0] == 0.5 and landing_on_bound[1][0, 0] == 0.0


def test_particles_stay_strictly_inside_and_zeroed_velocities_are_the_blocked_ones(synth):
    model, objective = synth
    pso = initialised(model, objective)
    lower, upper = model.bounds[:, 0], model.bounds[:, 1]
    for _ in range(3 * pso.population):
        before = pso.x.copy()
        x = pso.ask()
        pso.tell(x, objective(x))
        if x.shape[0] == 1:
            i = (pso._particle - 1) % pso.population
            blocked = pso.v[i] == 0
            assert np.array_equal(pso.x[i][blocked], before[i][blocked])
    assert np.all((pso.x > lower) & (pso.x < upper))


def test_async_ask_moves_one_particle_towards_the_freshly_updated_pg(synth):
    """Fig. 3.12: particle 1 already follows the Pg that particle 0 set in the same iteration."""
    model, objective = synth
    pso = initialised(model, objective)
    assert pso.ask().shape == (1, 4)
    x0 = pso.ask()
    pso.tell(x0, [-1.0])  # particle 0 found the best point ever: it becomes Pg at once
    assert np.array_equal(pso.Pg, x0[0]) and pso.Pgf == -1.0
    # particle 1 starts at its personal best with zero velocity: v = K phi2 r2 (Pg - x)
    start = pso.x[1].copy()
    x1 = pso.ask()[0]
    step = x1 - start
    moved = step != 0
    assert moved.any()
    assert np.array_equal(np.sign(step[moved]), np.sign(x0[0] - start)[moved])


def test_sync_ask_moves_the_whole_swarm_with_last_iterations_pg(synth):
    model, objective = synth
    pso = initialised(model, objective, synchronous=True)
    pg, start = pso.Pg.copy(), pso.x.copy()
    x = pso.ask()
    assert x.shape == (30, 4)
    step = x - start
    moved = step != 0
    assert np.array_equal(np.sign(step)[moved], np.sign(pg - start)[moved])
    pso.tell(x, objective(x))
    assert pso.ask().shape == (15, 4)  # then the additional population around Pg


@pytest.mark.parametrize("neighbourhood", ["global", "ring"])
def test_social_attractor_is_global_best_or_ring_neighbourhood_best(synth, neighbourhood):
    model, objective = synth
    pso = initialised(model, objective, synchronous=True, neighbourhood=neighbourhood)
    pso.Pf = pso.Pf[np.random.default_rng(0).permutation(30)]  # scatter the ranks over the ring
    start = pso.x.copy()
    if neighbourhood == "ring":
        ring = (np.arange(30)[:, None] + [-1, 0, 1]) % 30
        attractor = pso.P[ring[np.arange(30), np.argmin(pso.Pf[ring], axis=1)]]
    else:
        attractor = np.broadcast_to(pso.Pg, start.shape)
    step = pso.ask() - start  # P = x and v = 0 after iteration 0: v = K phi2 r2 (attractor - x)
    moved = step != 0
    assert moved.sum() > 30
    assert np.array_equal(np.sign(step)[moved], np.sign(attractor - start)[moved])


def test_ask_sizes_and_thesis_budget(synth):
    model, objective = synth
    pso = PSO(model.bounds, 0)
    assert ask_sizes(pso, objective) == [6000] + ([1] * 500 + [15]) * 18
    assert pso.evaluations == 15270 and len(pso.history) == 19


@pytest.mark.parametrize("options", [{}, {"synchronous": True}, {"neighbourhood": "ring"}])
def test_elitism_and_pg_is_the_best_known(synth, options):
    model, objective = synth
    pso = drive(PSO(model.bounds, 3, **SMALL, **options), objective)
    assert np.all(np.diff(pso.history) <= 0) and pso.history[-1] < pso.history[0]
    assert pso.Pgf == pso.history[-1] <= pso.Pf.min()
    x, f = pso.best(3)
    assert np.array_equal(x[0], pso.Pg) and f[0] == pytest.approx(objective(x[:1])[0])
    assert not np.array_equal(x[0], x[1])


@pytest.mark.parametrize("neighbourhood", ["global", "ring"])
def test_additional_population_updates_pg_and_with_a_ring_the_best_particle(synth, neighbourhood):
    model, objective = synth
    pso = initialised(model, objective, synchronous=True, neighbourhood=neighbourhood)
    x = pso.ask()
    pso.tell(x, objective(x))
    best_particle = int(np.argmin(pso.Pf))
    extra = pso.ask()
    f = objective(extra)
    f[4] = -1.0
    pso.tell(extra, f)
    assert np.array_equal(pso.Pg, extra[4]) and pso.Pgf == -1.0 and pso.iteration == 1
    in_swarm = np.all(extra[4] == pso.P, axis=1)
    if neighbourhood == "ring":  # the neighbourhoods can only see it through a personal best
        assert np.flatnonzero(in_swarm).tolist() == [best_particle] and pso.Pf[best_particle] == -1.0
    else:  # the thesis' global PSO only moves Pg
        assert not in_swarm.any()


def test_seeded_determinism(synth):
    model, objective = synth
    a = drive(PSO(model.bounds, 11, **SMALL), objective)
    b = drive(PSO(model.bounds, 11, **SMALL), objective)
    c = drive(PSO(model.bounds, 12, **SMALL), objective)
    assert a.history == b.history and np.array_equal(a.x, b.x)
    assert a.history != c.history


@pytest.mark.parametrize("options", [{}, {"synchronous": True}, {"neighbourhood": "ring"}])
@pytest.mark.parametrize("stop_after_asks", [1, 4, 17, 31])
def test_checkpoint_round_trip_resumes_bit_for_bit(synth, options, stop_after_asks):
    model, objective = synth
    reference = drive(PSO(model.bounds, 21, **SMALL, **options), objective)
    pso = PSO(model.bounds, 21, **SMALL, **options)
    for _ in range(stop_after_asks):
        if pso.done:
            break
        x = pso.ask()
        pso.tell(x, objective(x))
    restored = PSO.from_state(msgpack.unpackb(msgpack.packb(pso.state_dict())))
    drive(restored, objective)
    assert restored.history == reference.history
    assert restored.evaluations == reference.evaluations
    assert np.array_equal(restored.x, reference.x) and np.array_equal(restored.v, reference.v)


def test_uncomputable_particle_is_redrawn_before_the_next_one_moves():
    bounds = np.array([[0.0, 1.0], [0.0, 1.0]])
    pso = PSO(bounds, 1, initial_population=50, population=10, iterations=2)
    x = pso.ask()
    pso.tell(x, np.sum(x**2, axis=1))
    first = pso.ask()
    pso.tell(first, [np.inf])  # "Couldn't calculate. Generating new particle"
    again = pso.ask()
    assert again.shape == (1, 2) and not np.array_equal(again, first) and pso._particle == 0
    pso.tell(again, [5.0])
    assert np.array_equal(pso.x[0], again[0]) and pso._particle == 1


def test_inject_makes_a_migrant_the_worst_particles_position_and_personal_best(synth):
    model, objective = synth
    pso = initialised(model, objective)
    for _ in range(5):  # give the particles some velocity
        x = pso.ask()
        pso.tell(x, objective(x))
    truth = model.from_dict(TRUE_PARAMS)
    w = int(np.argmax(pso.Pf))
    worst = pso.Pf[w]
    assert pso.inject(truth[None, :], [0.0]) == 1
    assert np.array_equal(pso.x[w], truth) and np.array_equal(pso.P[w], truth)
    assert pso.Pf[w] == 0.0 and np.all(pso.v[w] == 0)
    assert np.array_equal(pso.Pg, truth) and pso.Pgf == 0.0
    assert pso.inject(truth * 1.0001, [worst * 10]) == 0
    outside = truth.copy()
    outside[0] = -0.1
    assert pso.inject(outside, [0.0]) == 0


def test_options_are_validated():
    bounds = np.array([[0.0, 1.0]])
    with pytest.raises(HysidInputError, match="neighbourhood"):
        PSO(bounds, 0, neighbourhood="star")
    with pytest.raises(HysidInputError, match="initial_population"):
        PSO(bounds, 0, initial_population=10, population=20)
    with pytest.raises(HysidInputError, match="synchronous"):
        PSO(bounds, 0, synchronous="yes")


def test_reaches_the_noiseless_synth_optimum(synth):
    """Thesis budget (async, global, 15270 evaluations). Alone, as in Table 5.9, it pins w0 to about 3e-4
    (median over 20 seeds; worst 8e-4), S_w to ~4 %, xi0 to ~5 %, S_xi to ~45 %; the polish reaches the truth."""
    model, objective = synth
    truth = model.from_dict(TRUE_PARAMS)
    polished_to_truth(drive(PSO(model.bounds, 0), objective), objective, truth)
