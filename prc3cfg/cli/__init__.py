"""The `prc3cfg` command line: typer apps, wiring only.

Each command lives in a module of this package that registers itself on `app` (or on one
of the sub-apps) when imported; `main()` imports them all and turns every way a command
can end into one line on stderr and an exit code:

- a `UserError`: `error: …` (one line per problem), its `exit_code` (1; 130 interrupted);
- a command line prc3cfg does not understand: `error: prc3cfg CMD: … — see prc3cfg CMD --help`,
  exit 64 (`EXIT_USAGE`) — never a boxed panel; a Terraform habit (`-out=p.json`, `-out p.json`,
  `-auto-approve`, `-target=NAME`) gets "did you mean --out p.json" (`--module NAME`);
- stdout closed by its reader (`prc3cfg read … | head -1`): quietly, exit 141 (`EXIT_BROKEN_PIPE`).
"""


import copy
import inspect
import os
import re
import sys
from typing import Annotated

import typer

try:  # typer 0.2x carries its own copy of click, and raises that copy's exceptions
    from typer._click import exceptions as click_errors
    from typer._click.utils import PacifyFlushWrapper
except ImportError:  # pragma: no cover - older typer uses click itself
    # click is installed only where typer has no copy of it (or where another package wants it)
    from click import exceptions as click_errors  # type: ignore[import-not-found, no-redef, unused-ignore]
    from click.utils import PacifyFlushWrapper  # type: ignore[import-not-found, no-redef, assignment, unused-ignore]

from prc3cfg import __version__
from prc3cfg.core.text import shown
from prc3cfg.errors import UserError, interruption_within

app = typer.Typer(
    no_args_is_help=True,
    add_completion=True,
    pretty_exceptions_enable=False,
    rich_markup_mode=None,  # plain help: rich's help renderer alone takes 70 ms to import
    help="Plant configuration as code for PRC 3 powder reciprocator controllers.",
)
emulator_app = typer.Typer(no_args_is_help=True, rich_markup_mode=None, help="A software PRC 3 bus.")
link_app = typer.Typer(no_args_is_help=True, rich_markup_mode=None, help="Gateway and line settings.")
app.add_typer(emulator_app, name="emulator")
records_app = typer.Typer(no_args_is_help=True, rich_markup_mode=None,
                          help="The journals and snapshots beside a plant file.")
app.add_typer(link_app, name="link")
app.add_typer(records_app, name="records")

#: The module of each command and group, in the order `prc3cfg --help` lists them (groups last). typer builds
#: every registered command from its signature before it runs one, so a command line registers only its own
#: command's module (`_register_commands`); a test holds this table to what the modules register.
COMMAND_MODULES: dict[str, str] = {
    "validate": "plant_commands", "show": "plant_commands", "schema": "plant_commands",
    "read": "plan_commands", "plan": "plan_commands", "apply": "plan_commands", "restore": "plan_commands",
    "ports": "bus_commands", "setup-machine": "bus_commands", "scan": "bus_commands",
                                   "import": "bus_commands",
    "doctor": "bus_commands",
    "adopt": "adopt_commands",
    "emulator": "emulator_commands", "link": "bus_commands", "records": "records_commands",
                                   "status": "status_commands",
    "fleet": "fleet_commands",
}


def _completing() -> bool:
    """Whether this process is shell completion (click's: `_PRC3CFG_COMPLETE`), which needs every command."""
    return any(key.endswith("_COMPLETE") for key in os.environ)


def _command_named(args: list[str]) -> str | None:
    """The command (or group) a command line names, when prc3cfg has it; None for `--help`, no command, a
    typo."""
    named = next((arg for arg in args if not arg.startswith("-")), None)
    return named if named in COMMAND_MODULES else None


def _register_commands(args: list[str] | None = None) -> None:
    """Import the command modules, which register their commands on `app`: of a command line `args`
    that names a command, only that command's; of any other (`--help`, a typo, shell completion), all."""
    import importlib

    named = _command_named(args or [])
    names = [COMMAND_MODULES[named]] if named is not None and not _completing() else COMMAND_MODULES.values()
    for name in dict.fromkeys(names):
        importlib.import_module(f"prc3cfg.cli.{name}")
    # in the table's order, whichever module a process imported first (a program running many command lines)
    rank = {command: n for n, command in enumerate(COMMAND_MODULES)}.get
    app.registered_commands.sort(key=lambda info: rank(_name_of(info), 0))
    app.registered_groups.sort(key=lambda group: rank(group.name or "", 0))


