"""`prc3cfg status PLANT [--json]` and `prc3cfg status serve PLANT --listen opc.tcp://HOST:PORT`.

- `status PLANT`: per line and module, from prc3cfg's records only (no bus traffic) — health, revision
  counter, last verified, drift, pending travel, evidence age; `--json`: the `prc3cfg-status/1` document.
- `status serve`: the same status on OPC UA (`prc3cfg.shell.opcua`, the optional extra `opcua`); without
  asyncua one line saying how to install it.

Arguments and output only: the status is `prc3cfg.api.status`'s.
"""

from pathlib import Path
from typing import Annotated, Any

import typer
from typer.core import TyperGroup

from prc3cfg.cli import app
from prc3cfg.cli.common import PlantArg, print_lines
from prc3cfg.errors import UserError


class _PlantOrServe(TyperGroup):
    """`status PLANT` shows, `status serve PLANT` serves: a first word that is no subcommand is the plant
    file."""

    def parse_args(self, ctx: Any, args: list[str]) -> list[str]:
        if args and args[0] not in self.commands and args[0] not in ("--help", "-h"):
            args = ["show", *args]
        return super().parse_args(ctx, args)


status_app = typer.Typer(cls=_PlantOrServe, no_args_is_help=True, rich_markup_mode=None,
                         help="Configuration status of each line and module, from prc3cfg's records (no bus "
                              "traffic).")
app.add_typer(status_app, name="status")


@status_app.command("show", hidden=True)
def show(plant: PlantArg,
         json_out: Annotated[bool, typer.Option("--json", help="Print a prc3cfg-status/1 "
                                                               "document.")] = False) -> None:
    """Each module's health, revision counter, last verified apply, drift, pending travel and evidence age."""
    import sys

    from prc3cfg import api
    from prc3cfg.cli.common import print_document
    from prc3cfg.core.text import shown

    document = api.status(api.load(plant))
    for note in document["notes"]:
        print(f"note: {shown(note)}", file=sys.stderr)
    if json_out:
        print_document(document)
        return
    print_lines("\n".join(text for line in document["lines"]
                           for text in (f"bus {shown(line['bus'])}: {line['health']}",
                                        *(shown(_module_line(module)) for module in line["modules"]))))


def _module_line(module: dict[str, Any]) -> str:
    last = module["last_verified"]
    verified = "never verified" if last is None else f"verified {last['time']} by {last['by'] or '?'}" + (
        f" at {last['commit'][:12]}" if last["commit"] else "")
    why = f" ({module['why']})" if module["why"] else ""
    return (f"  {module['address']:>2} {module['name']}: {module['health']}{why}, revision "
            f"{module['revision_counter']}, {verified}")


@status_app.command()
def serve(
    plant: PlantArg,
    listen: Annotated[str, typer.Option("--listen", metavar="URL",
                                        help="Where the OPC UA server listens: opc.tcp://HOST:PORT.")],
    certificate: Annotated[Path | None,
                           typer.Option("--certificate", metavar="FILE",
                                        help="The server's certificate (DER or PEM).")] = None,
    private_key: Annotated[Path | None,
                           typer.Option("--private-key", metavar="FILE",
                                        help="The certificate's private key (PEM).")] = None,
    trust: Annotated[Path | None,
                     typer.Option("--trust", metavar="DIR",
                                  help="Folder of client certificates allowed to connect.")] = None,
    allow_anonymous: Annotated[bool, typer.Option("--allow-anonymous",
                                                  help="Let a trusted client in without a user.")] = False,
    no_security: Annotated[bool, typer.Option("--no-security", help=(
        "Serve without signing or encryption (anyone on the network reads it): for a test "
        "bench only."))] = False,
) -> None:
    """Publish the status read-only on OPC UA under Objects/DeviceSet (DI), updated as the records change."""
    import sys

    from prc3cfg import api
    from prc3cfg.cli.common import CANCEL

    if (certificate is None) != (private_key is None):
        raise UserError("--certificate and --private-key go together: give both, or neither to use the one "
                        "made in the state folder")
    if not no_security and trust is None:
        raise UserError("--trust DIR is needed: the folder of client certificates allowed to connect (or "
                        "--no-security on a test bench)")
    if no_security:
        print("warning: --no-security: the status is served without signing or encryption — anyone who "
              "reaches the port reads it",
              file=sys.stderr)
    loaded = api.load(plant)
    api.serve_status(loaded, listen, certificate=certificate, private_key=private_key, trust=trust,
                     allow_anonymous=allow_anonymous,
                     no_security=no_security, cancel=CANCEL)
