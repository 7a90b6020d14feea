"""The owner-only rule of island/secret.py: a campaign secret's file that its group or anyone else may read, write
or run is named in a warning (and still read); a file of mode 0600 is read without one."""

from __future__ import annotations

import warnings

import pytest

from hysid_model.errors import HysidWarning
from island.secret import CampaignSecret


def read_with_warnings(path) -> tuple[CampaignSecret, list[str]]:
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        secret = CampaignSecret.read(path)
    return secret, [str(w.message) for w in caught if isinstance(w.message, HysidWarning)]


@pytest.mark.parametrize("mode", [0o640, 0o620, 0o610, 0o604, 0o602, 0o601, 0o644])
def test_a_secret_file_others_than_its_owner_may_use_is_warned_about(tmp_path, mode):
    secret = CampaignSecret.create("c1", bytes(32))
    path = secret.write(tmp_path / "c.secret")
    path.chmod(mode)
    read, warned = read_with_warnings(path)
    assert read == secret and len(warned) == 1 and "readable by others than its owner (chmod 600" in warned[0]


@pytest.mark.parametrize("mode", [0o600, 0o400])
def test_an_owner_only_secret_file_is_read_without_a_warning(tmp_path, mode):
    secret = CampaignSecret.create("c1", bytes(32))
    path = secret.write(tmp_path / "c.secret")
    path.chmod(mode)
    assert read_with_warnings(path) == (secret, [])
