"""The channel rule of hysid_model/readers/channels.py for a channel given by number in dataset.toml: numbers count
from 1 up to the last channel; one past it is a one-line error naming the key and the channels there are."""

from __future__ import annotations

from pathlib import Path

import pytest

from hysid_model.errors import HysidInputError, HysidWarning
from hysid_model.readers.channels import Channel, choose
from hysid_model.readers.dataset_dir import DatasetConfig

NAMES = ["Zeit [s]", "Weg [mm]", "Kraft [kN]"]


def numbered(**channels: int) -> DatasetConfig:
    return DatasetConfig(Path("."), "rig", **{f"{q}_channel": n for q, n in channels.items()})


def test_a_channel_number_counts_from_one_up_to_the_last_channel():
    """Channel 1 is the first column, channel 3 (the last of three) the last, each with the unit its name states."""
    assert choose(NAMES, "time", numbered(time=1), "r.csv").index == 0
    last = choose(NAMES, "force", numbered(force=3), "r.csv")
    assert (last.index, last.name, last.unit, last.factor) == (2, "Kraft [kN]", "kN", 1e3)


@pytest.mark.parametrize("number", [4, 5, 100])
def test_a_channel_number_past_the_last_is_a_one_line_error_naming_the_key(number):
    with pytest.raises(HysidInputError) as info:
        choose(NAMES, "force", numbered(force=number), "r.csv")
    message = str(info.value)
    assert message.startswith(f"r.csv: force_channel = {number} but there are 3 channels") and "\n" not in message


def named(**channels: str) -> DatasetConfig:
    return DatasetConfig(Path("."), "rig", **{f"{q}_channel": n for q, n in channels.items()})


def test_a_channel_given_by_name_matches_in_any_case_or_without_its_group():
    assert choose(["Time", "DISP", "Force_N"], "force", named(force="force_n"), "r.csv") == Channel(2, "Force_N", "N", 1.0)
    with pytest.warns(HysidWarning, match=r"channel 'g/Weg' states no unit"):
        assert choose(["g/Time", "g/Weg", "g/Kraft"], "displacement", named(displacement="weg"), "r.tdms").index == 1


@pytest.mark.parametrize(("names", "what"), [(["a", "b"], "no channel"), (["kraft", "Kraft"], "2 channels")])
def test_a_channel_name_that_matches_none_or_several_is_a_one_line_error(names, what):
    listing = ", ".join(repr(n) for n in names)
    with pytest.raises(HysidInputError, match=f"^r.csv: {what} named 'kraft' \\(force_channel in dataset.toml\\); channels: {listing}$"):
        choose(names, "force", named(force="kraft"), "r.csv")


def test_without_a_name_given_the_default_then_the_stated_unit_then_a_label_decide():
    assert choose(["time_s", "x", "force_n"], "force", None, "r.csv") == Channel(2, "force_n", "N", 1.0)
    assert choose(["time", "displacement", "force"], "force", None, "r.tdms", file_units=[None, "mm", "kN"]) == Channel(2, "force", "kN", 1e3)
    assert choose(["time_s", "displacement_mm", "force_n"], "displacement", None, "r.csv") == Channel(1, "displacement_mm", "mm", 1e-3)
    assert choose(["t [ms]", "Weg", "Load (kN)"], "force", None, "r.csv") == Channel(2, "Load (kN)", "kN", 1e3)
    assert choose(["t [ms]", "Weg", "Load (kN)"], "time", None, "r.csv") == Channel(0, "t [ms]", "ms", 1e-3)


def test_no_channel_or_several_of_a_quantity_is_a_one_line_error_unless_it_may_be_absent():
    assert choose(["time_s", "x"], "force", None, "r.csv", required=False) is None
    with pytest.raises(HysidInputError, match=r"^r.csv: 2 force channels \('Load \(kN\)', 'F \[N\]'\); name one with force_channel in dataset.toml$"):
        choose(["time_s", "Load (kN)", "F [N]"], "force", None, "r.csv")
    with pytest.raises(
        HysidInputError,
        match=r"^r.csv: no force channel: expected 'force_n' \(any case\), a name like 'force_<unit>' or "
        r"'Force \[unit\]', or force_channel in dataset.toml; channels: 'time_s', 'x'$",
    ):
        choose(["time_s", "x"], "force", None, "r.csv")
    with pytest.raises(HysidInputError, match=r"channels: none$"):
        choose([], "force", None, "r.csv")


def test_each_rule_wins_over_the_looser_ones_after_it():
    """The default name over another name with a unit; a bare name whose unit the file states, or a name with the
    quantity and its unit, over a bare synonym; a bare synonym is taken where nothing else is (its unit SI, warned)."""
    assert choose(["force_n", "force_kn"], "force", None, "r.csv").index == 0
    assert choose(["force", "load"], "force", None, "r.tdms", file_units=["kN", None]) == Channel(0, "force", "kN", 1e3)
    assert choose(["displacement_mm", "x"], "displacement", None, "r.csv").index == 0
    assert choose(["Messung/Gruppe/Weg [mm]", "Messung/Gruppe/Kraft"], "displacement", named(displacement="weg [mm]"), "r.tdms").index == 0
    with pytest.warns(HysidWarning, match=r"channel 'f' states no unit: read as N"):
        assert choose(["t", "x", "f"], "force", None, "r.csv") == Channel(2, "f", "N", 1.0)
    with pytest.warns(HysidWarning, match=r"channel 'force' states no unit"):
        assert choose(["time", "displacement", "force"], "force", None, "r.csv").index == 2


def test_the_unit_declared_in_dataset_toml_comes_first_and_a_disagreeing_one_is_an_error():
    config = DatasetConfig(Path("."), "rig", force_unit="kN")
    assert choose(["time_s", "x", "force"], "force", config, "r.csv") == Channel(2, "force", "kN", 1e3)
    with pytest.raises(HysidInputError, match=r"^r.tdms: channel 'force_kn' states the unit 'N' but its name says kN; set force_unit in dataset.toml$"):
        choose(["time", "force_kn"], "force", None, "r.tdms", file_units=[None, "N"])
