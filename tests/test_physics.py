"""Physics checks: the closed-form branches against time integration of Eq. 4.4, the objective
against the thesis' erreval, and the periodic steady state of the time-domain path."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from hysid_model.model import build_model
from hysid_model.objective import Objective
from hysid_model.synth import MEQ_KG, TRUE_PARAMS, synth_loops, thesis_force
from hysid_model.thesis_port import ThesisObjective
from timedomain_reference import SteadyStateError, periodic_steady_state

NAMES = ("xi0", "S_xi", "w0", "S_w")
TRUTH = np.array([TRUE_PARAMS[k] for k in NAMES])


def modal(params: dict[str, float], x0: float) -> tuple[float, float]:
    """xi and wn at amplitude x0 (Eq. 4.8, 4.9)."""
    return params["xi0"] + params["S_xi"] * x0, params["w0"] + params["S_w"] * x0


def shooting_steady_state(freq_hz: float, x0: float, params: dict[str, float]):
    """Periodic steady state of x'' + 2 xi wn x' + wn^2 x = F(t)/Meq (Eq. 4.4) driven by the
    closed-form force of Eq. 4.10, by DOP853 and shooting: the period map of the linear ODE is
    z -> A z + b, so the periodic state solves (I - A) z = b. Returns the dense solution over one period."""
    w = 2 * np.pi * freq_hz
    xi, wn = modal(params, x0)
    period = 2 * np.pi / w
    scale = np.array([x0, x0 * w])

    def rhs(t, z):
        return [z[1], thesis_force(t, freq_hz, x0, params, MEQ_KG) / MEQ_KG - 2 * xi * wn * z[1] - wn**2 * z[0]]

    def flow(z0, dense=False):
        return solve_ivp(rhs, (0.0, period), z0, method="DOP853", rtol=1e-13, atol=1e-13 * scale, dense_output=dense)

    b = flow([0.0, 0.0]).y[:, -1]
    a = np.column_stack([flow([x0, 0.0]).y[:, -1] - b, flow([0.0, x0 * w]).y[:, -1] - b]) / scale
    z_star = np.linalg.solve(np.eye(2) - a, b)
    sol = flow(z_star, dense=True)
    np.testing.assert_allclose(sol.y[:, -1] / scale, z_star / scale, atol=1e-11)  # periodic indeed
    return sol


@pytest.mark.parametrize("freq_hz", [25.0, 29.5, 30.0, 34.0])  # below, near (at 0.5 mm: 30 Hz) and above resonance
@pytest.mark.parametrize("x0", [0.5e-3, 1.5e-3])
def test_closed_form_force_drives_eq_4_4_into_the_prescribed_motion(freq_hz, x0):
    """Fed back into Eq. 4.4, the thesis force (Eq. 4.10) yields x = X0 sin(wt) at steady state, and
    hysid's branch samples (x, F) lie on that numerically integrated loop."""
    w = 2 * np.pi * freq_hz
    sol = shooting_steady_state(freq_hz, x0, TRUE_PARAMS)
    t = np.linspace(0.0, 2 * np.pi / w, 2001)
    x, v = sol.sol(t)
    np.testing.assert_allclose(x / x0, np.sin(w * t), rtol=0, atol=1e-9)
    np.testing.assert_allclose(v / (x0 * w), np.cos(w * t), rtol=0, atol=1e-9)

    loops = synth_loops(0.0)
    j = int(np.flatnonzero((loops.freq_hz == freq_hz) & np.isclose(loops.x0, x0))[0])
    obj = Objective(loops, build_model("thesis").fix(meq=MEQ_KG))
    predicted = obj.predict(TRUTH)[0, j]
    phase = loops.phases()[j]
    t_samples = np.mod(phase, 2 * np.pi) / w
    force = thesis_force(t_samples, freq_hz, x0, TRUE_PARAMS, MEQ_KG)
    peak = np.abs(force).max()
    np.testing.assert_allclose(predicted, force, rtol=0, atol=1e-12 * peak)
    x_sample = np.concatenate([loops.top[j, :, 0], loops.bottom[j, :, 0]])
    x_numeric, v_numeric = sol.sol(t_samples)
    np.testing.assert_allclose(x_numeric / x0, x_sample / x0, rtol=0, atol=1e-9)
    n = loops.n_samples  # loading branch: x' >= 0, unloading: x' <= 0 (beyond round-off at the tips)
    assert np.all(v_numeric[:n] > -1e-9 * x0 * w) and np.all(v_numeric[n:] < 1e-9 * x0 * w)