def _listed(app: typer.Typer) -> typer.Typer:
    """`app` as a listing shows it (`prc3cfg --help`, `prc3cfg`, a command it does not know): each command by
    its name and help alone. typer builds every command's options from its signature before it shows a
    listing that shows none of them — 8 ms of the 60 `--help` may take. The app itself is left as it is."""
    listed = copy.copy(app)
    listed.registered_commands = [_named(info) for info in app.registered_commands]
    listed.registered_groups = []
    for group in app.registered_groups:
        group = copy.copy(group)
        if group.typer_instance is not None:
            group.typer_instance = _listed(group.typer_instance)
        listed.registered_groups.append(group)
    return listed


def _name_of(info: typer.models.CommandInfo) -> str:
    """A registered command's name, as typer names it."""
    return info.name or typer.main.get_command_name(getattr(info.callback, "__name__", ""))


def _named(info: typer.models.CommandInfo) -> typer.models.CommandInfo:
    """A command as a listing shows it: its name and help, without its options (none to build)."""
    named = copy.copy(info)
    named.name = _name_of(info)
    named.help = info.help if info.help is not None else inspect.getdoc(info.callback)
    named.callback = _nothing
    return named


def _nothing() -> None:
    """What a listed command runs: nothing (a listing runs none)."""


def _print_version(value: bool) -> None:
    if value:
        print(f"prc3cfg {__version__}")
        raise typer.Exit()


@app.callback()
def _root(
    version: Annotated[bool, typer.Option("--version", callback=_print_version, is_eager=True,
                                          help="Print the version.")] = False,
) -> None:
    pass


#: A command line prc3cfg does not understand. click exits 2 for it, which `plan
#: --detailed-exitcode` uses for "changes": a CI job must never read a typo as changes.
EXIT_USAGE = 64
#: Stdout closed by its reader: 128 + SIGPIPE, what git, coreutils and a shell report for a
#: process that writes into a pipe nobody reads any more (prc3cfg says nothing, as they do).
EXIT_BROKEN_PIPE = 141
#: A single-dash word option, as Terraform spells its options: -out=plan.json, -auto-approve.
_SINGLE_DASH = re.compile(r"-([a-z][a-z0-9]*(?:-[a-z0-9]+)+|[a-z]{2,})(?:=(.*))?")
#: Terraform's options that prc3cfg names otherwise: its option, and why it is another.
_TERRAFORM = {"target": ("--module", "prc3cfg names a module with --module")}


class ExitStatus(Exception):
    """A command's result that is not an error but needs its own exit code (plan: 2 = changes)."""

    def __init__(self, code: int) -> None:
        super().__init__(code)
        self.code = code


def _options(command) -> dict[str, bool]:
    """Every long option of a command and of the commands under it: whether it takes a value."""
    names = {name: not getattr(param, "is_flag", False) for param in command.params for name in param.opts
             if name.startswith("--")}
    for sub in getattr(command, "commands", {}).values():
        names |= _options(sub)
    return names


def _single_dash_habit(args: list[str]) -> str | None:
    """ "-out=p.json: prc3cfg options take two dashes — did you mean --out p.json?" (`-out p.json`
    too), "-target=x: prc3cfg names a module with --module — did you mean --module x?", or None."""
    known: dict[str, bool] = {}
    for at, arg in enumerate(args):
        if arg == "--":
            return None
        match = _SINGLE_DASH.fullmatch(arg)
        if match is None:
            continue
        # the whole command tree: only for a word that needs it
        known = known or _options(typer.main.get_command(app))
        option, why = _TERRAFORM.get(match.group(1),
                                     (f"--{match.group(1)}", "prc3cfg options take two dashes"))
        if option not in known:
            continue
        written, value = arg, match.group(2)
        if value is None and known[option] and at + 1 < len(args):  # -out plan.json
            value = args[at + 1]
            written = f"{arg} {value}"
        return f"{written}: {why} — did you mean {option}{'' if value is None else ' ' + value}?"
    return None


