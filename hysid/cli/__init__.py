"""The ``hysid`` command line (typer): the only part of hysid that speaks in flags and prints.

Every command turns bad input into one line on stderr, ``hysid: error: ...``
naming the flag or file, and exit status 2; it never prints a traceback for a
user's mistake. Ctrl-C ends any command with ``hysid: error: interrupted`` and
exit status 130, also a campaign, which first stops its islands and writes its
report (marked interrupted). Warnings of the library (:class:`HysidWarning`) print as
``hysid: warning: ...`` and the command goes on.
"""

from __future__ import annotations

import sys
import warnings
from importlib.metadata import PackageNotFoundError, version
from typing import Any, TextIO

import typer

from hysid.cli import bench, campaign, data, diagnose, fit, island, router, watch
from hysid.cli.options import INTERRUPTED, error_line
from hysid_model.errors import HysidInputError, HysidWarning

app = typer.Typer(
    name="hysid",
    help="Identify damping, natural frequency and missing physics from hysteresis loops.",
    add_completion=False,
    no_args_is_help=True,
    pretty_exceptions_enable=False,
    rich_markup_mode=None,
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


for module in (data, fit, bench, campaign, island, router, diagnose, watch):
    module.register(app)


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
