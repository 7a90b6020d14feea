"""The port of the thesis' MATLAB objective (Appendix A) against a literal transcription and by hand."""

from __future__ import annotations

import operator

import numpy as np
import pytest

from hysid_model.model import build_model
from hysid_model.synth import FREQUENCIES_HZ, MEQ_KG, TRUE_PARAMS, synth_loops
from hysid_model.thesis_port import (
    ThesisObjective,
    ThesisPortError,
    centercurveloop,
    erreval,
    erreval_points,
    getloopdisp,
    getloopdisp_indices,
    interp1_linear,
    leastsqdisp,
    reinterpolate,
    time_grid,
)

THETA = np.array([TRUE_PARAMS[k] for k in ("xi0", "S_xi", "w0", "S_w")])


def matlab_getloopdisp(hys1: np.ndarray) -> tuple[int, int, int, int]:
    """getloopdisp of Appendix A transcribed sample by sample (1-based; its while loops one ``walk``, its four runs one
    loop), returning 0-based TOPmin..BOTmax."""

    def h(row: int, col: int) -> float:
        if row < 1:
            raise IndexError("index 0")
        return hys1[row - 1, col - 1]

    def walk(i: int, holds) -> tuple[int, int]:
        """``while holds(hys1(NR-i,1), hys1(NR-i-1,1)), i=i+1; end``: the new i and how many rows it walked."""
        start = i
        while holds(h(nr - i, 1), h(nr - i - 1, 1)):
            i += 1
        return i, i - start

    nr = hys1.shape[0]
    i, _ = walk(0, operator.eq)
    ends, flats = [], []  # F1..F4, each after its run (x falling, rising, falling, rising); F1f..F3f at the turns after F1..F3
    for k, holds in enumerate((operator.lt, operator.gt, operator.lt, operator.gt)):
        i, _ = walk(i, holds)
        ends.append(nr - i)
        if k < 3:
            i, flat = walk(i, operator.eq)
            flats.append(flat)
    f1, f2, f3, f4 = ends
    f1f, f2f, f3f = flats
    if h(nr, 1) < h(nr - 1, 1) and h(nr, 2) < h(nr - 1, 2):
        found = (f2, f1 - f1f, f3, f2 - f2f)
    elif (h(nr, 1) > h(nr - 1, 1) and h(nr, 2) < h(nr - 1, 2)) or (h(nr, 1) > h(nr - 1, 1) and h(nr, 2) > h(nr - 1, 2)):
        found = (f4, f3 - f3f, f3, f2 - f2f)
    elif h(nr, 1) < h(nr - 1, 1) and h(nr, 2) > h(nr - 1, 2):
        found = (f2, f1 - f1f, f3, f2 - f2f)
    else:
        raise NameError("TOPmin undefined")
    return tuple(k - 1 for k in found)


def records() -> list[np.ndarray]:
    """erreval's model records at every Synth frequency, plus records with plateaus and noise."""
    rng = np.random.default_rng(3)
    t = time_grid()
    out = []
    for f in FREQUENCIES_HZ:
        w = 2 * np.pi * f
        out.append(np.column_stack([1e-3 * np.sin(w * t), np.cos(w * t + 0.3)]))
    for f, digits, end in ((7.0, 1, 4001), (13.0, 2, 3977), (5.5, 1, 2222), (9.0, 3, 1000)):
        w = 2 * np.pi * f
        x = np.round(np.sin(w * t[:end]), digits)  # repeated x at every turn and inside runs
        out.append(np.column_stack([x, np.sin(w * t[:end] + 1.0)]))
    for _ in range(12):
        n = int(rng.integers(20, 400))
        x = np.cumsum(rng.standard_normal(n))
        out.append(np.column_stack([np.round(x, 0), rng.standard_normal(n)]))
    return out


def test_getloopdisp_matches_the_literal_transcription():
    outcomes = {"ok": 0, "error": 0}
    for rec in records():
        try:
            expected = matlab_getloopdisp(rec)
        except (IndexError, NameError):
            with pytest.raises(ThesisPortError):
                getloopdisp_indices(rec)
            outcomes["error"] += 1
            continue
        assert getloopdisp_indices(rec) == expected
        outcomes["ok"] += 1
    assert outcomes["ok"] >= 44 and outcomes["error"] >= 1


def test_getloopdisp_cuts_the_last_loading_and_unloading_branch():
    f = 30.0
    t = time_grid()
    x = np.sin(2 * np.pi * f * t)
    hys1 = np.column_stack([x, np.cos(2 * np.pi * f * t)])
    top, bot = getloopdisp(hys1)
    assert np.all(np.diff(top[:, 0]) > 0) and np.all(np.diff(bot[:, 0]) < 0)
    assert top[-1, 0] > 0.999 and bot[-1, 0] < -0.999 and top[0, 0] < -0.999
    top_min, top_max, bot_min, bot_max = getloopdisp_indices(hys1)
    # one half period each (1/60 s on the 1e-4 s grid), the unloading one right after the loading one,
    # ending within the last period of the 0.4 s record
    assert abs(top_max - top_min - 167) <= 1 and abs(bot_max - bot_min - 167) <= 1
    assert bot_min == top_max and bot_max >= t.size - 1 - 334


