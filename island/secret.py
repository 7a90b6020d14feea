"""The campaign secret: what a coordinator hands its islands, so that each side can tell the other from a stranger.

A coordinator makes one per campaign (its keys, :mod:`coordinator.keys`, kept in
an owner-only file beside its database). It holds

* ``admission``: 32 random bytes that an island proves it holds when it joins
  (an HMAC over the coordinator's fresh challenge, :func:`island.sealing.prove`;
  the secret itself never travels), so that only islands handed the secret
  are admitted;
* ``coordinator``: the public half of the coordinator's Ed25519 signing key, with
  which islands check everything the coordinator sends (the ``config``, the
  answers of the join handshake, ``control`` with its stop order, ``best``,
  its history queries): a party without the coordinator's private key (which
  stays in its key file) cannot pose as the coordinator, even one that holds
  the secret.

Nobody holds more than one member's say with one secret. The campaign's **shared secret**
(the one above, ``member`` ""), which the coordinator writes for islands started by hand,
admits as one member only, the *shared* one: every run joined with it, by whoever holds
it, counts for that member, whose share of the campaign's run slots and of its effort is
bounded like any other's (:mod:`coordinator.admission`). A **member secret** holds instead
the admission secret of one named member, which the coordinator makes from a members' key
that only it holds (:class:`coordinator.keys.CampaignKeys`): its holder joins only for that
member, under island ids that are the member's name or begin with it and a ``-``. No secret
an island is handed makes another's: neither the shared secret nor a member's gives any
other member's admission secret. Hand each host, process or party a member secret of its
own (``hysid coordinator --member NAME``; ``hysid campaign`` gives each island process
one), so that whoever holds one of them, or the shared one, is one bounded member.

Its text form is one line, ``hysid-secret 1 <campaign> <admission hex>
<coordinator hex>`` (the campaign's) or ``hysid-secret 2 <campaign> <member>
<admission hex> <coordinator hex>`` (a member's), kept in a file of mode 0600
beside the campaign database (:func:`secret_path`, ``<db>-<campaign>.secret``;
:func:`member_path` for a member's) and handed to islands by file (``hysid island
--secret-file``) or in the environment (:data:`SECRET_ENV`).
"""

from __future__ import annotations

import os
import secrets
import stat
import warnings
from dataclasses import dataclass
from pathlib import Path

from hysid_model.errors import HysidInputError, HysidWarning
from island.wire import NAME_PATTERN, check_name

SECRET_ENV = "HYSID_SECRET"
"""Environment variable holding a campaign secret's text (instead of ``--secret-file``)."""
SECRET_FILE_ENV = "HYSID_SECRET_FILE"
"""Environment variable naming a campaign secret's file."""
MAGIC = "hysid-secret"
FORMAT = "1"
MEMBER_FORMAT = "2"
KEY_BYTES = 32


def of_member(island: str, member: str) -> bool:
    """Whether island id ``island`` may be one of ``member``'s: the member's name, or it and a ``-`` and more."""
    return island == member or island.startswith(member + "-")


