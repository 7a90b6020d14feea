"""Discovery's candidate with memory (issue 33): the Bouc-Wen internal variable of the loops' own history, its
term (the rate of its force) and module, and a hidden law with memory the library cannot draw."""

from __future__ import annotations

import importlib.util
import json
import sys
from pathlib import Path

import numpy as np
import pytest

import hysid
from hysid.bench.discovery import loop_motion, shape_error, shape_phases
from hysid.bench.discovery_cases import LAWS, jenkins, loops_of, truth_model
from hysid.bench.validation import truth_nrmse
from hysid.diagnosis.discovery import propose
from hysid.diagnosis.refits import best_of, data_starts
from hysid.diagnosis.tally import Tally
from hysid.harmonic_fits import initial_fit, make_model, soft_bounds
from hysid_model.discovery.memory import memory_families
from hysid_model.discovery.proposal import Law, expression, function_source, make_term, module_source
from hysid_model.harmonics import HarmonicObjective, Harmonics
from hysid_model.kinematics import Kinematics
from hysid_model.terms import ModalState
from hysid_model.user_laws import RateTerm

AT_REST = ModalState(xi=np.zeros(1), wn=np.zeros(1), m=np.zeros(1))


def sine(samples: int = 200) -> tuple[Kinematics, np.ndarray, np.ndarray, np.ndarray]:
    """Two loops (1 mm at 4 Hz, 4 mm at 17 Hz): their motion, phases and x, v there."""
    kin = Kinematics(x0=np.array([1e-3, 4e-3]), omega=2.0 * np.pi * np.array([4.0, 17.0]))
    phase = np.broadcast_to(np.linspace(0.0, 2.0 * np.pi, samples, endpoint=False), (2, samples))
    return kin, phase, kin.displacement(phase[None])[0], (kin.omega[:, None] * kin.displacement(phase[None], 1))[0]


def integrated(x: np.ndarray, zy: float, n: float, cycles: int = 4, substeps: int = 100) -> np.ndarray:
    """z / z_y of dz/dt = v - |v| |z|^(n-1) z / z_y^n along ``x`` (one cycle per row, repeated ``cycles`` times), by
    explicit midpoint steps in the travel with ``substeps`` substeps per sample: the last cycle."""
    out = np.empty_like(x)
    for row, path in enumerate(x):
        z = 0.0
        ahead = np.roll(path, -1)
        for _ in range(cycles):
            for j in range(path.size):
                out[row, j] = z / zy
                dx = (ahead[j] - path[j]) / substeps
                for _ in range(substeps):
                    half = z + 0.5 * (dx - abs(dx) * abs(z / zy) ** n * np.sign(z))
                    z += dx - abs(dx) * abs(half / zy) ** n * np.sign(half)
    return out


@pytest.mark.parametrize(("zy", "n"), [(4e-4, 1.0), (1.2e-3, 2.0), (2e-4, 6.0)])
def test_the_memory_family_is_the_bouc_wen_orbit_and_its_term_integrates_to_it(zy: float, n: float) -> None:
    kin, phase, x, v = sine()
    (family,) = memory_families(4e-3, *kin.extremes)
    u = family.evaluate(x, v, {"zy": zy, "n": n})
    assert np.abs(u).max() < 1.0 + 1e-9
    assert np.allclose(u, integrated(x, zy, n), atol=2e-3)  # the steady orbit, however the state started
    law = Law([family], [{"zy": zy, "n": n}], [30.0], 1000.0)
    made = make_term(law, 90)
    values = {"t90_c": np.array([[30.0]]), "t90_zy": np.array([[zy]]), "t90_n": np.array([[n]])}
    assert np.allclose(made.time_force(values, AT_REST, kin, phase)[0], 30.0 * (u - u.mean(axis=-1, keepdims=True)), rtol=0, atol=1e-9)
    force = RateTerm.time_force(made, values, AT_REST, kin, phase)[0]  # the module's: its rate integrated
    difference = force - 30.0 * (u - u.mean(axis=-1, keepdims=True))  # the rate term's 256 steps a cycle against the exact orbit
    assert np.abs(difference).max() < 0.02 * 30.0 and np.sqrt(np.mean(difference**2)) < 0.003 * 30.0
    rate = expression(law, 90, {"t90_c": 30.0, "t90_zy": zy, "t90_n": n})
    assert "z / 30" in rate and "np.abs(v)" in rate and "dF/dt" in expression(law, 90, plain=True)


def test_the_written_module_defines_the_memory_term_as_a_rate(tmp_path: Path) -> None:
    kin, phase, x, v = sine(64)
    (family,) = memory_families(4e-3, *kin.extremes)
    law = Law([family], [{"zy": 3e-4, "n": 3.0}], [25.0], 1000.0, fixed=[{"n": 3.0}])
    source = module_source([(law, 91, "t91_c = 25, t91_zy = 0.0003")], "test loops")
    assert "def term_91_rate(z, x, v, t91_c, t91_zy):" in source and "hysid.term(rate=term_91_rate" in source
    assert "term_91.params = with_physical(term_91.params, " in source  # a fit widens z_y and n only where the rate is defined
    (tmp_path / "proposed_memory.py").write_text(source)
    spec = importlib.util.spec_from_file_location("proposed_memory", tmp_path / "proposed_memory.py")
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    sys.modules["proposed_memory"] = module
    spec.loader.exec_module(module)
    values = {"t91_c": np.array([[25.0]]), "t91_zy": np.array([[3e-4]])}
    assert [p.physical for p in module.term_91.params][1] == (0.0, np.inf)
    written = module.term_91.time_force(values, AT_REST, kin, phase)[0]
    fitted = make_term(law, 91)  # the diagnosis' term: the same rate, its orbit from the compiled solver
    assert function_source(law, 91) in source
    assert [(p.name, p.unit, p.lower, p.upper) for p in fitted.params] == [(p.name, p.unit, p.lower, p.upper) for p in module.term_91.params]
    u = family.evaluate(x, v, {"zy": 3e-4, "n": 3.0})
    assert np.allclose(fitted.time_force(values, AT_REST, kin, phase)[0], 25.0 * (u - u.mean(axis=-1, keepdims=True)), rtol=0, atol=1e-9)
    assert np.allclose(written, 25.0 * (u - u.mean(axis=-1, keepdims=True)), atol=0.25)  # the rate integrated: within 1 % of c
    off = module.term_91.time_force({"t91_c": np.zeros((1, 1)), "t91_zy": np.array([[3e-4]])}, AT_REST, kin, phase)
    assert np.all(off == 0.0)


