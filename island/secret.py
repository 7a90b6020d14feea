"""The campaign secret: what a coordinator hands its islands, so that each side can tell the other from a stranger.

A coordinator makes one per campaign (:meth:`CampaignSecret.create`, kept in
its database). It holds

* ``admission``: 32 random bytes that an island proves it holds when it joins
  (an HMAC over the coordinator's fresh challenge, :func:`island.sealing.prove`;
  the secret itself never travels), so that only islands handed the secret
  are admitted;
* ``coordinator``: the public half of the coordinator's Ed25519 signing key, with
  which islands check everything the coordinator sends (the ``config``, the
  answers of the join handshake, ``control`` with its stop order, ``best``,
  its history queries): a party without the coordinator's private key (which
  stays in its database) cannot pose as the coordinator, even one that holds
  the secret.

Its text form is one line, ``hysid-secret 1 <campaign> <admission hex>
<coordinator hex>``, kept in a file of mode 0600 beside the campaign database
(:func:`secret_path`, ``<db>-<campaign>.secret``) and handed to islands by file
(``hysid island --secret-file``) or in the environment (:data:`SECRET_ENV`).
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
KEY_BYTES = 32


@dataclass(frozen=True)
class CampaignSecret:
    """A campaign's admission secret and its coordinator's public signing key (see the module docstring)."""

    campaign: str
    admission: bytes
    coordinator: bytes

    @classmethod
    def create(cls, campaign: str, coordinator: bytes) -> "CampaignSecret":
        """A fresh admission secret for ``campaign`` whose coordinator signs with the key of public half ``coordinator``."""
        return cls(check_name("campaign", campaign), secrets.token_bytes(KEY_BYTES), coordinator)

    def text(self) -> str:
        return f"{MAGIC} {FORMAT} {self.campaign} {self.admission.hex()} {self.coordinator.hex()}"

    @classmethod
    def parse(cls, text: str, source: str) -> "CampaignSecret":
        """The secret in ``text``; anything else is a one-line :class:`HysidInputError` naming ``source``."""
        parts = text.split()
        if len(parts) != 5 or parts[0] != MAGIC:
            raise HysidInputError(f"{source}: not a hysid campaign secret (one line '{MAGIC} {FORMAT} <campaign> <hex> <hex>')")
        if parts[1] != FORMAT:
            raise HysidInputError(f"{source}: campaign secret of format {parts[1][:10]!r}; this hysid reads format {FORMAT}")
        if not NAME_PATTERN.match(parts[2]):
            raise HysidInputError(f"{source}: the campaign secret names no valid campaign")
        try:
            admission, coordinator = bytes.fromhex(parts[3]), bytes.fromhex(parts[4])
        except ValueError:
            raise HysidInputError(f"{source}: the campaign secret's keys are not hexadecimal") from None
        if len(admission) != KEY_BYTES or len(coordinator) != KEY_BYTES:
            raise HysidInputError(f"{source}: the campaign secret's keys must be {KEY_BYTES} bytes each")
        return cls(parts[2], admission, coordinator)

    @classmethod
    def read(cls, path: Path | str) -> "CampaignSecret":
        """The secret kept in file ``path``; a :class:`HysidWarning` if others than its owner may read it."""
        return cls.parse(read_owner_only(path, "secret_file", "the campaign secret"), str(path))

    def write(self, path: Path | str) -> Path:
        """Keep the secret in ``path`` (mode 0600, replaced whole: never a half-written file)."""
        return write_owner_only(path, self.text() + "\n")

    def check_campaign(self, campaign: str, source: str) -> "CampaignSecret":
        if self.campaign != campaign:
            raise HysidInputError(f"{source}: the campaign secret is campaign {self.campaign!r}'s, not {campaign!r}'s")
        return self


def secret_path(db: Path | str, campaign: str) -> Path:
    """Where a coordinator keeps the secret of ``campaign`` of database ``db``: ``<db>-<campaign>.secret``."""
    return Path(f"{db}-{check_name('campaign', campaign)}.secret")


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
