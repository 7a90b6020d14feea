"""Data slips named where the result is read (hysid_model/slips.py, hysid_model/notices.py): records as a German lab
writes them (';' and decimal commas, 'Zeit [s];Weg [mm];Kraft [kN]') with columns swapped, metres under a millimetre
header (every value below 1) and the reverse, kilonewtons under a newton header with the mass given; each named with
its code and the dataset.toml lines that fix it, and those lines tested; the warnings carried into result.json,
report.md, diagnosis.json and a campaign's database."""

from __future__ import annotations

import json
import re
import warnings
from pathlib import Path
from typing import ClassVar

import numpy as np
import pytest

import hysid
from hysid.cli import main
from hysid_model.datasets import load_dataset, write_dataset
from hysid_model.errors import HysidWarning
from hysid_model.model import build_model
from hysid_model.notices import CODES, MAX_MESSAGE, keeps_warnings, merged, recorded
from hysid_model.synth import RawRecord, simulate_raw
from support import sizes

LAB = ("Zeit [s]", "Weg [mm]", "Kraft [kN]")
UNIT_CODES = {"unit_slip", "unit_slip_displacement", "unit_slip_force", "mass_contradicted"}
TINY = dict(initial_population=60, population=20, iterations=3)
THOUSAND = r"(99\d|100\d)(\.\d)?"
"""A factor of 1000 as the warnings write it (999.4, 1001)."""


@pytest.fixture(scope="module")
def bearing() -> list[RawRecord]:
    """An elastomeric bearing: Bouc-Wen (n = 2) on a 200 kg mass resonating at 10 Hz, 8-12 Hz at 3 and 12 mm, the
    displacement sensor adding a 1 % second harmonic (not the motion)."""
    model = build_model("mr_damper").with_bounds({"w0": (10, 500), "meq": (1, 1000)})
    truth = model.from_dict(dict(xi0=0.05, w0=63.246, meq=200.0, bw_k=2.5e6, bw_zy=2e-3, bw_r=0.5, bw_n=2.0))
    f, x0 = np.array([8.0, 10.0, 12.0] * 2), np.repeat([3e-3, 12e-3], 3)
    return simulate_raw(model, truth, f, x0, noise_n=0.005 * 3e6 * x0, seed=0, sample_rate_hz=1500.0, cycles=5, sensor={2: 0.01})


def lab_files(
    directory: Path,
    records: list[RawRecord],
    header: tuple[str, str, str] = LAB,
    x_scale: float = 1e3,
    f_scale: float = 1e-3,
    swap: bool = False,
    toml: str = "",
) -> Path:
    """One German CSV per record (';', decimal commas): time, then x * x_scale and F * f_scale under ``header``, or
    (``swap``) the force's numbers in the displacement's column and the displacement's in the force's."""
    directory.mkdir(parents=True)
    manifest = ["file,frequency_hz"]
    for r in records:
        x, force = r.x * x_scale, r.force * f_scale
        columns = (r.t, force, x) if swap else (r.t, x, force)
        rows = [";".join(header)] + [";".join(f"{v:.7g}" for v in row).replace(".", ",") for row in zip(*columns)]
        (directory / f"{r.label}.csv").write_text("\n".join(rows) + "\n", encoding="utf-8")
        manifest.append(f"{r.label}.csv,{r.freq_hz}")
    (directory / "manifest.csv").write_text("\n".join(manifest) + "\n")
    if toml:
        (directory / "dataset.toml").write_text(toml)
    return directory


def loaded(directory: Path):
    """The loops and the warnings their loading kept (code -> message)."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", HysidWarning)
        loops = load_dataset(directory)
    return loops, {w["code"]: w["message"] for w in loops.meta["warnings"]}


def test_swapped_columns_of_a_german_lab_csv_are_named_with_the_lines_that_read_them_right(tmp_path, bearing):
    """Both columns look plausible (4-10 'mm', 2-12 'kN'): the loops generate energy and the 'displacement' carries
    the Bouc-Wen force's harmonics. The lines the warning gives, pasted into dataset.toml, read the right loops."""
    right, _ = loaded(lab_files(tmp_path / "right", bearing))
    _loops, found = loaded(lab_files(tmp_path / "swapped", bearing, swap=True))
    assert "swapped_columns" in found and not UNIT_CODES & set(found)
    fix = 'displacement_channel = "Kraft [kN]", displacement_unit = "mm", force_channel = "Weg [mm]" and force_unit = "kN" in dataset.toml'
    assert "the loops generate energy" in found["swapped_columns"] and fix in found["swapped_columns"]
    lines = re.search(r"set (.*) in dataset.toml", found["swapped_columns"]).group(1).replace(" and ", ", ").split(", ")
    fixed, found = loaded(lab_files(tmp_path / "fixed", bearing, swap=True, toml="\n".join(lines) + "\n"))
    assert not {"swapped_columns", "sign_reversed", "energy_generated", "no_unit"} & set(found)
    np.testing.assert_allclose(fixed.x0, right.x0, rtol=1e-6)
    np.testing.assert_allclose(fixed.top, right.top, rtol=1e-5, atol=1e-6 * np.abs(right.top).max())


