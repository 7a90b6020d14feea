"""A user's own terms (``hysid.term``): their force against independent forms of their laws, every mistake refused
in one line, model strings ``module:attribute``, and a known law recovered through fit, diagnose and campaigns."""

from __future__ import annotations

import json

import numpy as np
import pytest

import hysid
from hysid.cli import main
from hysid_model import waveform
from hysid_model.datasets import load_dataset, write_dataset
from hysid_model.errors import HysidInputError
from hysid_model.kinematics import Kinematics
from hysid_model.model import build_model
from hysid_model.objective import Objective
from hysid_model.params import Parameter
from hysid_model.synth import harmonics, simulate_raw, synth_loops
from hysid_model.terms import ModalState, TermGroup
from hysid_model.user_laws import Cycle, FunctionTerm, RateTerm
from support import GA_SMALL, PSO_SMALL, importable

MODULE = "hysid_test_labterms"
"""The user's module of these tests, written to a temporary directory (what ``myterms.py`` is to a user)."""
SOURCE = '''
"""A lab's own force laws."""
import numpy as np
import hysid


def quadratic_damping(x, v, c2):
    """Fluid damping that grows with the square of the velocity."""
    return c2 * v * np.abs(v)


drag = hysid.term(quadratic_damping, name="drag", units={"c2": "N s^2/m^2"}, bounds={"c2": (0.0, 200.0)})


def dahl_rate(z, x, v, sigma, F_c):
    """Dahl's friction: the force follows the motion with stiffness sigma and saturates at F_c."""
    return sigma * v * (1.0 - z * np.sign(v) / F_c)


dahl = hysid.term(rate=dahl_rate, name="dahl", units={"sigma": "N/m", "F_c": "N"}, bounds={"sigma": (0.0, 1e6), "F_c": (0.1, 20.0)}, strength="sigma")


def polynomial_spring(x, v, s2, s3):
    return s2 * x**2 + s3 * x**3


spring = hysid.term(polynomial_spring, name="spring", units={"s2": "N/m^2", "s3": "N/m^3"}, bounds={"s2": (-1e7, 1e7), "s3": (-1e10, 1e10)})
not_a_term = 3.0
'''
TRUTH = {"xi0": 0.02, "w0": 2 * np.pi * 18.0, "meq": 2.0, "c2": 20.0}
"""The known law: a 2 kg oscillator (18 Hz, 2 % damping) with fluid damping c2 v|v| of up to a few newtons."""
FREQS = np.array([6.0, 11.0, 18.0, 27.0, 40.0])
AMPS = np.array([0.5e-3, 1e-3, 2e-3])
SPEC = f"baseline+{MODULE}:drag"


@pytest.fixture(scope="module")
def labterms(tmp_path_factory):
    """The user's module, importable (its directory on ``sys.path``) for this module's tests."""
    with importable(tmp_path_factory.mktemp("labterms"), MODULE, SOURCE) as module:
        yield module


@pytest.fixture(scope="module")
def loops(labterms, tmp_path_factory):
    """Raw records of the known law (simulated through the user's term), written and read back as a lab's dataset."""
    model = build_model(SPEC)
    f, x0 = np.tile(FREQS, AMPS.size), np.repeat(AMPS, FREQS.size)
    raw = simulate_raw(model, model.from_dict(TRUTH), f, x0, noise_n=0.4, seed=11, sample_rate_hz=4000.0, cycles=6)
    where = write_dataset(tmp_path_factory.mktemp("drag") / "lab", raw, name="lab", meq_kg=TRUTH["meq"])
    return load_dataset(where, n_points=48)


def recovered(params: dict[str, float], stderr: dict[str, float]) -> None:
    """Every parameter of the known law within 3 standard errors of the truth, each error below 5 % of its value."""
    assert set(params) == {"xi0", "w0", "c2"}
    for name, value in params.items():
        assert abs(value - TRUTH[name]) < 3.0 * stderr[name] and stderr[name] < 0.05 * TRUTH[name], (name, value, stderr[name])


