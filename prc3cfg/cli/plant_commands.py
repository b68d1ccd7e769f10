"""`prc3cfg validate`, `show` and `schema`: plant files checked, explained and described.

- `validate PLANT`: "PLANT: valid (N buses, M modules)", exit 0; or every problem on
  stderr, one `error: file:line:column: …` line each, exit 1. `--format github` says the
  problems as GitHub workflow-command annotations (`::error file=…,line=…,col=…::…`, on stdout),
  `--format json` as a JSON list of {file, line, column, message} (line and column null for
  a problem of the whole file; `[]` when valid): the exit codes are the same. `--json` is
  `--format json`, as the other commands spell it.
- `show PLANT [--module NAME]`: a module's effective configuration in human units, each
  value with its device value and where it came from (default, profile NAME, module);
  without `--module`, the plant's modules. `--plot FILE.svg|png` draws the module's chains
  instead (`prc3cfg.core.plot`; the `plot` extra), and `--actual FILE` (a `read --json` file)
  overlays what the module holds as before, against what the plan leaves it holding.
- `schema`: the plant file's JSON Schema (draft-07), as `schemas/plant.schema.json` holds it.
"""

import enum
import sys
from pathlib import Path
from typing import TYPE_CHECKING, Annotated

import typer

from prc3cfg.cli import app, click_errors
from prc3cfg.cli.common import (
    FramesOpt,
    OutFileOpt,
    PlantArg,
    check_output,
    printed_or_written,
    stdout_console,
)
from prc3cfg.errors import UserError

if TYPE_CHECKING:  # imported when a command runs: `prc3cfg --help` stays quick
    from rich.console import Console
    from rich.table import Table

    from prc3cfg.api import PolicyReport
    from prc3cfg.core import render
    from prc3cfg.plant import Module, Plant
    from prc3cfg.plant.problems import Finding


class Format(enum.StrEnum):
    """How `validate` says the problems: for a person, for GitHub Actions, for a program."""

    TEXT = "text"
    GITHUB = "github"
    JSON = "json"


@app.command()
def validate(
    ctx: typer.Context,
    plant: PlantArg,
    fmt: Annotated[Format, typer.Option("--format", metavar="text|github|json", help=(
        "text: one line per problem on stderr; github: workflow-command annotations at file:line:col (CI); "
        "json: a list of {file, line, column, message}."))] = Format.TEXT,
    json_out: Annotated[bool, typer.Option("--json",
                                           help="The same as --format json "
                                                "(schemas/validate.schema.json).")] = False,
) -> None:
    """Check a plant file offline: structure, ranges, P ≤ S1, S5 ≤ V ≤ S4, chains, unique names."""
    import json

    from prc3cfg import api
    from prc3cfg.plant import PlantError

    if json_out and fmt is Format.GITHUB:
        raise click_errors.UsageError("--json is --format json — give one of them", ctx=ctx)
    if json_out:
        fmt = Format.JSON

    file = plant
    try:
        loaded = api.load(plant)
        file = loaded.policy_path or plant
        # the policy file's problems, then what its envelopes find (windows judge an apply's moment)
        judged = api.policy(loaded)
    except PlantError as error:
        if fmt is Format.TEXT:
            raise  # one `error:` line per problem, as every error
        findings = error.findings(str(file))
        if fmt is Format.JSON:
            print(json.dumps([{"file": f.file, "line": f.line, "column": f.column, "message": f.message}
                              for f in findings], indent=1))
        else:
            print("\n".join(github_annotation(f) for f in findings))
        raise typer.Exit(1) from None
    if _envelopes_refuse(None if judged is None else judged.only("envelope"), fmt):
        raise typer.Exit(1)
    if fmt is Format.JSON:
        return
    modules = len(loaded.modules())
    print(f"{plant}: valid ({_count(len(loaded.buses), 'bus', 'buses')}, "
          f"{_count(modules, 'module', 'modules')})")


def _envelopes_refuse(judged: "PolicyReport | None", fmt: Format) -> bool:
    """Say what the policy's envelopes found, in `fmt`; whether a hard one refuses the plant file. JSON lists
    the hard ones only: they are its problems (`[]`, valid, as before); the others are warnings (stderr,
    `::warning`)."""
    import json

    found = [] if judged is None else judged.placed
    hard = [at for f, at in found if f.level == "hard"]
    if fmt is Format.JSON:
        print(json.dumps([{"file": f.file, "line": f.line, "column": f.column, "message": f.message}
                          for f in hard], indent=1))
    elif fmt is Format.GITHUB:
        for f, at in found:
            print(github_annotation(at, "error" if f.level == "hard" else "warning"))
    else:
        for f, line in () if judged is None else judged.findings:
            print(f"{'error' if f.level == 'hard' else 'warning'}: {line}", file=sys.stderr)
    return judged is not None and judged.fails_plan


def github_annotation(finding: "Finding", kind: str = "error") -> str:
    """A problem as GitHub's `::error` (or `::warning`) workflow command, escaped as its rules want
    (`prc3cfg.core.text`)."""
    from prc3cfg.core.text import github_data, github_property

    place = "" if finding.line is None else f",line={finding.line},col={finding.column}"
    file, message = github_property(finding.file), github_data(finding.message)
    return f"::{kind} file={file}{place},title=prc3cfg::{message}"