def test_closed_form_force_by_rk4_periodic_steady_state():
    """The same check by :func:`periodic_steady_state` (in phase, from rest) for better damped oscillators."""
    cases = np.array(
        [  # xi, wn (rad/s), w/wn, X0 (m)
            [0.15, 200.0, 0.8, 0.5e-3],
            [0.20, 150.0, 1.0, 1.0e-3],
            [0.20, 180.0, 1.3, 1.5e-3],
            [0.25, 190.0, 1.15, 2.0e-3],
        ]
    ).T
    xi, wn, x0 = cases[0], cases[1], cases[3]
    w = wn * cases[2]
    params = {"xi0": xi, "S_xi": 0.0, "w0": wn, "S_w": 0.0}
    forces: dict[float, np.ndarray] = {}  # the RK4 grid's phases recur every cycle

    def rhs(theta, z):  # z = (x / X0, x' / (X0 w)) as functions of theta = wt
        if theta not in forces:
            forces[theta] = thesis_force(theta / w, w / (2 * np.pi), x0, params, MEQ_KG)
        force = forces[theta]
        return np.stack([z[1], (force / (MEQ_KG * x0) - 2 * xi * wn * w * z[1] - wn**2 * z[0]) / w**2])

    phase = np.linspace(-np.pi, 3 * np.pi, 77)
    z = periodic_steady_state(rhs, np.zeros((2, 4)), phase)
    assert z.shape == (2, 4, 77)
    np.testing.assert_allclose(z[0], np.broadcast_to(np.sin(phase), (4, 77)), rtol=0, atol=1e-9)
    np.testing.assert_allclose(z[1], np.broadcast_to(np.cos(phase), (4, 77)), rtol=0, atol=1e-9)


def test_objective_is_zero_at_the_true_parameters():
    loops = synth_loops(0.0)
    obj = Objective(loops, build_model("thesis").fix(meq=MEQ_KG))
    scale = np.sum(obj.loop_weight * np.sum(obj.y**2, axis=1))
    assert obj(TRUTH)[0] <= 1e-26 * scale
    assert np.max(np.abs(obj.residuals(TRUTH))) <= 1e-12 * np.abs(obj.y).max()
    assert obj(TRUTH * [1.01, 1, 1, 1])[0] > 1e-8 * scale


def test_objective_agrees_with_the_thesis_erreval():
    """Within 1 % on the samples both evaluate: erreval drops branch ends its 1e-4 s grid does not
    reach (at most one per branch end), which carry about 5 % of the error, so hysid is summed over
    the same kept samples."""
    loops = synth_loops(0.0)
    obj = Objective(loops, build_model("thesis").fix(meq=MEQ_KG))
    port = ThesisObjective(loops, obj.model)
    rng = np.random.default_rng(11)
    low, span = obj.bounds[:, 0], obj.bounds[:, 1] - obj.bounds[:, 0]
    pop = np.vstack(
        [
            low + span * rng.random((5, 4)),  # anywhere in Table 5.4's bounds
            TRUTH * (1.0 + 0.05 * rng.standard_normal((3, 4))),  # near the optimum
            TRUTH * (1.0 + 0.01 * rng.standard_normal((2, 4))),
        ]
    )
    thesis = port(pop)
    hysid_all = obj(pop)
    for theta, f_thesis, f_all in zip(pop, thesis, hysid_all):
        keep, _ = port.points(theta)
        assert np.all(keep.sum(axis=1) >= 2 * loops.n_samples - 4)
        f_kept = np.sum(obj.loop_weight * np.sum(np.where(keep, obj.residuals(theta) ** 2, 0.0), axis=1))
        assert f_thesis == pytest.approx(f_kept, rel=0.01)
        assert f_kept <= f_all
    assert port(TRUTH)[0] < 1e-5 * min(thesis)  # erreval's own interpolation error at the optimum


def test_periodic_steady_state_of_a_first_order_lag():
    """tau z' + z = sin(wt), i.e. dz/dtheta = (sin theta - z) / a with a = w tau, has the periodic
    solution z = (sin theta - a cos theta) / (1 + a^2); batch (2, 3), phases shared per loop."""
    a = np.array([[0.3, 1.0, 3.0], [0.5, 2.0, 8.0]])

    def rhs(theta, z):
        return (np.sin(theta) - z) / a

    phase = np.array([np.linspace(-7.0, 9.0, 41), np.linspace(0.0, 2 * np.pi, 41), np.linspace(2.0, 30.0, 41)])
    z = periodic_steady_state(rhs, np.full((1, 2, 3), 5.0), phase)
    exact = (np.sin(phase) - a[..., None] * np.cos(phase)) / (1 + a[..., None] ** 2)
    assert z.shape == (1, 2, 3, 41)
    np.testing.assert_allclose(z[0], exact, rtol=0, atol=1e-9)


def test_periodic_steady_state_flags_non_finite_elements_and_non_convergence():
    a = np.array([1.0, np.nan, 2.0])

    def lag(theta, z):
        return (np.cos(theta) - z) / a

    z = periodic_steady_state(lag, np.zeros((1, 3)), np.linspace(0, 6, 5))
    assert np.all(np.isnan(z[0, 1])) and np.all(np.isfinite(z[0, [0, 2]]))

    def undamped(theta, z):  # x'' + 2 x = cos(theta): quasi-periodic, never repeats
        return np.stack([z[1], np.cos(theta) - 2.0 * z[0]])

    with pytest.raises(SteadyStateError, match="after 5 cycles"):
        periodic_steady_state(undamped, np.array([[1.0], [0.0]]), np.zeros(3), max_cycles=5)
    with pytest.raises(ValueError, match="shape"):
        periodic_steady_state(lambda theta, z: z[:1], np.zeros((2, 3)), np.zeros(3))