#: pydantic's words (typer checks an option's type and bounds with it) → the tool's: what the value must be.
#: Patterns, not compiled ones: only a usage error needs them (`re` compiles and keeps them then), not
#: each start-up.
_PYDANTIC_WORDS = (
    (r"Input should be greater than or equal to (\S+)", r"must be \1 or more"),
    (r"Input should be less than or equal to (\S+)", r"must be \1 or less"),
    (r"Input should be greater than (\S+)", r"must be more than \1"),
    (r"Input should be less than (\S+)", r"must be less than \1"),
    (r"Input should be a valid integer(, unable to parse string as an integer)?",
     "must be a whole number"),
    (r"Input should be a valid number(, unable to parse string as a number)?", "must be a number"),
    (r"Input should be ", "must be "),
    (r"Value error, ", ""),
)


def _completion_for(args: list[str]) -> str | None:
    """`--install-completion zsh`: typer installs for the shell it runs in and drops the name — bash
    completion for a zsh user, said as done. Refused, saying how to get what was asked for."""
    for at, arg in enumerate(args[:-1]):
        if arg in ("--install-completion", "--show-completion") and not args[at + 1].startswith("-"):
            return (f"prc3cfg: {arg} takes no shell name ({shown(args[at + 1])}): it is for the shell it is "
                    "run in — run "
                    f"prc3cfg {arg} from that shell")
    return None


def _usage(error: click_errors.UsageError) -> str:
    command = error.ctx.command_path if error.ctx is not None else "prc3cfg"
    message = shown(" ".join(error.format_message().split()).rstrip("."))
    for pattern, words in _PYDANTIC_WORDS:
        message = re.sub(pattern, words, message)
    return f"error: {command}: {message} — see {command} --help"


def _streams_where_there_are_none() -> None:
    """Started with no standard output or error — pythonw, a Windows service, a descriptor closed —
    Python leaves them None and the first word said would end the command in an error nobody sees:
    what the command says goes to the null device instead, and its exit status still tells."""
    for name in ("stdout", "stderr"):
        if getattr(sys, name) is None:
            from prc3cfg.shell.platform import open_text

            setattr(sys, name, open_text(os.devnull))  # open for the process's life


def main(argv: list[str] | None = None) -> None:
    """The console script; `argv` (default: sys.argv) lets tests run a command in-process."""
    _streams_where_there_are_none()
    args = sys.argv[1:] if argv is None else list(argv)
    _register_commands(args)
    from prc3cfg.cli.common import CANCEL, COMMAND_LINE

    COMMAND_LINE[:] = ["prc3cfg", *args]
    try:
        if (habit := _single_dash_habit(args) or _completion_for(args)) is not None:
            print(f"error: {habit}", file=sys.stderr)
            sys.exit(EXIT_USAGE)
        with CANCEL.handling():
            run = _listed(app) if _command_named(args) is None and not _completing() else app
            code = run(args=args, prog_name="prc3cfg", standalone_mode=False)
        sys.stdout.flush()
    except ExitStatus as outcome:
        sys.exit(outcome.code)
    except click_errors.NoArgsIsHelpError as error:  # `prc3cfg`, `prc3cfg emulator`: what there is to run
        print(error.ctx.get_help() if error.ctx is not None else "see prc3cfg --help")
        sys.exit(EXIT_USAGE)
    except click_errors.UsageError as error:
        print(_usage(error), file=sys.stderr)
        sys.exit(EXIT_USAGE)
    except click_errors.ClickException as error:
        print(f"error: {shown(' '.join(error.format_message().split()))}", file=sys.stderr)
        sys.exit(1)
    except UserError as error:
        for line in str(error).split("\n"):  # several problems: one line each, what a file holds `shown`
            print(f"error: {shown(line)}", file=sys.stderr)
        sys.exit(error.exit_code)
    except (KeyboardInterrupt, typer.Abort):
        print("error: interrupted", file=sys.stderr)
        sys.exit(130)
    except RuntimeError as error:
        if not interruption_within(error):
            raise
        print("error: interrupted", file=sys.stderr)
        sys.exit(130)
    except BrokenPipeError:
        # the reader went away (`| head`): nothing more to say, and nothing more to flush
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        sys.exit(EXIT_BROKEN_PIPE)
    except SystemExit:
        if isinstance(sys.stdout, PacifyFlushWrapper):  # typer met the closed pipe in a command: it wraps
            sys.exit(EXIT_BROKEN_PIPE)                  # stdout so nothing is said at exit, and exits 1
        raise
    sys.exit(code if isinstance(code, int) else 0)