def kinematics(distorted: bool) -> Kinematics:
    x0 = np.array([0.8e-3, 1.6e-3])
    xh = np.stack([harmonics(a, {2: 0.1, 3: 0.05j}) for a in x0]) if distorted else None
    return Kinematics(x0=x0, omega=2 * np.pi * np.array([9.0, 23.0]), xh=xh)


def values(**named: float) -> dict[str, np.ndarray]:
    return {k: np.array([[v]]) for k, v in named.items()}


# --- a force law: the law at the samples, less its cycle mean ------------------------------------------------


@pytest.mark.parametrize("distorted", [False, True])
def test_a_force_law_is_the_law_at_the_samples_less_its_cycle_mean(labterms, distorted):
    kin = kinematics(distorted)
    phase = np.broadcast_to(np.linspace(0.0, 2 * np.pi, 37), (2, 37))
    force = labterms.spring.time_force(values(s2=3e5, s3=2e8), ModalState(0, 0, 0), kin, phase)[0]
    fine = np.broadcast_to(np.linspace(0.0, 2 * np.pi, 20000, endpoint=False), (2, 20000))

    def law(theta):  # x from the harmonics themselves, the cycle mean by a fine rectangle rule
        x = kin.x0[:, None] * np.sin(theta) if kin.xh is None else waveform.displacement(kin.xh, theta)
        return 3e5 * x**2 + 2e8 * x**3

    expected = law(phase) - law(fine).mean(axis=1, keepdims=True)
    np.testing.assert_allclose(force, expected, rtol=0, atol=1e-9 * np.abs(expected).max())
    if not distorted:  # under the sine the mean is s2 X0^2 / 2 (x^3 has none)
        x = kin.x0[:, None] * np.sin(phase)
        np.testing.assert_allclose(force, 3e5 * (x**2 - kin.x0[:, None] ** 2 / 2) + 2e8 * x**3, rtol=0, atol=1e-12)


def dry_friction(x, v, F):
    return F * np.sign(v)


@pytest.mark.parametrize("distorted", [False, True])
def test_a_friction_law_takes_its_branch_s_side_at_the_reversals(distorted):
    """At the samples where the motion reverses (x_min and x_max ends both branches, at one phase) a user's law that
    jumps at v = 0 sees its branch's side, + loading and - unloading, as the library's Coulomb friction does
    (its sign feature) and as the extraction's one-sided fits at the reversals do; not the sign of a velocity of
    rounding size, which put + on the unloading sample at x_max (2 F off)."""
    dry = hysid.term(dry_friction, name="dry", units={"F": "N"}, bounds={"F": (0.0, 100.0)})
    kin = kinematics(distorted)
    n = 25
    top, bottom = np.linspace(*kin.extremes, n).T, np.linspace(*kin.extremes, n).T
    phase = waveform.branch_phases(kin.harmonics, top, bottom)
    force = dry.time_force(values(F=30.0), ModalState(0, 0, 0), kin, phase, n)[0]
    branch = np.where(np.arange(2 * n) < n, 30.0, -30.0)
    centred = force - force.mean(axis=1, keepdims=True) - (branch - branch.mean())
    assert np.ptp(centred, axis=1).max() < 1e-9  # the branch's sign at every sample, the reversals' included


def test_velocity_is_the_derivative_of_the_displacement_in_time(labterms):
    kin = kinematics(True)
    theta = np.broadcast_to(np.linspace(0.0, 2 * np.pi, 4000, endpoint=False), (2, 4000))
    drag = labterms.drag.time_force(values(c2=7.0), ModalState(0, 0, 0), kin, theta)[0]
    x = waveform.displacement(kin.xh, theta)
    v = (np.roll(x, -1, axis=1) - np.roll(x, 1, axis=1)) / (2 * (theta[0, 1] - theta[0, 0])) * kin.omega[:, None]
    law = 7.0 * v * np.abs(v)
    np.testing.assert_allclose(drag - drag.mean(axis=1, keepdims=True), law - law.mean(axis=1, keepdims=True), atol=1e-5 * np.abs(law).max())