@app.command()
def show(
    plant: Annotated[Path, typer.Argument(metavar="PLANT",
                                          help="The plant file (YAML), or a plan file (JSON) made by "
                                               "plan --out.", show_default=False)],
    module: Annotated[str | None,
                      typer.Option("--module", "-m", metavar="NAME",
                                   help="The module to show, by name.")] = None,
    json_out: Annotated[bool, typer.Option("--json", help="A plan file: print it as JSON.")] = False,
    markdown: Annotated[bool, typer.Option("--markdown",
                                           help="A plan file: print it as markdown (PR comments).")] = False,
    max_chars: Annotated[int, typer.Option("--max-chars", min=1000, metavar="N",
                                           help="--markdown: at most this many characters.")] = 65_000,
    plot: Annotated[Path | None, typer.Option(metavar="FILE",
        help="Draw the module's chains (position against time, F1/F2 bands) to this .svg or "
             ".png file.")] = None,
    actual: Annotated[Path | None, typer.Option(metavar="FILE",
        help="With --plot: overlay what the module holds (images saved by `read --json`) as before.")] = None,
    frames: FramesOpt = False,
) -> None:
    """Print a module's effective configuration and where each value came from, or draw its chains;
    or show a saved plan file as `plan` shows a plan (human, --json, --markdown)."""
    if plant.suffix == ".json":
        _show_plan_file(plant, json_out=json_out, markdown=markdown, max_chars=max_chars, frames=frames)
        return
    from prc3cfg import api

    if plot is not None:
        fmt = api.plot_format(plot)
        if module is None:
            raise UserError("--plot draws one module — name it with --module NAME")
        check_output(plot, "--plot", plant=plant)
    elif actual is not None:
        raise UserError("--actual is what --plot overlays — give --plot FILE.svg or FILE.png too")
    loaded = api.load(plant)
    if module is None:
        stdout_console().print(_modules_table(loaded))
        return
    found = {m.name: (bus.name, m) for bus, m in loaded.modules()}
    if module not in found:
        raise UserError(f"{plant}: no module named '{module}' — the modules are {', '.join(found)}")
    bus, chosen = found[module]
    if plot is None:
        _show_module(stdout_console(), bus, chosen)
        return
    _plot_module(loaded, chosen, plot, fmt, actual)


def _show_plan_file(path: Path, *, json_out: bool, markdown: bool, max_chars: int, frames: bool) -> None:
    """A saved plan file as the plan was shown — its steps' summaries worked out again from their bytes."""
    import json

    from prc3cfg import api
    from prc3cfg.cli.common import print_lines
    from prc3cfg.core import render

    document = api.plan_document(path)
    if json_out:
        print(json.dumps(document, indent=1))
    elif markdown:
        # its line end is counted in the budget
        print(render.markdown(document, max_chars=max_chars, full_plan=f"`{path.name}`", frames=frames),
              end="")
    else:
        print_lines(render.human(document, frames=frames))


@app.command()
def schema(out: OutFileOpt = None) -> None:
    """Print the JSON Schema of plant files (draft-07; schemas/plant.schema.json)."""
    from prc3cfg.plant import plant_schema_text

    printed_or_written(plant_schema_text(), out)


def _count(n: int, one: str, many: str) -> str:
    return f"{n} {one if n == 1 else many}"


def _modules_table(plant: "Plant") -> "Table":
    from prc3cfg.core import render

    return _drawn(render.modules_table(plant.name, (
        render.ModuleRow(bus.name, m.address, m.name, m.profiles, tuple(m.settings.programs),
                         m.unmanaged_programs)
        for bus, m in plant.modules())))


def _show_module(console: "Console", bus: str, module: "Module") -> None:
    """What `render.shown_module` says of the module, from the values of its plant file and where each came
    from."""
    from rich.text import Text

    from prc3cfg.core import render
    from prc3cfg.plant.profiles import Sourced

    settings = module.settings
    jumps = settings.jumps()
    shown = render.shown_module(render.Settings(
        name=module.name, bus=bus, address=module.address, profiles=module.profiles,
                                                unmanaged_programs=module.unmanaged_programs,
        system=module.desired_system(), programs=module.desired_programs(),
        sources={"unmanaged_programs": settings.unmanaged_programs.source, "chains": settings.chains.source,
                 **{key: value.source for key, value in settings.system.items()}},
        program_sources={number: {**{key: fields[key].source for key in fields},
                                  "jump": jumps.get(number, Sourced(0)).source}
                         for number, fields in settings.programs.items()},
        chains=tuple((chain.programs, chain.loop) for chain in settings.chains.value),
    ))
    before, name, after = shown.heading
    console.print(Text.assemble(before, (name, "bold"), after))
    for block in shown.blocks:
        console.print(block if isinstance(block, str) else _drawn(block, no_wrap=True))


def _drawn(table: "render.Table", *, no_wrap: bool = False) -> "Table":
    """A table of `show` drawn for the terminal: a line under the head and between its sections."""
    from rich import box
    from rich.table import Table

    drawn = Table(title=table.title, title_justify="left", box=box.SIMPLE_HEAD)
    for column in table.columns:
        drawn.add_column(column, no_wrap=no_wrap)
    for section in table.sections:
        for i, row in enumerate(section):
            drawn.add_row(*row, end_section=i == len(section) - 1)
    return drawn


def _plot_module(plant: "Plant", module: "Module", path: Path, fmt: str, actual: Path | None) -> None:
    """Draw the module's chains as the plant file says them; with `actual`, what it holds now as
    before and what the plan leaves it holding as after (`prc3cfg.api.picture`)."""
    from prc3cfg import api
    from prc3cfg.cli.output import write_picture

    images = None if actual is None else api.load_images(actual, plant, [module.name])
    write_picture(path, api.picture(plant, module.name, fmt=fmt, images=images), module.name)

