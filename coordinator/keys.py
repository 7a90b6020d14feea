"""The coordinator's keys: what only the coordinator may hold, in an owner-only file beside its database.

A campaign's keys are

* its shared admission secret (what a holder of the campaign's shared secret, :mod:`island.secret`, proves when it
  joins: all of them together are *one* member, the shared one);
* the **members' key**, from which the admission secret of each named member is made (:meth:`CampaignKeys.member_secret`,
  an HMAC of the member's name): it never leaves the key file, so no secret an island is handed (the shared one, or
  any member's) makes another member's, and a holder of one secret joins as one member only;
* the coordinator's private Ed25519 signing key (everything islands obey carries its signature).

They live in a key file of mode 0600, ``<db>-<campaign>.keys`` (:func:`key_path`), one line ``hysid-keys 2
<campaign> <admission hex> <signing key hex> <members' key hex>``, written when the campaign is created and read by
``--resume`` (so a resumed coordinator admits the same members again); never in the database, which readers of the
results (``hysid watch``, ``hysid report``, a copy sent to a colleague) open without them. A database of an earlier
hysid that kept them in its ``secrets`` table has them moved here when it is opened for writing
(:func:`coordinator.store.Store`), the table dropped and the file vacuumed. A key file of format 1 (an earlier
hysid, no members' key) gets one when a coordinator resumes with it (:func:`campaign_keys`): the shared secret stays,
member secrets written before no longer admit and are written again by ``--member``.
"""

from __future__ import annotations

import hashlib
import hmac
import secrets
import warnings
from dataclasses import dataclass, field, replace
from pathlib import Path

from hysid_model.errors import HysidInputError, HysidWarning
from island.sealing import new_key, public_key
from island.secret import KEY_BYTES, CampaignSecret, read_owner_only, write_owner_only
from island.wire import NAME_PATTERN, check_name

MAGIC = "hysid-keys"
FORMAT = "2"
FORMAT_WITHOUT_MEMBERS = "1"
"""An earlier hysid's key file: the shared admission secret and the signing key, no members' key."""


