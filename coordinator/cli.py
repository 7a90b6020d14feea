"""The ``hysid`` command line (typer).

Every command turns bad input into one line on stderr, ``hysid: error: ...``,
and exit status 2; it never prints a traceback for a user's mistake.
"""

from __future__ import annotations

import sys

import typer

from coordinator import cli_bench, cli_campaign, cli_data, cli_diagnose, cli_fit
from hysid_model.errors import HysidInputError
from hysid_model.model import PRESETS, build_model
from hysid_model.effects import EFFECTS

app = typer.Typer(
    name="hysid",
    help="Identify damping, natural frequency and missing physics from hysteresis loops.",
    add_completion=False,
    no_args_is_help=True,
    pretty_exceptions_enable=False,
    rich_markup_mode=None,
)



@app.callback()
def root() -> None:
    """Identify damping, natural frequency and missing physics from hysteresis loops."""


for module in (cli_data, cli_fit, cli_bench, cli_campaign, cli_diagnose):
    module.register(app)


@app.command("models")
def models_command() -> None:
    """List the model presets and the effect library, with every parameter's unit and default bounds."""
    for spec in PRESETS:
        print(build_model(spec, meq_kg=1.0).describe())
    print("effects (add with MODEL+EFFECT, e.g. thesis+coulomb_friction):")
    for effect_id, term_type in sorted(EFFECTS.items()):
        term = term_type()
        plist = ", ".join(f"{p.name} [{p.unit}] in [{p.lower:g}, {p.upper:g}]" for p in term.params)
        print(f"  {effect_id}: {plist}\n      {term.explanation}")


def fail(message: str) -> None:
    print(f"hysid: error: {' '.join(str(message).split())}", file=sys.stderr)


def main(argv: list[str] | None = None) -> int:
    command = typer.main.get_command(app)
    try:
        result = command.main(args=argv, prog_name="hysid", standalone_mode=False)
    except typer.Exit as exc:
        return int(exc.exit_code or 0)
    except typer.TyperException as exc:
        fail(exc.format_message())
        return int(getattr(exc, "exit_code", 2) or 2)
    except typer.Abort:
        fail("aborted")
        return 130
    except HysidInputError as exc:
        fail(str(exc))
        return 2
    except KeyboardInterrupt:
        fail("interrupted")
        return 130
    return result if isinstance(result, int) else 0


if __name__ == "__main__":
    sys.exit(main())
