"""The owner-only rules of island/secret.py: a campaign secret's file that its group or anyone else may read, write
or run is named in a warning (and still read); a file of mode 0600 is read without one; such a file is written at
mode 0600 from the start and replaced whole; one that cannot be read is a one-line error."""

from __future__ import annotations

import warnings

import pytest

from hysid_model.errors import HysidInputError, HysidWarning
from island.secret import CampaignSecret, read_owner_only, write_owner_only


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


def test_an_owner_only_file_is_written_whole_at_mode_0600_and_read_up_to_1000_characters(tmp_path):
    path = write_owner_only(tmp_path / "k", "a" * 1500)
    assert oct(path.stat().st_mode & 0o777) == "0o600" and sorted(p.name for p in tmp_path.iterdir()) == ["k"]
    write_owner_only(path, "short\n")  # replaced whole
    assert read_owner_only(path, None, "the key") == "short\n" and oct(path.stat().st_mode & 0o777) == "0o600"
    write_owner_only(path, "b" * 1500)
    assert read_owner_only(path, None, "the key") == "b" * 1000


def test_a_failed_write_leaves_no_partial_file(tmp_path):
    (tmp_path / "taken").mkdir()
    with pytest.raises(IsADirectoryError):
        write_owner_only(tmp_path / "taken", "x")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["taken"]


def test_an_unreadable_secret_is_a_one_line_error_naming_the_file_or_the_parameter(tmp_path):
    missing = tmp_path / "nope"
    with pytest.raises(HysidInputError) as named:
        read_owner_only(missing, "secret_file", "the campaign secret")
    assert str(named.value) == f"secret_file={missing}: no such file" and named.value.param == "secret_file"
    with pytest.raises(HysidInputError, match=f"^{missing}: the key: no such file$"):
        read_owner_only(missing, None, "the key")
    with pytest.raises(HysidInputError, match=f"^{tmp_path}: the key: cannot be read \\(Is a directory\\)$"):
        read_owner_only(tmp_path, None, "the key")


def test_a_secret_file_is_ascii_and_bytes_that_are_not_read_as_replacement_characters(tmp_path):
    """A secret is one ASCII line: a file holding other bytes is read (its parse then names what is wrong), never a
    decoding traceback; text that is not ASCII is refused before anything is written."""
    path = tmp_path / "odd"
    path.write_bytes("hysid-secret é\xff".encode() + b"\xff")
    path.chmod(0o600)
    assert read_owner_only(path, None, "the key") == "hysid-secret " + "\ufffd" * 5
    with pytest.raises(HysidInputError, match="not a hysid campaign secret"):
        CampaignSecret.read(path)
    with pytest.raises(UnicodeEncodeError):
        write_owner_only(tmp_path / "k", "clé")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["odd"]