@dataclass(frozen=True)
class CampaignKeys:
    """A campaign's shared admission secret, its coordinator's private signing key and the members' key (see the
    module docstring; ``members`` is empty for keys of an earlier hysid until :meth:`with_members_key`)."""

    campaign: str
    admission: bytes = field(repr=False)
    signing: bytes = field(repr=False)
    members: bytes = field(default=b"", repr=False)

    @classmethod
    def create(cls, campaign: str) -> CampaignKeys:
        """Fresh keys for ``campaign``."""
        return cls(check_name("campaign", campaign), secrets.token_bytes(KEY_BYTES), new_key(), secrets.token_bytes(KEY_BYTES))

    def with_members_key(self) -> CampaignKeys:
        """These keys with a members' key (a fresh one if they had none)."""
        return self if self.members else replace(self, members=secrets.token_bytes(KEY_BYTES))

    @property
    def secret(self) -> CampaignSecret:
        """The campaign's shared secret: the shared admission secret and the public half of the signing key."""
        return CampaignSecret(self.campaign, self.admission, public_key(self.signing))

    def admission_for(self, member: str) -> bytes:
        """What a join for ``member`` must prove: the shared admission secret for ``""``, else that member's, made from
        the members' key (which no island holds)."""
        if not member:
            return self.admission
        if not self.members:
            raise HysidInputError(f"campaign {self.campaign!r}: its keys have no members' key (a key file of an earlier hysid)")
        return hmac.new(self.members, b"hysid member\x00" + check_name("member", member).encode(), hashlib.sha256).digest()

    def member_secret(self, member: str) -> CampaignSecret:
        """The secret of ``member`` (a non-empty name): its holder joins as that member only, under island ids that are
        its name or begin with it and a ``-``."""
        return CampaignSecret(self.campaign, self.admission_for(check_name("member", member)), public_key(self.signing), member)

    def text(self) -> str:
        return f"{MAGIC} {FORMAT} {self.campaign} {self.admission.hex()} {self.signing.hex()} {self.members.hex()}"

    @classmethod
    def parse(cls, text: str, source: str) -> CampaignKeys:
        """The keys in ``text`` (format 1, of an earlier hysid: without members' key); anything else is a one-line
        :class:`HysidInputError` naming ``source``."""
        parts = text.split()
        shape = (FORMAT, 6) if parts[1:2] == [FORMAT] else (FORMAT_WITHOUT_MEMBERS, 5)
        if len(parts) != shape[1] or parts[0] != MAGIC or parts[1] != shape[0] or not NAME_PATTERN.match(parts[2]):
            raise HysidInputError(f"{source}: not a hysid key file (one line '{MAGIC} {FORMAT} <campaign> <hex> <hex> <hex>')")
        try:
            keys = [bytes.fromhex(p) for p in parts[3:]]
        except ValueError:
            raise HysidInputError(f"{source}: the campaign's keys are not hexadecimal") from None
        if any(len(k) != KEY_BYTES for k in keys):
            raise HysidInputError(f"{source}: the campaign's keys must be {KEY_BYTES} bytes each")
        return cls(parts[2], *keys)

    @classmethod
    def read(cls, path: Path | str, campaign: str) -> CampaignKeys:
        """The keys of ``campaign`` kept in ``path``."""
        keys = cls.parse(read_owner_only(path, None, "the campaign's key file"), str(path))
        if keys.campaign != campaign:
            raise HysidInputError(f"{path}: the keys of campaign {keys.campaign!r}, not {campaign!r}'s")
        return keys

    def write(self, path: Path | str) -> Path:
        """Keep the keys in ``path`` (mode 0600, replaced whole)."""
        return write_owner_only(path, self.text() + "\n")

    def keep(self, path: Path | str) -> Path:
        """Write the keys to ``path`` unless it holds them already (its members' key, if it has one, kept); a
        :class:`HysidInputError` if it holds others (nothing is overwritten that could be a campaign's only copy)."""
        path = Path(path)
        if path.exists():
            kept = CampaignKeys.read(path, self.campaign)
            if (kept.admission, kept.signing) != (self.admission, self.signing):
                raise HysidInputError(f"{path} holds other keys of campaign {self.campaign!r} than its database; move one of them away")
            return path
        return self.write(path)


def key_path(db: Path | str, campaign: str) -> Path:
    """Where the keys of ``campaign`` of database ``db`` are kept: ``<db>-<campaign>.keys``."""
    return Path(f"{db}-{check_name('campaign', campaign)}.keys")


def campaign_keys(db: str, campaign: str, resume: bool) -> CampaignKeys:
    """The keys of a campaign of database ``db`` (``":memory:"``: kept nowhere): fresh ones, written to its key file, for
    a new campaign; for a resumed one, those of its key file (one of an earlier hysid given a members' key, with a
    :class:`HysidWarning`), or (none there, with a :class:`HysidWarning`) fresh ones."""
    path = None if db == ":memory:" else key_path(db, campaign)
    if resume and path is not None and path.exists():
        keys = CampaignKeys.read(path, campaign)
        if keys.members:
            return keys
        keys = keys.with_members_key()
        warnings.warn(
            HysidWarning(
                f"{path}: a key file of an earlier hysid, without a members' key; one was added (islands with the campaign's shared "
                "secret join as before; member secrets written before no longer admit: write them again with --member NAME)"
            ),
            stacklevel=3,
        )
    else:
        keys = CampaignKeys.create(campaign)
        if resume and path is not None:
            warnings.warn(
                HysidWarning(
                    f"{path}: no key file of campaign {campaign!r}; it carries on with new keys (its islands of before check the "
                    "coordinator's signature, so they cannot be taken up: start them again with the new secret)"
                ),
                stacklevel=3,
            )
    if path is not None:
        try:
            keys.write(path)
        except OSError as exc:
            raise HysidInputError(f"{path}: cannot write the campaign's key file ({exc.strerror or exc})") from None
    return keys