def test_metres_under_a_millimetre_header_every_value_below_one_are_named_from_the_inertia(tmp_path, bearing):
    """Data in m under 'Weg [mm]' (0.003-0.012): a plausible motion of 3-12 um, but 200 t of inertia with no mass
    given, 1000 times the mass given; displacement_unit = "m" sets it right."""
    _, found = loaded(lab_files(tmp_path / "nomass", bearing, x_scale=1.0))
    assert set(found) & UNIT_CODES == {"unit_slip"}
    assert 'the displacement in m under its mm header (displacement_unit = "m")' in found["unit_slip"]
    assert re.search(r"inertia, 2(\.\d+)?e\+05 \+- .* making the inertia (199|20\d) kg", found["unit_slip"])
    _, found = loaded(lab_files(tmp_path / "mass", bearing, x_scale=1.0, toml="meq_kg = 200\n"))
    assert re.search(rf"is {THOUSAND} times the given mass meq_kg = 200 kg: a unit slip\? the displacement in m under its mm header", found["unit_slip"])
    _, found = loaded(lab_files(tmp_path / "fixed", bearing, x_scale=1.0, toml='meq_kg = 200\ndisplacement_unit = "m"\n'))
    assert not UNIT_CODES & set(found)


def test_millimetres_under_a_metre_header_every_value_below_one_on_a_soft_isolator(tmp_path):
    """0.3-0.6 mm written under 'Weg [m]' at 0.3-0.5 Hz: 0.6 'm' move at 1.9 m/s, within a rig's limits, so only the
    force (0.14 N/m of stiffness) and the inertia tell: with no mass the force or the displacement is named, with the
    mass given (50 kg, 1000 times the inertia shown) the displacement, the force or a mass in grams."""
    model = build_model("baseline").with_bounds({"w0": (0.1, 500), "meq": (1, 1000)})
    truth = model.from_dict(dict(xi0=0.05, w0=2 * np.pi * 0.4, meq=50.0))
    records = simulate_raw(model, truth, np.array([0.3, 0.4, 0.5] * 2), np.repeat([0.3e-3, 0.6e-3], 3), noise_n=0.002, seed=1, sample_rate_hz=200.0, cycles=6)
    metre = ("Zeit [s]", "Weg [m]", "Kraft [N]")
    _, found = loaded(lab_files(tmp_path / "right", records, header=("Zeit [s]", "Weg [mm]", "Kraft [N]"), f_scale=1.0, toml="meq_kg = 50\n"))
    assert found == {}
    _, found = loaded(lab_files(tmp_path / "nomass", records, header=metre, f_scale=1.0))
    assert set(found) & UNIT_CODES == {"unit_slip"} and "moves as no rig does" not in found["unit_slip"]
    assert ('the force in kN under its N header (force_unit = "kN") or the displacement in mm under its m header (displacement_unit = "mm")') in found[
        "unit_slip"
    ]
    _, found = loaded(lab_files(tmp_path / "mass", records, header=metre, f_scale=1.0, toml="meq_kg = 50\n"))
    assert re.search(
        rf"is 1/{THOUSAND} of the given mass meq_kg = 50 kg: a unit slip\? the displacement in mm under its m header "
        r'\(displacement_unit = "mm"\), the force in kN under its N header \(force_unit = "kN"\) or meq_kg in g '
        r"\(meq_kg = 0\.05\)",
        found["unit_slip"],
    )


