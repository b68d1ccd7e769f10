"""The `prc3cfg` command line: typer apps, wiring only.

Each command lives in a module of this package that registers itself on `app` (or on one
of the sub-apps) when imported; `main()` imports them all and turns a `UserError` into one
line on stderr and a non-zero exit.
"""

from __future__ import annotations

import sys

import typer

from prc3cfg.errors import UserError

app = typer.Typer(
    no_args_is_help=True,
    add_completion=False,
    pretty_exceptions_enable=False,
    help="Plant configuration as code for PRC 3 powder reciprocator controllers.",
)
emulator_app = typer.Typer(no_args_is_help=True, help="A software PRC 3 bus.")
link_app = typer.Typer(no_args_is_help=True, help="Gateway and line settings.")
app.add_typer(emulator_app, name="emulator")
app.add_typer(link_app, name="link")

COMMAND_MODULES: tuple[str, ...] = ("emulator_commands", "plant_commands", "plan_commands", "bus_commands")


def _register_commands() -> None:
    import importlib

    for name in COMMAND_MODULES:
        importlib.import_module(f"prc3cfg.cli.{name}")


#: A command line prc3cfg does not understand. click exits 2 for it, which `plan
#: --detailed-exitcode` uses for "changes": a CI job must never read a typo as changes.
EXIT_USAGE = 64


class Outcome(Exception):
    """A command's result that is not an error but needs its own exit code (plan: 2 = changes)."""

    def __init__(self, code: int) -> None:
        super().__init__(code)
        self.code = code


def main(argv: list[str] | None = None) -> None:
    """The console script; `argv` (default: sys.argv) lets tests run a command in-process."""
    _register_commands()
    from prc3cfg.cli.common import CANCEL

    try:
        with CANCEL.handling():
            app(args=argv)
    except Outcome as outcome:
        sys.exit(outcome.code)
    except UserError as error:
        for line in str(error).splitlines():  # several problems: one line each
            print(f"error: {line}", file=sys.stderr)
        sys.exit(error.exit_code)
    except KeyboardInterrupt:
        print("error: interrupted", file=sys.stderr)
        sys.exit(130)
    except SystemExit as exit:
        if exit.code == 2:  # click: usage error
            sys.exit(EXIT_USAGE)
        raise