@pytest.mark.parametrize("term", ["drag", "dahl"])
def test_the_objective_evaluates_a_term_at_fixed_phases_as_the_reference_does(labterms, term):
    """The compiled path (a sampler per term, the delay as a shift of every candidate's phases) against the
    numpy reference, beside a Bouc-Wen spring and a channel delay."""
    data = synth_loops(1.0, 0, 24).subset(np.arange(0, 120, 17))
    model = build_model(f"thesis+bouc_wen+channel_delay+{MODULE}:{term}").fix(meq=0.04)
    assert model.spec == f"thesis+bouc_wen+channel_delay+{MODULE}:{term}"
    rng = np.random.default_rng(4)
    pop = model.bounds[:, 0] + rng.uniform(0.1, 0.6, (5, model.dim)) * (model.bounds[:, 1] - model.bounds[:, 0])
    compiled, reference = Objective(data, model), Objective(data, model, compiled=False)
    assert compiled.sampled is not None and compiled.sampled.compiled
    np.testing.assert_allclose(compiled.predict(pop), reference.predict(pop), rtol=1e-9, atol=1e-9)


# --- a state's rate: the periodic orbit ------------------------------------------------------------------------


@pytest.mark.parametrize("yield_fraction", [0.005, 0.05, 0.5])
def test_dahl_rate_reaches_the_closed_form_orbit_and_bouc_wen_with_r_1(labterms, yield_fraction):
    """On loading dF/dx = sigma (1 - F / F_c): F = F_c - (F_c + F_m) exp(-(x + X0) / z_y), z_y = F_c / sigma, and
    F(X0) = F_m = F_c tanh(X0 / z_y); the library's Bouc-Wen spring with r = 1 (beta = 0) is the same law.
    A yield at 0.5 % of the amplitude is far stiffer than a step: the orbit must still settle."""
    x0, sigma = 1e-3, 4e4
    zy = yield_fraction * x0
    kin = Kinematics(x0=np.array([x0]), omega=np.array([2 * np.pi * 10.0]))
    theta = np.linspace(0.0, 2 * np.pi, 301)[None]
    force = labterms.dahl.time_force(values(sigma=sigma, F_c=sigma * zy), ModalState(0, 0, 0), kin, theta)[0, 0]
    x = x0 * np.sin(theta[0])
    peak = sigma * zy * np.tanh(x0 / zy)
    loading = sigma * zy - (sigma * zy + peak) * np.exp(-(x + x0) / zy)
    orbit = np.where(np.cos(theta[0]) >= 0.0, loading, -(sigma * zy - (sigma * zy + peak) * np.exp(-(x0 - x) / zy)))
    np.testing.assert_allclose(force, orbit, rtol=0, atol=3e-4 * sigma * zy)  # the orbit is odd: no mean
    bouc_wen = build_model("baseline+bouc_wen").fix(meq=1.0)
    spring = bouc_wen.memory_force(bouc_wen.from_dict({"xi0": 0.0, "w0": 1.0, "bw_k": sigma, "bw_zy": zy, "bw_r": 1.0})[None], kin, theta)
    np.testing.assert_allclose(force, spring[0, 0], rtol=0, atol=3e-4 * sigma * zy)


def test_a_state_that_forgets_slowly_is_found_on_its_periodic_orbit(labterms):
    """A Maxwell element, dz/dt = k v - z / tau with w tau = 300: plain integration from rest would need
    thousands of cycles; its periodic orbit is z = Re[k X0 w e^(i wt) / (i w + 1 / tau)] (under x = X0 sin wt)."""
    maxwell = hysid.term(
        rate=lambda z, x, v, k_m, tau: k_m * v - z / tau,
        name="maxwell_probe",
        units={"k_m": "N/m", "tau": "s"},
        bounds={"k_m": (0.0, 1e6), "tau": (1e-3, 10.0)},
        strength="k_m",
    )
    kin = kinematics(False)
    tau = 300.0 / kin.omega[0]
    theta = np.broadcast_to(np.linspace(0.0, 2 * np.pi, 53), (2, 53))
    force = maxwell.time_force(values(k_m=2e5, tau=tau), ModalState(0, 0, 0), kin, theta)[0]
    exact = np.real(2e5 * kin.x0[:, None] * kin.omega[:, None] * np.exp(1j * theta) / (1j * kin.omega[:, None] + 1.0 / tau))
    np.testing.assert_allclose(force, exact, rtol=0, atol=1e-4 * np.abs(exact).max())
    assert "maxwell_probe" in repr(maxwell) and isinstance(maxwell, RateTerm)