@dataclass(frozen=True)
class CampaignSecret:
    """A campaign's shared admission secret (or one member's: ``member``) and its coordinator's public signing key (see
    the module docstring)."""

    campaign: str
    admission: bytes
    coordinator: bytes
    member: str = ""
    """The member this secret admits for ("": the campaign's shared secret, which admits as the shared member)."""

    @classmethod
    def create(cls, campaign: str, coordinator: bytes) -> CampaignSecret:
        """A fresh admission secret for ``campaign`` whose coordinator signs with the key of public half ``coordinator``."""
        return cls(check_name("campaign", campaign), secrets.token_bytes(KEY_BYTES), coordinator)

    def text(self) -> str:
        if self.member:
            return f"{MAGIC} {MEMBER_FORMAT} {self.campaign} {self.member} {self.admission.hex()} {self.coordinator.hex()}"
        return f"{MAGIC} {FORMAT} {self.campaign} {self.admission.hex()} {self.coordinator.hex()}"

    @classmethod
    def parse(cls, text: str, source: str) -> CampaignSecret:
        """The secret in ``text``; anything else is a one-line :class:`HysidInputError` naming ``source``."""
        parts = text.split()
        if len(parts) not in (5, 6) or parts[0] != MAGIC:
            raise HysidInputError(
                f"{source}: not a hysid campaign secret (one line '{MAGIC} {FORMAT} <campaign> <hex> <hex>', "
                f"or a member's '{MAGIC} {MEMBER_FORMAT} <campaign> <member> <hex> <hex>')"
            )
        if (parts[1], len(parts)) not in ((FORMAT, 5), (MEMBER_FORMAT, 6)):
            raise HysidInputError(f"{source}: campaign secret of format {parts[1][:10]!r}; this hysid reads formats {FORMAT} and {MEMBER_FORMAT}")
        member = parts[3] if parts[1] == MEMBER_FORMAT else ""
        if not NAME_PATTERN.match(parts[2]) or (member and not NAME_PATTERN.match(member)):
            raise HysidInputError(f"{source}: the campaign secret names no valid campaign" + (" or member" if member else ""))
        try:
            admission, coordinator = bytes.fromhex(parts[-2]), bytes.fromhex(parts[-1])
        except ValueError:
            raise HysidInputError(f"{source}: the campaign secret's keys are not hexadecimal") from None
        if len(admission) != KEY_BYTES or len(coordinator) != KEY_BYTES:
            raise HysidInputError(f"{source}: the campaign secret's keys must be {KEY_BYTES} bytes each")
        return cls(parts[2], admission, coordinator, member)

    @classmethod
    def read(cls, path: Path | str) -> CampaignSecret:
        """The secret kept in file ``path``; a :class:`HysidWarning` if others than its owner may read it."""
        return cls.parse(read_owner_only(path, "secret_file", "the campaign secret"), str(path))

    def write(self, path: Path | str) -> Path:
        """Keep the secret in ``path`` (mode 0600, replaced whole: never a half-written file)."""
        return write_owner_only(path, self.text() + "\n")

    def check_campaign(self, campaign: str, source: str) -> CampaignSecret:
        if self.campaign != campaign:
            raise HysidInputError(f"{source}: the campaign secret is campaign {self.campaign!r}'s, not {campaign!r}'s")
        return self


def secret_path(db: Path | str, campaign: str) -> Path:
    """Where a coordinator keeps the secret of ``campaign`` of database ``db``: ``<db>-<campaign>.secret``."""
    return Path(f"{db}-{check_name('campaign', campaign)}.secret")


def member_path(db: Path | str, campaign: str, member: str) -> Path:
    """Where a coordinator writes the secret of ``member`` of ``campaign`` of database ``db``: ``<db>-<campaign>+<member>.secret``
    (a ``+`` is in no name: no campaign's secret can have that path)."""
    return Path(f"{db}-{check_name('campaign', campaign)}+{check_name('member', member)}.secret")


def write_owner_only(path: Path | str, text: str) -> Path:
    """Write ``text`` to ``path`` readable and writable by its owner only (mode 0600 from the start: no moment
    when another user may open it), replacing the file whole (never a half-written one)."""
    path = Path(path)
    partial = path.with_name(f".{path.name}.{secrets.token_hex(4)}")
    fd = os.open(partial, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o600)
    try:
        with os.fdopen(fd, "w", encoding="ascii") as f:
            f.write(text)
            f.flush()
            os.fsync(f.fileno())
        os.replace(partial, path)
    except BaseException:
        partial.unlink(missing_ok=True)
        raise
    return path


def read_owner_only(path: Path | str, param: str | None, what: str) -> str:
    """The text of an owner-only file (at most 1,000 characters), a one-line :class:`HysidInputError` naming
    ``param`` (None: the file) if it cannot be read, a :class:`HysidWarning` if others than its owner may read it."""
    path = Path(path)

    def failed(why: str) -> HysidInputError:
        return HysidInputError(why, param=param, value=path) if param else HysidInputError(f"{path}: {what}: {why}")

    try:
        mode = path.stat().st_mode
        text = path.read_text(encoding="ascii", errors="replace")[:1000]
    except FileNotFoundError:
        raise failed("no such file") from None
    except OSError as exc:
        raise failed(f"cannot be read ({exc.strerror or exc})") from None
    if mode & (stat.S_IRWXG | stat.S_IRWXO):
        warnings.warn(HysidWarning(f"{path}: {what} is readable by others than its owner (chmod 600 {path})"), stacklevel=3)
    return text
