"""The ``hysid`` command line (typer): the only part of hysid that speaks in flags and prints.

Every command turns bad input into one line on stderr, ``hysid: error: ...``
naming the flag or file, and exit status 2; it never prints a traceback for a
user's mistake. Ctrl-C ends any command with ``hysid: error: interrupted`` and
exit status 130, also a campaign, which first stops its islands and writes its
report (marked interrupted). Warnings of the library (:class:`HysidWarning`) print as
``hysid: warning: ...`` and the command goes on.
"""

from __future__ import annotations

import importlib
import sys
import warnings
from collections.abc import Iterator, MutableMapping, Sequence
from importlib.metadata import PackageNotFoundError, version
from typing import Any, TextIO

import typer
from typer.core import TyperGroup

from hysid.cli.options import INTERRUPTED, error_line
from hysid_model.errors import HysidInputError, HysidWarning

COMMANDS = {
    "synth": "data",
    "loops": "data",
    "fit": "fit",
    "campaign": "campaign",
    "coordinator": "campaign",
    "island": "island",
    "router": "router",
    "diagnose": "diagnose",
    "watch": "watch",
    "report": "watch",
    "models": "",
    "reproduce": "fit",
    "bench": "bench",
}
"""Each command and the module of :mod:`hysid.cli` that registers it ("": this one), in the order ``hysid --help``
lists them."""
SETTINGS: dict[str, Any] = {"add_completion": False, "pretty_exceptions_enable": False, "rich_markup_mode": None}


def command_modules(argv: Sequence[str]) -> list[str]:
    """The modules of :mod:`hysid.cli` a command line ``argv`` needs: its command's, or every one where it names
    none (``hysid --help`` lists them all) or one that is not a command."""
    first = next((a for a in argv if not a.startswith("-")), "")
    if first not in COMMANDS:
        return sorted({m for m in COMMANDS.values() if m})
    return [COMMANDS[first]] if COMMANDS[first] else []


def load_commands(argv: Sequence[str]) -> None:
    """Import what :func:`command_modules` names (``python -m hysid`` does it while Ctrl-C waits, :mod:`hysid.__main__`)."""
    for module in command_modules(argv):
        importlib.import_module(f"hysid.cli.{module}")


class CommandTable(MutableMapping[str, Any]):
    """The commands of ``hysid`` by name, each module of :mod:`hysid.cli` imported when one of its commands is
    looked up: a command starts with what it needs (``hysid island``, started hundreds of times by a campaign,
    loads no coordinator, report or bench), and ``hysid --help`` looks them all up."""

    def __init__(self, loaded: MutableMapping[str, Any]) -> None:
        self._loaded = dict(loaded)

    def __getitem__(self, name: str) -> Any:
        if name not in self._loaded and COMMANDS.get(name):
            commands = typer.Typer(**SETTINGS)
            importlib.import_module(f"hysid.cli.{COMMANDS[name]}").register(commands)
            self._loaded.update(typer.main.get_group(commands).commands)
        return self._loaded[name]

    def __setitem__(self, name: str, command: Any) -> None:
        self._loaded[name] = command

    def __delitem__(self, name: str) -> None:
        del self._loaded[name]

    def __iter__(self) -> Iterator[str]:
        return iter([*COMMANDS, *(n for n in self._loaded if n not in COMMANDS)])

    def __len__(self) -> int:
        return len(set(COMMANDS) | set(self._loaded))


class Commands(TyperGroup):
    """hysid's command group: its commands in a :class:`CommandTable`."""

    def __init__(self, **kwargs: Any) -> None:
        super().__init__(**kwargs)
        self.commands = CommandTable(self.commands)


app = typer.Typer(
    name="hysid",
    help="Identify damping, natural frequency and missing physics from hysteresis loops.",
    no_args_is_help=True,
    cls=Commands,
    **SETTINGS,
)


def package_version() -> str:
    try:
        return version("hysid")
    except PackageNotFoundError:
        return "unknown (not installed)"


def show_version(value: bool) -> None:
    if value:
        print(f"hysid {package_version()}")
        raise typer.Exit()


@app.callback()
def root(
    _version: bool = typer.Option(False, "--version", callback=show_version, is_eager=True, help="Print hysid's version and exit."),
) -> None:
    """Identify damping, natural frequency and missing physics from hysteresis loops."""


@app.command("models")
def models_command(
    modules: list[str] | None = typer.Option(
        None,
        "--import",
        metavar="MODULE",
        help="Import this module (repeatable) and list the terms of your own it makes (hysid.term).",
    ),
) -> None:
    """List the model presets, the effect library and terms of your own (--import), with every parameter's unit and default bounds."""
    from hysid.report.text import models_text
    from hysid_model.user_terms import import_user_module

    for module in modules or []:
        import_user_module(module, "--import: ")
    print(models_text())


def fail(message: str) -> None:
    print(f"hysid: error: {' '.join(str(message).split())}", file=sys.stderr)


def show_warning(message: Any, category: type[Warning], filename: str, lineno: int, file: TextIO | None = None, line: str | None = None) -> None:
    """Library warnings as one line each; others as Python shows them."""
    if issubclass(category, HysidWarning):
        print(f"hysid: warning: {' '.join(str(message).split())}", file=sys.stderr)
    else:
        print(warnings.formatwarning(message, category, filename, lineno, line), file=sys.stderr, end="")


def main(argv: list[str] | None = None) -> int:
    with warnings.catch_warnings():
        warnings.simplefilter("default", HysidWarning)
        warnings.showwarning = show_warning
        try:
            result = typer.main.get_command(app).main(args=argv, prog_name="hysid", standalone_mode=False)
        except typer.Exit as exc:
            return int(exc.exit_code or 0)
        except typer.TyperException as exc:
            fail(exc.format_message())
            return int(getattr(exc, "exit_code", 2) or 2)
        except typer.Abort:
            fail("aborted")
            return INTERRUPTED
        except HysidInputError as exc:
            fail(error_line(exc))
            return 2
        except OSError as exc:  # the environment: a full disk, a file made read-only while the command ran
            fail(f"{exc.strerror or type(exc).__name__}" + (f": {exc.filename}" if exc.filename else "") + " (what was written before is kept)")
            return 2
        except KeyboardInterrupt:
            fail("interrupted")
            return INTERRUPTED
    if result == INTERRUPTED:  # Ctrl-C in a command: typer's answer, or a campaign that stopped and reported
        fail("interrupted")
    return result if isinstance(result, int) else 0