def test_a_jenkins_element_is_on_its_steady_orbit() -> None:
    x = 2e-3 * np.sin(np.linspace(0.0, 2.0 * np.pi, 400, endpoint=False))
    v = np.cos(np.linspace(0.0, 2.0 * np.pi, 400, endpoint=False))
    slips = jenkins(x, v, 1e5, 40.0)  # slips after 0.8 mm of travel
    assert slips.max() == pytest.approx(40.0) and slips.min() == pytest.approx(-40.0)
    assert jenkins(x, v, 1e4, 40.0) == pytest.approx(1e4 * x)  # never slips: a spring


@pytest.mark.slow
def test_beside_a_bouc_wen_spring_for_one_slider_discovery_proposes_the_other_as_a_memory_term() -> None:
    """Two Jenkins sliders (20 N after 0.2 mm, 60 N after 3 mm): from the library's Bouc-Wen spring fitted (one slider,
    its exponent free), discovery proposes the other as the Bouc-Wen state, sharp-kneed, and the loops reach the noise."""
    harmonics = Harmonics.from_loops(loops_of("two_slider", 1.0, 0))
    start = initial_fit(harmonics, "baseline")
    model = make_model(harmonics, "baseline", ("bouc_wen",), soft_bounds(start.model)).vary("bw_n")
    rows = [model.from_dict({**start.params(), "bw_n": 1.0, **p}) for p in data_starts("bouc_wen", harmonics, model.names)]
    library = best_of(HarmonicObjective(harmonics, model), "baseline", ("bouc_wen",), np.clip(np.array(rows), model.bounds[:, 0], model.bounds[:, 1]))
    assert library.whitened_rms > 3.0  # one Bouc-Wen spring does not draw two sliders
    found, why = propose(library, harmonics, soft_bounds(library.model), False, Tally())
    assert found is not None, why
    assert [f.key for f in found.law.families] == ["bouc_wen_state"] and found.law.memory
    truth = LAWS["two_slider"].truth
    slip, stiffness = truth["hts_fr"] * truth["hts_f"], truth["hts_kr"] * truth["hts_k"]
    params, n = found.params(), found.number
    assert params[f"t{n}_c"] == pytest.approx(slip, rel=0.1)
    assert params[f"t{n}_zy"] == pytest.approx(slip / stiffness, rel=0.1)
    assert params[f"t{n}_n"] >= 4.0  # a sharp knee: a slider, not Dahl's friction
    assert found.fit.whitened_rms < 1.2
    loops = harmonics.loops
    kin = Kinematics(x0=np.asarray(loops.x0, dtype=float), omega=2.0 * np.pi * np.asarray(loops.freq_hz, dtype=float))
    phase = shape_phases(kin.x0.size)
    x, v = loop_motion(loops.freq_hz, loops.x0)
    assert shape_error(jenkins(x, v, stiffness, slip), found.term_force(kin, phase), x, v) < 0.1
    entry = json.loads(json.dumps(found.as_dict()))
    assert entry["memory"] is True and "z / " in entry["formula"] and entry["notation"].startswith("dF/dt = ")


@pytest.mark.slow
def test_two_sliders_end_to_end_get_the_librarys_bouc_wen_and_the_other_slider_proposed_as_a_memory_term() -> None:
    """Two Jenkins sliders, end to end: the library's Bouc-Wen spring draws one slider and is its own shape (rule 9 with
    the step's other contenders projected out); the library effects that would stand in for the other slider beside it (a
    loss factor, a cubic spring: named before rule 9 judged the library search) are refused by their shape, and
    discovery, from the Bouc-Wen model, proposes the other slider as the Bouc-Wen state (its slip force and yield
    displacement within 10 %); nothing else is named and the loops come within 1.5 times the truth's floor."""
    loops = loops_of("two_slider", 1.0, 0)
    diagnosis = hysid.diagnose(loops, "baseline")
    assert [s.effect for s in diagnosis.steps] == ["bouc_wen"], diagnosis.discovery
    assert all(why.startswith("is not the shape of what is left") for why in diagnosis.rejected.values()), diagnosis.rejected
    (found,) = diagnosis.proposed
    assert found.law.memory and found.base is diagnosis.steps[0].after and diagnosis.final is found.fit
    truth = LAWS["two_slider"].truth
    slip, stiffness = truth["hts_fr"] * truth["hts_f"], truth["hts_kr"] * truth["hts_k"]
    assert found.params()[f"t{found.number}_c"] == pytest.approx(slip, rel=0.1)
    assert found.params()[f"t{found.number}_zy"] == pytest.approx(slip / stiffness, rel=0.1)
    assert len(diagnosis.gap) == len(diagnosis.fits()) == 3  # start, + bouc_wen, + the proposed term
    _, values, spec = truth_model("two_slider")
    assert diagnosis.gap[-1].nrmse_pct < 1.5 * truth_nrmse(loops, (spec, values, "measured"))