def test_getloopdisp_raises_where_matlab_stops():
    flat_force = np.column_stack([np.sin(np.linspace(0, 20, 300)), np.ones(300)])
    with pytest.raises(ThesisPortError, match="four cases"):
        getloopdisp(flat_force)
    half_cycle = np.column_stack([np.sin(np.linspace(0, 3, 50)), np.arange(50.0)])
    with pytest.raises(ThesisPortError, match="start of the record"):
        getloopdisp(half_cycle)


def test_time_grid_is_matlab_colon():
    t = time_grid(0.4, 1e-4)
    assert t.size == 4001 and t[0] == 0.0 and t[-1] == pytest.approx(0.4, abs=1e-15)
    assert time_grid(0.3, 0.1).size == 4


def test_interp1_linear_nan_outside_any_direction():
    x = np.array([3.0, 2.0, 1.0])
    y = np.array([30.0, 20.0, 10.0])
    out = interp1_linear(x, y, np.array([0.5, 1.0, 1.5, 3.0, 3.5]))
    assert np.isnan(out[0]) and np.isnan(out[-1])
    np.testing.assert_allclose(out[1:4], [10.0, 15.0, 30.0])
    with pytest.raises(ThesisPortError, match="distinct"):
        interp1_linear(np.array([1.0, 1.0, 2.0]), y, np.array([1.5]))


def test_leastsqdisp():
    a = np.array([[0.0, 1.0], [1.0, 3.0]])
    assert leastsqdisp(a, np.array([0.0, 1.0])) == 5.0
    with pytest.raises(ThesisPortError):
        leastsqdisp(a, np.array([0.0]))


def test_erreval_drops_one_unreached_sample_per_branch_end_and_keeps_nan_beyond():
    loops = synth_loops(0.0)
    j = 45  # 1.0 mm, 29.5 Hz: the 1e-4 s grid misses both peaks of x
    top, bot, f, x0 = loops.top[j], loops.bottom[j], loops.freq_hz[j], loops.x0[j]
    keep, ymod = erreval_points(top, bot, THETA, f, x0, MEQ_KG)
    n = loops.n_samples
    assert not keep[0] and not keep[n - 1] and not keep[n] and not keep[-1]
    assert keep.sum() == 2 * n - 4 and np.all(np.isfinite(ymod[keep]))
    value = erreval(top, bot, THETA, f, x0, MEQ_KG)
    assert value == pytest.approx(np.sum((loops.forces()[j] - ymod)[keep] ** 2), rel=1e-12)
    wide = top.copy()
    wide[:, 0] = np.linspace(-1.05 * x0, 1.05 * x0, n)  # several samples beyond the model's reach
    assert np.isnan(erreval(wide, bot, THETA, f, x0, MEQ_KG))


def test_reinterpolate_and_centercurveloop():
    rng = np.random.default_rng(0)
    x = np.sort(rng.uniform(-2.0, 3.0, 40))
    top = np.column_stack([x, 4.0 * x + 1.0])
    bot = np.column_stack([x[::-1], -(x[::-1] ** 3)])
    rt, rb = reinterpolate(top, bot, 25)
    np.testing.assert_allclose(rt[:, 0], np.linspace(x.min(), x.max(), 25))
    np.testing.assert_allclose(rt[:, 1], 4.0 * rt[:, 0] + 1.0, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(rb[[0, -1], 1], -(np.array([x.min(), x.max()]) ** 3))
    ct, cb = centercurveloop(top + [1.0, 2.0], bot + [1.0, 2.0])
    both = np.concatenate([ct, cb])
    assert both[:, 0].max() == pytest.approx(-both[:, 0].min())
    assert both[:, 1].max() == pytest.approx(-both[:, 1].min())
    shift = np.concatenate([ct - top, cb - bot])
    np.testing.assert_allclose(shift, np.broadcast_to(shift[0], shift.shape), atol=1e-12)


def test_thesis_objective_is_the_weighted_sum_of_erreval():
    loops = synth_loops(10.0, seed=2).subset(np.arange(0, 120, 17))
    port = ThesisObjective(loops, build_model("thesis").fix(meq=MEQ_KG))
    max_f = np.maximum(np.abs(loops.top[:, :, 1]).max(axis=1), np.abs(loops.bottom[:, :, 1]).max(axis=1))
    nos = 2 * loops.n_samples
    weights = (max_f.max() / max_f) / nos  # loopsweights(j) / NOS of the GA program
    np.testing.assert_allclose(port.loop_weight, weights, rtol=1e-15)
    rng = np.random.default_rng(5)
    low, span = port.bounds[:, 0], port.bounds[:, 1] - port.bounds[:, 0]
    pop = low + span * rng.random((3, 4))
    expected = [sum(weights[j] * erreval(loops.top[j], loops.bottom[j], p, loops.freq_hz[j], loops.x0[j], MEQ_KG) for j in range(loops.n_loops)) for p in pop]
    got = port(pop)
    np.testing.assert_allclose(got, expected, rtol=1e-12)
    assert port.evaluations == 3
    np.testing.assert_allclose(port(pop[1]), got[1:2], rtol=1e-15)
    assert port.evaluations == 4
    bad = np.vstack([pop[0], [np.nan, 0.0, 190.0, 0.0], [0.0, 0.0, np.inf, 0.0]])
    out = port(bad)
    assert np.isfinite(out[0]) and np.all(np.isinf(out[1:]))
