"""The channel rule of hysid_model/readers/channels.py for a channel given by number in dataset.toml: numbers count
from 1 up to the last channel; one past it is a one-line error naming the key and the channels there are."""

from __future__ import annotations

from pathlib import Path

import pytest

from hysid_model.errors import HysidInputError
from hysid_model.readers.channels import choose
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
