"""The error and warning types of hysid's user-facing API.

Library code speaks Python: an error names the file, the Python parameter or
the message field that is wrong, never a command-line flag. An error about a
parameter carries it (``param``, ``value``) so that the command line can name
its own flag instead (``hysid.cli.options.FLAGS``).
"""

from __future__ import annotations

from typing import Any

_UNSET: Any = object()


class HysidInputError(ValueError):
    """Bad input (a file, an argument or a message): one line that names what is wrong.

    ``HysidInputError("data/run1.csv: column 'force_n' missing")`` names a file;
    ``HysidInputError("must be at least 1", param="runs", value=0)`` reads
    ``runs=0: must be at least 1`` in Python and ``--runs 0: must be at least 1``
    on the command line.
    """

    def __init__(self, message: str, *, param: str | None = None, value: Any = _UNSET) -> None:
        self.detail = " ".join(str(message).split())
        self.param = param
        self.value = value
        super().__init__(self.detail if param is None else f"{self.subject()}: {self.detail}")

    @property
    def has_value(self) -> bool:
        return self.value is not _UNSET

    def subject(self, name: str | None = None) -> str:
        """``param=value`` (or ``name value`` when a flag ``name`` stands for the parameter)."""
        name = name or self.param or ""
        if not self.has_value:
            return name
        value = repr(self.value) if isinstance(self.value, str) else str(self.value)
        return f"{name} {value}" if name.startswith("-") else f"{name}={value}"


class HysidWarning(UserWarning):
    """Something suspicious that does not stop the work (distortion, a unit slip, a fallback).

    ``code`` names the kind with a stable word (``swapped_columns``, ``unit_slip_displacement``, ...;
    :data:`hysid_model.notices.CODES` lists them) so that a result can carry its warnings
    (``result.json``'s ``warnings``) and a program can act on them without parsing the message.
    """

    def __init__(self, message: str, code: str = "warning") -> None:
        super().__init__(message)
        self.code = code