def test_kilonewtons_under_a_newton_header_are_named_where_a_mass_is_given(tmp_path, bearing):
    """kN under 'Kraft [N]': silent where the mass is unknown (a 0.2 kg specimen ten times softer is as plausible),
    named against a given 200 kg; force_unit = "kN" sets it right. A mass written in grams is named too, and a given
    mass the loops show no trace of is contradicted."""
    newton = ("Zeit [s]", "Weg [mm]", "Kraft [N]")
    _, found = loaded(lab_files(tmp_path / "nomass", bearing, header=newton))
    assert not UNIT_CODES & set(found)
    _, found = loaded(lab_files(tmp_path / "mass", bearing, header=newton, toml="meq_kg = 200\n"))
    assert 'the force in kN under its N header (force_unit = "kN")' in found["unit_slip"]
    _, found = loaded(lab_files(tmp_path / "fixed", bearing, header=newton, toml='meq_kg = 200\nforce_unit = "kN"\n'))
    assert not UNIT_CODES & set(found)
    _, found = loaded(lab_files(tmp_path / "grams", bearing, toml="meq_kg = 200000\n"))
    assert "meq_kg in g (meq_kg = 200)" in found["unit_slip"]
    t = np.arange(3000) / 1500.0
    springs = [
        RawRecord(f"r{k}", f, 2e-3, t, 2e-3 * np.sin(2 * np.pi * f * t), 4e3 * np.sin(2 * np.pi * f * t + 0.2), 0.0) for k, f in enumerate((8.0, 10.0, 12.0))
    ]
    _, found = loaded(lab_files(tmp_path / "nomotion", springs, toml="meq_kg = 200\n"))
    assert set(found) == {"mass_contradicted"} and "contradicts the given mass meq_kg = 200 kg" in found["mass_contradicted"]


def test_kilonewtons_under_a_newton_header_in_a_resonance_dwell_are_named_from_the_given_mass(tmp_path):
    """One frequency, so no inertia to read off the loops: a 0.5 kg, 2 % damped specimen dwelt at its 30 Hz resonance
    pushes back with 4 % of its mass's inertia force m w^2 X0; in kN under 'Kraft [N]' with 0.004 %, as no specimen
    would (a resonance damped below 5e-5)."""
    model = build_model("baseline").with_bounds({"w0": (1, 500), "meq": (0.01, 10)})
    truth = model.from_dict(dict(xi0=0.02, w0=2 * np.pi * 30.0, meq=0.5))
    records = simulate_raw(model, truth, np.full(3, 30.0), np.array([0.2e-3, 0.5e-3, 1e-3]), noise_n=0.005, seed=2, sample_rate_hz=3000.0, cycles=8)
    _, found = loaded(lab_files(tmp_path / "right", records, header=("Zeit [s]", "Weg [mm]", "Kraft [N]"), f_scale=1.0, toml="meq_kg = 0.5\n"))
    assert found == {}
    _, found = loaded(lab_files(tmp_path / "kn", records, header=("Zeit [s]", "Weg [mm]", "Kraft [N]"), toml="meq_kg = 0.5\n"))
    assert "of the inertia force m w^2 X0 of the given mass meq_kg = 0.5 kg in every loop" in found["unit_slip"]
    assert 'the force in kN under its N header (force_unit = "kN")' in found["unit_slip"]


def test_warnings_are_kept_whatever_the_filters_and_said_again():
    """A result keeps every HysidWarning its work raised, also under an 'ignore' filter, and the warning still reaches
    Python's own handling (the command line prints it from there)."""

    class Result:
        raised: ClassVar[list] = []

    @keeps_warnings
    def work() -> Result:
        warnings.warn(HysidWarning("a channel states no unit", "no_unit"), stacklevel=1)
        warnings.warn(HysidWarning("a channel states no unit", "no_unit"), stacklevel=1)
        return Result()

    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        assert work().raised == [{"code": "no_unit", "message": "a channel states no unit"}]
    assert [str(w.message) for w in caught] == ["a channel states no unit"] * 2
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        assert work().raised == [{"code": "no_unit", "message": "a channel states no unit"}]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        with pytest.raises(ValueError), recorded() as kept:
            warnings.warn(HysidWarning("said before the error", "drift"), stacklevel=1)
            raise ValueError
    assert [n.code for n in kept] == ["drift"]
    left_out = merged([{"code": "records_left_out", "message": "d: left out " + ", ".join(f"run{k}.csv" for k in range(2000))}])
    assert len(left_out[0]["message"]) == MAX_MESSAGE  # a campaign's configuration takes no string beyond 10,000


def test_load_warnings_travel_into_a_fit_and_a_diagnosis(tmp_path, bearing):
    """The swapped lab files: the fit and the diagnosis list the loading's warnings with their codes (first), then
    their own; the notebook views show them above the numbers."""
    loops, _ = loaded(lab_files(tmp_path / "swapped", bearing, swap=True))
    fit = hysid.fit(loops, "baseline", options=TINY)
    codes, loading = [w["code"] for w in fit.to_dict()["warnings"]], [w["code"] for w in loops.meta["warnings"]]
    assert codes[: len(loading)] == loading and "swapped_columns" in loading and "misfit" in codes and set(codes) <= set(CODES)
    view = fit._repr_markdown_()
    assert view.index("## Warnings") < view.index("| parameter") and "**`swapped_columns`**" in view
    diagnosis = hysid.diagnose(loops, "baseline", max_steps=0, cross_validate=False, discover=False)  # the warnings, not discovery
    assert [w["code"] for w in diagnosis.to_dict()["warnings"]][: len(loading)] == loading
    assert "## Warnings" in diagnosis._repr_markdown_()