def test_the_periodic_solution_is_found_whether_it_attracts_or_repels(labterms):
    """dz/dt = a z + b v: z = Re[b X0 w e^(i wt) / (i w - a)] under x = X0 sin wt, attracting for a < 0 (the
    steady state) and repelling for a > 0 (no steady state; its continuation, smooth across a = 0, is what a
    finite difference at a strength's bound of 0 sees)."""
    linear = hysid.term(
        rate=lambda z, x, v, a, b: a * z + b * v, name="linear_probe", units={"a": "1/s", "b": "N/m"}, bounds={"a": (-10.0, 10.0), "b": (0.0, 1e3)}
    )
    kin = kinematics(False)
    theta = np.broadcast_to(np.linspace(0.0, 2 * np.pi, 41), (2, 41))
    a = np.array([[-5.0], [5.0]])
    force = linear.time_force({"a": a, "b": np.full((2, 1), 1e3)}, ModalState(0, 0, 0), kin, theta)
    w, x0 = kin.omega[None, :, None], kin.x0[None, :, None]
    exact = np.real(1e3 * x0 * w * np.exp(1j * theta[None]) / (1j * w - a[:, :, None]))
    np.testing.assert_allclose(force, exact, rtol=0, atol=1e-4 * np.abs(exact).max())


def test_a_law_without_a_periodic_solution_gives_no_force(labterms):
    """dz/dt = b v + c drifts by c T every cycle from any start: no periodic solution, no force (NaN: an infinite
    fitness), and a term of it is refused when made, naming where (c = 0, the midpoint, has one)."""
    drifting = lambda z, x, v, b, c: b * v + c
    with pytest.raises(HysidInputError, match=r"rate: term 'drifting_probe': rate gives non-finite forces at b=300, c=-0.4 \(no periodic solution"):
        hysid.term(rate=drifting, name="drifting_probe", units={"b": "N/m", "c": "N/s"}, bounds={"b": (0.0, 1e3), "c": (-1.0, 1.0)})
    unchecked = RateTerm(drifting, "drifting", (Parameter("b", "N/m", 0.0, 1e3), Parameter("c", "N/s", -1.0, 1.0)), "", "", ())
    orbit, _ = unchecked.orbit({"b": np.full((2, 1), 1e3), "c": np.array([[0.0], [0.5]])}, Cycle(kinematics(False)))
    assert np.all(np.isfinite(orbit[0])) and np.all(np.isnan(orbit[1]))


# --- every mistake in one line ---------------------------------------------------------------------------------


def law(x, v, c):
    return c * v


