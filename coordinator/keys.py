"""The coordinator's keys: what only the coordinator may hold, in an owner-only file beside its database.

A campaign's keys are its admission secret (what islands prove they hold when
they join, :mod:`island.secret`) and the coordinator's private Ed25519 signing
key (everything islands obey carries its signature). They live in a key file of
mode 0600, ``<db>-<campaign>.keys`` (:func:`key_path`), one line
``hysid-keys 1 <campaign> <admission hex> <signing key hex>``, written when the
campaign is created and read by ``--resume``; never in the database, which
readers of the results (``hysid watch``, ``hysid report``, a copy sent to a
colleague) open without them. A database of an earlier hysid that kept them in
its ``secrets`` table has them moved here when it is opened for writing
(:func:`coordinator.store.Store`), the table dropped and the file vacuumed.
"""

from __future__ import annotations

import secrets
import warnings
from dataclasses import dataclass, field
from pathlib import Path

from hysid_model.errors import HysidInputError, HysidWarning
from island.secret import KEY_BYTES, CampaignSecret, read_owner_only, write_owner_only
from island.sealing import new_key, public_key
from island.wire import NAME_PATTERN, check_name

MAGIC = "hysid-keys"
FORMAT = "1"


@dataclass(frozen=True)
class CampaignKeys:
    """A campaign's admission secret and its coordinator's private signing key."""

    campaign: str
    admission: bytes = field(repr=False)
    signing: bytes = field(repr=False)

    @classmethod
    def create(cls, campaign: str) -> "CampaignKeys":
        """Fresh keys for ``campaign``."""
        return cls(check_name("campaign", campaign), secrets.token_bytes(KEY_BYTES), new_key())

    @property
    def secret(self) -> CampaignSecret:
        """What the islands are handed: the admission secret and the public half of the signing key."""
        return CampaignSecret(self.campaign, self.admission, public_key(self.signing))

    def text(self) -> str:
        return f"{MAGIC} {FORMAT} {self.campaign} {self.admission.hex()} {self.signing.hex()}"

    @classmethod
    def parse(cls, text: str, source: str) -> "CampaignKeys":
        """The keys in ``text``; anything else is a one-line :class:`HysidInputError` naming ``source``."""
        parts = text.split()
        if len(parts) != 5 or parts[0] != MAGIC or parts[1] != FORMAT or not NAME_PATTERN.match(parts[2]):
            raise HysidInputError(f"{source}: not a hysid key file (one line '{MAGIC} {FORMAT} <campaign> <hex> <hex>')")
        try:
            admission, signing = bytes.fromhex(parts[3]), bytes.fromhex(parts[4])
        except ValueError:
            raise HysidInputError(f"{source}: the campaign's keys are not hexadecimal") from None
        if len(admission) != KEY_BYTES or len(signing) != KEY_BYTES:
            raise HysidInputError(f"{source}: the campaign's keys must be {KEY_BYTES} bytes each")
        return cls(parts[2], admission, signing)

    @classmethod
    def read(cls, path: Path | str, campaign: str) -> "CampaignKeys":
        """The keys of ``campaign`` kept in ``path``."""
        keys = cls.parse(read_owner_only(path, None, "the campaign's key file"), str(path))
        if keys.campaign != campaign:
            raise HysidInputError(f"{path}: the keys of campaign {keys.campaign!r}, not {campaign!r}'s")
        return keys

    def write(self, path: Path | str) -> Path:
        """Keep the keys in ``path`` (mode 0600, replaced whole)."""
        return write_owner_only(path, self.text() + "\n")

    def keep(self, path: Path | str) -> Path:
        """Write the keys to ``path`` unless it holds them already; a :class:`HysidInputError` if it holds others
        (nothing is overwritten that could be a campaign's only copy)."""
        path = Path(path)
        if path.exists():
            if CampaignKeys.read(path, self.campaign) != self:
                raise HysidInputError(f"{path} holds other keys of campaign {self.campaign!r} than its database; move one of them away")
            return path
        return self.write(path)


def key_path(db: Path | str, campaign: str) -> Path:
    """Where the keys of ``campaign`` of database ``db`` are kept: ``<db>-<campaign>.keys``."""
    return Path(f"{db}-{check_name('campaign', campaign)}.keys")


def campaign_keys(db: str, campaign: str, resume: bool) -> CampaignKeys:
    """The keys of a campaign of database ``db`` (``":memory:"``: kept nowhere): fresh ones, written to its key file, for
    a new campaign; for a resumed one, those of its key file, or (none there, with a :class:`HysidWarning`) fresh ones."""
    path = None if db == ":memory:" else key_path(db, campaign)
    if resume and path is not None and path.exists():
        return CampaignKeys.read(path, campaign)
    keys = CampaignKeys.create(campaign)
    if path is not None:
        if resume:
            warnings.warn(HysidWarning(
                f"{path}: no key file of campaign {campaign!r}; it carries on with new keys (its islands of before check the "
                "coordinator's signature, so they cannot be taken up: start them again with the new secret)"), stacklevel=3)
        try:
            keys.write(path)
        except OSError as exc:
            raise HysidInputError(f"{path}: cannot write the campaign's key file ({exc.strerror or exc})") from None
    return keys