def test_load_warnings_travel_into_a_campaign_and_its_database(tmp_path, bearing):
    """A single-node campaign lists them, and so does its result rebuilt from the database alone (the coordinator
    stored the loop set with them)."""
    loops, _ = loaded(lab_files(tmp_path / "swapped", bearing, swap=True))
    db = tmp_path / "c.sqlite"
    run = hysid.campaign(loops, "baseline", islands=2, single_node=True, options={"ga": TINY, "pso": TINY}, db=db)
    swapped = [w for w in run.to_dict()["warnings"] if w["code"] == "swapped_columns"]
    assert swapped == [w for w in loops.meta["warnings"] if w["code"] == "swapped_columns"]
    assert [w for w in hysid.CampaignResult.from_database(db).warnings if w["code"] == "swapped_columns"] == swapped


def test_a_loops_file_keeps_the_warnings_for_the_fits_that_read_it(tmp_path, bearing):
    """The loops.csv that `hysid loops --out` writes holds them; loading it says them again and keeps them."""
    write_dataset(tmp_path / "loops", loaded(lab_files(tmp_path / "swapped", bearing, swap=True))[0])
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        loops = load_dataset(tmp_path / "loops")
    said = [w.message for w in caught if isinstance(w.message, HysidWarning)]
    assert "swapped_columns" in [w.code for w in said] and "swapped_columns" in [w["code"] for w in loops.meta["warnings"]]


@pytest.mark.slow
def test_fit_diagnose_campaign_and_report_write_the_warnings_near_the_top(tmp_path, bearing, capsys):
    """The command line on the lab files with m under a mm header and the mass given: report.md, diagnosis.md and the
    campaign's report (also rebuilt from its database by hysid report) open with a Warnings section naming the unit
    slip, result.json and diagnosis.json list it with its code, and stderr says it once per command. The reports are
    written without their figures (--no-figures: none drawn, each report says so where they would be)."""
    data = str(lab_files(tmp_path / "metres", [bearing[k] for k in (0, 2, 3, 5)], x_scale=1.0, toml="meq_kg = 200\n"))
    small = ["--points", "30", "--quiet", "--no-figures"]
    runs = {
        "fit": (["fit", data, "--model", "baseline", *small, "--out", str(tmp_path / "fit")], "report.md", "result.json"),
        "diagnose": (  # from the bearing's own model: the warnings, not the search (one step)
            ["diagnose", data, "--model", "mr_damper", *small, "--out", str(tmp_path / "diagnose")],
            "diagnosis.md",
            "diagnosis.json",
        ),
        "campaign": (
            [
                "campaign",
                data,
                "--model",
                "baseline",
                "--single-node",
                "--islands",
                "2",
                *sizes(20, 40, 5),
                *small,
                "--out",
                str(tmp_path / "campaign"),
            ],
            "report.md",
            "result.json",
        ),
        "report": (["report", str(tmp_path / "campaign" / "campaign.sqlite"), "--no-figures", "--out", str(tmp_path / "report")], "report.md", "result.json"),
    }
    for name, (argv, markdown, document) in runs.items():
        assert main(argv) == 0, name
        err = capsys.readouterr().err
        assert len(re.findall(f"is {THOUSAND} times", err)) == (0 if name == "report" else 1), (name, err)
        text = (tmp_path / name / markdown).read_text()
        assert not list((tmp_path / name).glob("*.png")) and ": not drawn, the report was asked for without figures" in text, name
        assert "## Warnings" in text and text.index("## Warnings") < text.index("\n## ", text.index("## Warnings") + 1), name
        assert re.search(rf"- \*\*`unit_slip`\*\*: .*metres: the loops' inertia, .* is {THOUSAND} times the given mass", text), name
        codes = [w["code"] for w in json.loads((tmp_path / name / document).read_text())["warnings"]]
        assert codes[0] == "unit_slip" and set(codes) <= set(CODES), name
    assert main(["loops", data, "--points", "30", "--out", str(tmp_path / "loops")]) == 0
    assert [w["code"] for w in json.loads((tmp_path / "loops" / "loops.json").read_text())["warnings"]] == ["unit_slip"]