BAD = [
    (dict(fn=3.0, name="t", units={}, bounds={}), r"fn: must be a function"),
    (dict(name="t", units={}, bounds={}), r"give a force law fn\(x, v, \*\*params\) or a rate"),
    (dict(fn=law, rate=law, name="t", units={"c": "N s/m"}, bounds={"c": (0, 1)}), r"one of them"),
    (dict(fn=law, name="two words", units={"c": "N s/m"}, bounds={"c": (0, 1)}), r"name='two words': a term's name is a Python identifier"),
    (dict(fn=law, name="coulomb_friction", units={"c": "N s/m"}, bounds={"c": (0, 1)}), r"is the name of a preset or of a library effect"),
    (dict(fn=law, name="t", units={"c": "N s/m"}, bounds={}), r"bounds: give the search bounds \(lower, upper\) of parameter 'c'"),
    (dict(fn=law, name="t", units={}, bounds={"c": (0, 1)}), r"units: give the SI unit of parameter 'c'"),
    (dict(fn=law, name="t", units={"c": "N s/m"}, bounds={"c": 5.0}), r"bounds\['c'\]=5.0: must be a pair of numbers"),
    (dict(fn=law, name="t", units={"c": "N s/m"}, bounds={"c": (1.0, 0.0)}), r"bounds\['c'\]: lower bound 1 must be finite and below the upper bound 0"),
    (dict(fn=law, name="t", units={"c": "N s/m", "d": "1"}, bounds={"c": (0, 1)}), r"units: 'd' is no parameter of term 't' \(its parameters: c\)"),
    (dict(fn=lambda x, v: x, name="t", units={}, bounds={}), r"takes \(x, v, then its parameters by name\)"),
    (dict(fn=lambda x, v, *p: x, name="t", units={}, bounds={}), r"name every parameter as an argument, not \*p"),
    (dict(fn=lambda x, v, F_d: F_d * x, name="t", units={"F_d": "N"}, bounds={"F_d": (0, 1)}), r"'F_d' of term 't' is a parameter of coulomb_friction"),
    (
        dict(fn=lambda x, v, c: np.sum(c * x, axis=-1), name="t", units={"c": "N/m"}, bounds={"c": (0, 1)}),
        r"fn returns shape \(2, 2\), which is not \(2, 2, 24\)",
    ),
    (dict(fn=lambda x, v, c: c * v / x, name="t", units={"c": "N"}, bounds={"c": (0, 1)}), r"fn gives non-finite forces at c=0.5$"),
    (dict(fn=lambda x, v, c: float(c) * x, name="t", units={"c": "N/m"}, bounds={"c": (0, 1)}), r"fn fails on the probe motion at c=0.5 \(TypeError: "),
    (dict(fn=lambda x, v, c: c * x / np.abs(x).max(), name="t", units={"c": "N"}, bounds={"c": (0, 1)}), r"must be vectorized"),
    (
        dict(fn=lambda x, v, c, d: c * x + d, name="t", units={"c": "N/m", "d": "N"}, bounds={"c": (0, 1), "d": (0, 1)}, strength="e"),
        r"strength='e': is no parameter of term 't'",
    ),
    (dict(fn=lambda x, v, c: c * x, name="t", units={"c": "N/m"}, bounds={"c": (1, 2)}, strength="c"), r"its bounds 1:2 must hold 0"),
    (
        dict(fn=lambda x, v, c, d: c * x + d * x**2, name="t", units={"c": "N/m", "d": "N/m^2"}, bounds={"c": (0, 1), "d": (0, 1)}, strength="c"),
        r"at c = 0 its force is not zero",
    ),
    (dict(rate=lambda z, x, v, c: c * np.log(x), name="t", units={"c": "N/s"}, bounds={"c": (0, 1)}), r"rate gives non-finite forces"),
    (dict(rate=lambda z, c: c * z, name="t", units={"c": "1/s"}, bounds={"c": (0, 1)}), r"takes \(z, x, v, then its parameters by name\)"),
]


@pytest.mark.parametrize("kwargs, message", BAD)
def test_every_mistake_in_a_term_is_one_line_naming_it(kwargs, message):
    fn = kwargs.pop("fn", None)
    with pytest.raises(HysidInputError, match=message) as caught:
        hysid.term(fn, **kwargs)
    assert "\n" not in str(caught.value)


# --- terms compose, as PySINDy's libraries -----------------------------------------------------------------------


def test_terms_compose_into_groups_and_models(labterms):
    effects = hysid.effects
    group = effects.coulomb_friction + effects.bouc_wen
    assert isinstance(group, TermGroup) and [t.id for t in group] == ["coulomb_friction", "bouc_wen"]
    assert (hysid.models.thesis + group).spec == "thesis+coulomb_friction+bouc_wen"
    assert (group + hysid.models.thesis).names == (hysid.models.thesis + group).names  # a model string starts with its preset
    assert (effects.coulomb_friction + hysid.models.baseline).spec == "baseline+coulomb_friction"
    three = group + labterms.drag
    assert isinstance(three, TermGroup) and len(three) == 3 and (labterms.drag + group).terms[0] is labterms.drag
    model = hysid.models.baseline + three
    assert model.spec == f"baseline+coulomb_friction+bouc_wen+{MODULE}:drag" and build_model(model.spec).names == model.names
    with pytest.raises(HysidInputError, match="effect 'bouc_wen' is twice in the group"):
        group + effects.bouc_wen
    with pytest.raises(HysidInputError, match="effect 'coulomb_friction' is already in the model"):
        (hysid.models.thesis + effects.coulomb_friction) + group
    assert hysid.models.thesis.spec == "thesis" and isinstance(hysid.effects.bouc_wen, type(effects.bouc_wen))  # nothing changed in place


# --- model strings: module:attribute ---------------------------------------------------------------------------


def test_a_model_string_names_a_users_term_by_module_and_attribute(labterms):
    model = build_model(f"thesis+{MODULE}:drag")
    assert model.names[-1] == "c2" and model.terms[-1] is labterms.drag and model.spec == f"thesis+{MODULE}:drag"
    assert (hysid.models.thesis + labterms.drag).spec == model.spec  # the term knows where it lives
    assert build_model("thesis+drag").spec == model.spec  # in this process also by its name
    local = hysid.term(lambda x, v, c9: c9 * v, name="local_probe", units={"c9": "N s/m"}, bounds={"c9": (0.0, 1.0)})
    assert isinstance(local, FunctionTerm) and (hysid.models.baseline + local).spec == "baseline+local_probe"  # no module holds it
    assert labterms.drag.params[0].physical == (0.0, np.inf) and labterms.spring.params[0].physical == (-np.inf, np.inf)  # a strength's sign


@pytest.mark.parametrize(
    "spec, message",
    [
        ("thesis+no_such_module_xyz:drag", r"'no_such_module_xyz:drag': no module 'no_such_module_xyz' on this Python's path"),
        (f"thesis+{MODULE}:nothing", rf"'{MODULE}:nothing': module '{MODULE}' has no attribute 'nothing'"),
        (f"thesis+{MODULE}:not_a_term", rf"'{MODULE}:not_a_term': is a float, not a term made by hysid.term"),
        ("thesis+a:b:c", r"'a:b:c': a term of your own is named module:attribute"),
        ("thesis+magic_term", r"unknown effect 'magic_term'; known: .*, or a term of your own as module:attribute"),
        (f"thesis+drag+{MODULE}:drag", rf"effect '{MODULE}:drag' is already in the model"),
    ],
)
def test_a_bad_model_string_is_one_line(labterms, spec, message):
    with pytest.raises(HysidInputError, match=message) as caught:
        build_model(spec)
    assert str(caught.value).startswith(f"model={spec!r}: ")


def test_a_module_that_fails_to_import_is_named(tmp_path, monkeypatch):
    (tmp_path / "hysid_test_broken.py").write_text("raise RuntimeError('calibration file missing')\n")
    monkeypatch.syspath_prepend(str(tmp_path))
    with pytest.raises(HysidInputError, match=r"importing module 'hysid_test_broken' failed \(RuntimeError: calibration file missing\)"):
        build_model("baseline+hysid_test_broken:drag")


def test_hysid_models_lists_the_terms_it_imports(labterms, capsys):
    assert main(["models", "--import", MODULE]) == 0
    out = capsys.readouterr().out
    assert f"  {MODULE}:drag: c2 [N s^2/m^2] in [0, 200] (strength c2)\n      Fluid damping that grows with the square of the velocity." in out
    assert f"  {MODULE}:dahl: sigma [N/m] in [0, 1e+06], F_c [N] in [0.1, 20] (strength sigma)" in out
    assert main(["models", "--import", "no_such_module_xyz"]) == 2
    assert capsys.readouterr().err == "hysid: error: --import: no module 'no_such_module_xyz' on this Python's path\n"


def test_a_candidate_needs_a_strength(labterms, capsys):
    assert main(["diagnose", "synth", "--candidates", f"{MODULE}:spring", "--quiet"]) == 2
    err = capsys.readouterr().err
    assert err.startswith(f"hysid: error: --candidates: term '{MODULE}:spring' names no strength") and err.count("\n") == 1


def test_island_processes_need_a_term_they_can_import(loops):
    local = hysid.term(lambda x, v, c8: c8 * v * np.abs(v), name="unimportable_probe", units={"c8": "N s^2/m^2"}, bounds={"c8": (0.0, 200.0)})
    with pytest.raises(HysidInputError, match=r"model: term 'unimportable_probe' is no attribute of an importable module .* or run single_node"):
        hysid.campaign(loops, hysid.models.baseline + local, islands=1)


# --- a known law recovered: fit, diagnose, campaigns -----------------------------------------------------------


def test_fit_recovers_a_known_law_through_the_users_term(loops):
    result = hysid.fit(loops, SPEC, algo="ga", seed=1, options=GA_SMALL)
    assert result.model.spec == SPEC and result.model.fixed == {"meq": TRUTH["meq"]}
    recovered(result.params, result.stderr)


@pytest.mark.slow  # over 3 s: a rate term integrated for every candidate
def test_fit_recovers_dahl_friction_through_a_rate_term(labterms, tmp_path):
    truth = {"xi0": 0.02, "w0": 2 * np.pi * 18.0, "meq": 2.0, "sigma": 2e4, "F_c": 3.0}
    model = build_model(f"baseline+{MODULE}:dahl")
    f, x0 = np.tile(FREQS, AMPS.size), np.repeat(AMPS, FREQS.size)
    raw = simulate_raw(model, model.from_dict(truth), f, x0, noise_n=0.4, seed=11, sample_rate_hz=4000.0, cycles=6)
    data = load_dataset(write_dataset(tmp_path / "dahl", raw, name="dahl", meq_kg=2.0), n_points=48)
    result = hysid.fit(data, model, algo="ga", seed=1, options=GA_SMALL)
    for name, value in result.params.items():
        assert abs(value - truth[name]) < 3.0 * result.stderr[name] and result.stderr[name] < 0.05 * truth[name], name


def test_diagnose_takes_the_users_term_as_a_candidate(labterms, loops):
    diagnosis = hysid.diagnose(loops, candidates=[labterms.drag], cross_validate=False)
    assert [s.effect for s in diagnosis.steps] == [f"{MODULE}:drag"] and diagnosis.status == "adequate"
    recovered(diagnosis.params, diagnosis.stderr)
    assert f"{MODULE}:drag" in diagnosis.summary()


def test_a_single_node_campaign_recovers_the_known_law(loops):
    options = {"ga": GA_SMALL, "pso": PSO_SMALL}
    result = hysid.campaign(loops, SPEC, islands=2, single_node=True, options=options, seed=3)
    assert result.fit.model.spec == SPEC
    recovered(result.params, result.stderr)


@pytest.mark.slow  # island processes and Zenoh
def test_island_processes_import_the_users_module_and_recover_the_law(loops, tmp_path):
    """The module is on this process' path only (not the island processes' working directory, which ``-P``
    keeps off theirs): the launcher hands its directory to the islands, which import it by the model string."""
    options = {"ga": GA_SMALL, "pso": PSO_SMALL}
    result = hysid.campaign(loops, SPEC, islands=2, options=options, seed=3, db=tmp_path / "c.sqlite")
    assert result.fit.model.spec == SPEC and len(result.islands) == 2 and all(i["evaluations"] > 0 for i in result.islands)
    recovered(result.params, result.stderr)
    again = hysid.CampaignResult.from_database(tmp_path / "c.sqlite")  # the stored model string rebuilds the same model
    assert again.fit.model.spec == SPEC and again.params == pytest.approx(result.params)


@pytest.mark.slow  # a diagnosis and its report through the command line
def test_the_command_line_diagnoses_with_candidates_and_fits_a_model_string(labterms, loops, tmp_path, capsys):
    data = tmp_path / "lab"
    write_dataset(data, loops, name="lab")
    assert main(["diagnose", str(data), "--candidates", f"{MODULE}:drag,{MODULE}:dahl", "--out", str(tmp_path / "d"), "--json", "--quiet", "--no-figures"]) == 0
    doc = json.loads(capsys.readouterr().out)
    assert [s["effect"] for s in doc["steps"]] == [f"{MODULE}:drag"]
    assert (tmp_path / "d" / "diagnosis.md").read_text().count(f"{MODULE}:drag") >= 1
    assert main(["fit", str(data), "--model", SPEC, "--algo", "ga", "--out", str(tmp_path / "f"), "--json", "--quiet", "--no-figures"]) == 0
    fit = json.loads(capsys.readouterr().out)
    recovered(fit["params"], fit["stderr"])
