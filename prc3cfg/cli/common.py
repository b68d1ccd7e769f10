"""What the commands share: option types, output paths checked before the line, progress on the
terminal, and the `LineOptions` every line-using command hands to `prc3cfg.api`."""

from __future__ import annotations

import contextlib
import enum
import os
import stat
import sys
import tempfile
from collections.abc import Callable, Iterable, Iterator
from pathlib import Path
from typing import TYPE_CHECKING, Annotated, Any, TextIO

import typer

from prc3cfg.cli.durations import TIMES, duration
from prc3cfg.errors import UserError
from prc3cfg.shell.cancel import Cancellation
from prc3cfg.shell.platform import command_line, open_text

if TYPE_CHECKING:  # what the commands use when they run is imported then: `prc3cfg --help` stays quick
    from rich.console import Console
    from rich.progress import Progress, TaskID

    from prc3cfg.api import LineOptions
    from prc3cfg.api import Progress as LineProgress
    from prc3cfg.shell.link.client import Link

#: The framings, as option help names them (a test checks them against `prc3cfg.core.framing.FRAMINGS`).
FRAMING_NAMES = ("crc16", "open-driver", "stx")
#: Module addresses on a line (`prc3cfg.core.image.MAX_MODULE_ADDRESS`, checked by the same test).
ADDRESSES = range(1, 31)
#: Character formats (`prc3cfg.core.line`, checked by the same test).
PARITY_NAMES = ("none", "odd", "even")
#: A PRC 3 line's data bits: always 8 (`prc3cfg.core.line.FRAME_DATA_BITS`, checked by the same test).
DATA_BITS = (8,)
STOP_BITS = (1, 1.5, 2)


def one_of(allowed: tuple) -> Callable[[Any], Any]:
    """An option's callback: a value outside `allowed` is a usage error (exit 64), as click words it."""

    def check(value: Any) -> Any:
        if value is not None and value not in allowed:
            raise typer.BadParameter(f"{value!r} is not one of {', '.join(map(str, allowed))}")
        return value

    return check


def frame_data_bits(value: Any) -> Any:
    """`--data-bits`'s callback: anything but 8 is a usage error, in the words a plant file's `data_bits`
    gets."""
    if value is not None and value not in DATA_BITS:
        raise typer.BadParameter(f"{value} data bits cannot carry a PRC 3 frame — its frames are binary and "
                                 "need 8 data bits: "
                                 "give 8 or leave the option out")
    return value


class VerifyChoice(enum.StrEnum):
    """`--verify`: the values of `prc3cfg.shell.apply.Verify` (checked by the same test)."""

    FLOOR = "floor"
    FULL = "full"


#: Colours of a plan's lines on a terminal, by how the line starts (after its indentation).
COLOURS = {"+": "green", "-": "red", "~": "yellow", "⚠": "bold red", "✗": "red", "✓": "green"}


def console(**options: Any) -> Console:
    """A rich console for prc3cfg's output, which draws every string as the text it is: names and words from
    files are data — rich's markup ("[/]": a traceback) and emoji codes (":smile:") are read in none."""
    from rich.console import Console

    return Console(markup=False, emoji=False, **options)


def stderr_console() -> Console:
    return console(stderr=True)


def may_be_terminal(stream: TextIO) -> bool:
    """Whether rich could take `stream` for a terminal: it is one, or TTY_COMPATIBLE or FORCE_COLOR
    tells rich to treat any stream as one. Where not, rich is not imported (16 ms; its progress bar 22)."""
    return stream.isatty() or bool({"TTY_COMPATIBLE", "FORCE_COLOR"} & os.environ.keys())


def print_lines(text: str) -> None:
    """Print plan or account text: on a terminal, each line broken for its width (`render.hanging`) and
    coloured by its leading symbol (not under NO_COLOR, which rich honours); piped, plain, a line of the
    text a line of output (grep finds a change whole) — without importing rich where it could not take
    stdout for a terminal (`may_be_terminal`). Plain, it is one write (as `TerminalProgress.note`'s): the
    lines' threads may note their plans meanwhile."""
    if may_be_terminal(sys.stdout):
        from prc3cfg.core.render.words import hanging

        terminal = console(highlight=False)
        if terminal.is_terminal:
            width = _width(sys.stdout)
            for line in text.splitlines():
                style = None if terminal.no_color else COLOURS.get(line.lstrip()[:1])
                for part in hanging(line, width):
                    terminal.print(part, style=style, soft_wrap=True)
            return
    print(f"{text}\n", end="")


def stdout_console() -> Console:
    """A console for tables on stdout: the terminal's width there; piped or redirected, as wide as the
    table needs — never cut (colour follows the terminal, and NO_COLOR is honoured)."""
    drawn = console()
    return drawn if drawn.is_terminal else console(width=1_000, soft_wrap=True)
#: Ctrl-C and SIGTERM for the running command (`main` installs the handlers).
CANCEL = Cancellation()

#: Bytes written and flushed in the folder of an output file before any time on the line:
#: a full disk or a read-only folder says so then, not after the read-back.
PROBE = 4096
#: Linux's /dev/full (character device 1:7): every write fails with "no space left on device".
DEV_FULL = (1, 7)


def check_output(path: Path | None, option: str, *, plant: Path | None = None) -> Path | None:
    """Refuse in one line — before any time is spent on the line — an output that cannot be written:
    a directory, a missing folder, a read-only or full one, /dev/full, the plant file itself."""
    if path is None:
        return None
    from prc3cfg.api import device_number as _device_number

    where = f"{option} {path}"
    try:
        found = os.stat(path)
    except FileNotFoundError:
        found = None
    except OSError as error:
        raise UserError(f"{where}: {error.strerror} — name a file in a folder you can write to") from None
    if found is not None:
        if stat.S_ISDIR(found.st_mode):
            raise UserError(f"{where} is a directory — name a file in it")
        if plant is not None and plant.exists() and os.path.samefile(path, plant):
            raise UserError(f"{where} is the plant file itself — name another file")
        if stat.S_ISCHR(found.st_mode) and _device_number(found) == DEV_FULL:
            raise UserError(f"{where}: no space left on device — name a file on a disk with space")
        if not stat.S_ISREG(found.st_mode):
            return path  # a device or a FIFO (/dev/stdout, a pipe): written as it is
    folder = path.parent
    if not folder.is_dir():
        raise UserError(f"{where}: the folder {folder} does not exist — create it, or name a file in an "
                        "existing folder")
    try:
        fd, probe = tempfile.mkstemp(prefix=".prc3cfg-probe-", dir=folder)
        try:
            os.write(fd, bytes(PROBE))
            os.fsync(fd)
        finally:
            os.close(fd)
            os.unlink(probe)
    except OSError as error:
        raise UserError(f"{where}: cannot write in {folder} ({error.strerror}) — name a file on a disk and "
                        "in a folder you can write to") from None
    return path


def write_output(path: Path, text: str, option: str) -> None:
    """Write an output file: a regular file atomically, a device or FIFO as it is; one line if it fails."""
    from prc3cfg.shell.files import write_atomically  # json, secrets and tempfile: not for `--help`

    try:
        if path.exists() and not path.is_file():
            with open_text(path) as handle:
                handle.write(text)
        else:
            write_atomically(path, text)
    except OSError as error:
        raise UserError(f"{option} {path}: cannot write it ({error.strerror}) — nothing was "
                        "saved there") from None


def _output_option(option: str) -> Callable[[Path | None], Path | None]:
    return lambda value: check_output(value, option)


#: `--out FILE` of a command that prints a file (import, schema): written as UTF-8 whatever the shell —
#: Windows PowerShell 5.1's `>` writes UTF-16, which no plant file may be.
OutFileOpt = Annotated[Path | None, typer.Option("--out", callback=_output_option("--out"), metavar="FILE",
                                                 help="Write it to FILE (UTF-8), not to stdout.")]


def print_document(document: Any) -> None:
    """A `--json` document on stdout (its `format` first: `prc3cfg-KIND/1`, `schemas/KIND.schema.json`), in
    ASCII as every JSON prc3cfg prints: what it read from a bus or a journal reaches no terminal as a control.
    """
    import json

    print(json.dumps(document, indent=1))


def printed_or_written(text: str, out: Path | None) -> None:
    """`text` printed, or written to `out` (`OutFileOpt`) with a line saying where."""
    if out is None:
        sys.stdout.write(text)
        return
    write_output(out, text, "--out")
    print(f"Written to {out}", file=sys.stderr)


def unanswered(json_out: bool, answered: bool, instead: str) -> str | None:
    """Why `--json` cannot run as asked, or None: a stream of events asks no question (Terraform's `apply
    -json` neither), so the approval must be given on the command line — `--auto-approve`, or what `instead`
    names."""
    if json_out and not answered:
        return f"--json asks no question — pass --auto-approve ({instead})"
    return None


PlantArg = Annotated[Path, typer.Argument(metavar="PLANT", help="The plant file (YAML).", show_default=False)]
ModuleOpt = Annotated[list[str] | None,
                      typer.Option("--module", metavar="NAME", help="Only this module (name); repeatable.")]
TraceOpt = Annotated[
    Path | None,
    typer.Option(callback=_output_option("--trace"), metavar="FILE",
                 help="Write every frame, both directions, with timestamps, in hex."),
]
RetriesOpt = Annotated[int, typer.Option(min=0, max=100, metavar="N",
                                         help="Retries of a lost or damaged reply, per message.")]
FramesOpt = Annotated[bool, typer.Option("--frames",
                                         help="Show each step's bytes as sent, in hex (a plan file always "
                                              "keeps them).")]
LockOpt = Annotated[float, typer.Option("--lock-timeout", parser=duration(0), metavar="TIME",
                                        help="How long to wait while another prc3cfg uses the line "
                                             f"({TIMES}).")]

Key = tuple[str, int]  # (bus name, module address)


def parse_addresses(text: str) -> list[int]:
    """"1,3-5" → [1, 3, 4, 5]; every address must lie in 1..30. ValueError, saying what to write,
    for anything else — an empty entry too ("1,,2", "1,2,", ""): a slip, not "all modules"."""
    addresses: set[int] = set()
    for part in (p.strip() for p in text.split(",")):
        if not part:
            raise ValueError(f"'{text}' has an empty entry — write addresses and ranges between commas, "
                             "e.g. 1,3-5")
        low, _, high = part.partition("-")
        try:
            first, last = int(low), int(high or low)
        except ValueError:
            raise ValueError(f"'{part}' is not an address or a range like 3-5") from None
        if first not in ADDRESSES or last not in ADDRESSES or first > last:
            raise ValueError(f"'{part}' is outside 1..{ADDRESSES[-1]} — module addresses are "
                             f"1..{ADDRESSES[-1]}")
        addresses.update(range(first, last + 1))
    return sorted(addresses)


def addresses_option(value: str | None) -> str | None:
    """`--modules`'s callback: addresses `parse_addresses` cannot read are a usage error (exit 64)."""
    if value is not None:
        try:
            parse_addresses(value)
        except ValueError as error:
            raise typer.BadParameter(str(error)) from None
    return value


def _time_left() -> Any:
    """A rich column: the time left in the phase at its rate so far — the steps to go at the seconds a
    step has taken on average since the phase began, counting down between steps ("0:00:12 left");
    "-:--:-- left" until a step is done. Measured on this line, so a line slower than its settings
    shows here what the plan's estimate did not; steps of unequal size (a module with 64 programs to
    read beside one with none) make it a rate, not a promise."""
    from rich.progress import ProgressColumn, Task
    from rich.text import Text

    class TimeLeft(ProgressColumn):
        def render(self, task: Task) -> Text:
            stepped = task.fields.get("stepped")
            if not task.completed or stepped is None or task.start_time is None or task.total is None:
                return Text("-:--:-- left", style="progress.remaining")
            per_step = (stepped - task.start_time) / task.completed
            left = max(0, round(per_step * (task.total - task.completed) - (task.get_time() - stepped)))
            return Text(f"{left // 3600}:{left // 60 % 60:02d}:{left % 60:02d} left",
                        style="progress.remaining")

    return TimeLeft()


class TerminalProgress:
    """`api.Progress` on the terminal: a rich progress bar on stderr (when it is a terminal) with the
    phase's steps, time taken and time left (`_time_left`), notes on stdout. `stop` takes the bar off
    the screen — before the plan and before a question (`ask`) — and the next phase's `start` shows it again.
    """

    def __init__(self, stack: contextlib.ExitStack, notes: TextIO | None = None) -> None:
        self._bar: Progress | None = None
        self._task: TaskID | None = None
        self._notes = notes  # None: stdout (as it is when the note is written)
        stack.callback(self.stop)

    def start(self, what: str, total: int) -> None:
        if self._bar is None and not may_be_terminal(sys.stderr):  # a bar nobody sees
            return
        from rich.progress import (
            BarColumn,
            MofNCompleteColumn,
            Progress,
            TextColumn,
            TimeElapsedColumn,
        )

        if self._bar is None:
            stderr = stderr_console()
            self._bar = Progress(
                TextColumn("{task.description}"), BarColumn(), MofNCompleteColumn(), TimeElapsedColumn(),
                                 _time_left(),
                console=stderr, transient=True, disable=not stderr.is_terminal,
            )
            self._bar.start()
        if self._task is not None:
            self._bar.remove_task(self._task)
        self._task = self._bar.add_task(what, total=total)

    def advance(self) -> None:
        # another thread may `stop` it meanwhile: a stopped bar takes the step unseen
        bar, task = self._bar, self._task
        if bar is not None and task is not None:
            bar.update(task, advance=1, stepped=bar.get_time())

    def note(self, text: str) -> None:
        # one write, its newline in it: the lines' threads note their plans at once, and print's two
        # writes let another line's text in before a newline ("…pretreatWriting bus booth-a now")
        stream = self._notes or sys.stdout
        print(f"{broken_for(stream, text)}\n", end="", flush=True, file=stream)

    def stop(self) -> None:
        """The bar off the screen, its lines cleared (nothing drawn until the next `start`)."""
        if self._bar is not None:
            self._bar.stop()
            self._bar = self._task = None


#: What `ask` takes for yes and for no (as click's confirm); an empty answer is no.
YES, NO = ("y", "yes"), ("n", "no", "")
#: The one answer a question about the machine takes (`ask(..., typed=True)`), as Terraform's apply: anything
#: else is no.
TYPED_YES = "yes"


def _answering_terminal() -> TextIO:
    """The terminal answers come from (stdin's), opened to write to — not stdout, which may be a file."""
    from prc3cfg.api import terminal_path

    return open_text(terminal_path(sys.stdin.fileno()))


def to_the_terminal(text: str) -> None:
    """`text` written to the terminal answers come from, beside stdout in a file: a question's subject."""
    with _answering_terminal() as terminal:
        terminal.write(broken_for(terminal, text) + "\n")


def broken_for(stream: TextIO, text: str) -> str:
    """`text` with each line broken for the terminal `stream` is, as `print_lines` breaks it."""
    from prc3cfg.core.render.words import hanging

    width = _width(stream)
    return "\n".join(part for line in text.split("\n") for part in hanging(line, width))


def _width(stream: TextIO) -> int:
    """How wide lines may be on the terminal `stream` is (`render.hanging`): its columns — COLUMNS where set,
    as rich and shutil take it — but one, spare where a terminal draws ⚠ two columns wide; 0 (lines whole)
    where `stream` is no terminal or does not tell its size."""
    try:
        if not stream.isatty():
            return 0
        columns = os.environ.get("COLUMNS", "")
        return (int(columns) if columns.isdigit() else os.get_terminal_size(stream.fileno()).columns) - 1
    except (OSError, ValueError):
        return 0


def ask(question: str, options: LineOptions | None = None, *, typed: bool = False) -> bool:
    """A yes/no question, default no, asked whole where the operator sees it: every question goes
    through here. The progress display of `options` is taken off the screen first (a bar redrawn
    below or over the question hid it), what was printed is flushed, and the question is written to
    the terminal the answer comes from (stdin's) — not to stdout, which may be a file. An answer
    that is neither yes nor no is asked again; the end of input is no. `typed`: a question whose yes
    sends frames that can change a module — only `yes` typed out is yes, anything else no at once."""
    if options is not None and isinstance(options.progress, TerminalProgress):
        options.progress.stop()
    sys.stdout.flush()
    sys.stderr.flush()
    with _answering_terminal() as terminal:
        if typed:
            terminal.write(f"{question} Only '{TYPED_YES}' will be accepted: ")
            terminal.flush()
            return sys.stdin.readline().strip() == TYPED_YES
        while True:
            terminal.write(f"{question} [y/N]: ")
            terminal.flush()
            line = sys.stdin.readline()
            answer = line.strip().lower()
            if not line or answer in NO:
                return False
            if answer in YES:
                return True
            terminal.write("Answer y or n.\n")


#: The command line `main` runs (`prc3cfg` and its arguments), for the records' header.
COMMAND_LINE: list[str] = []


@contextlib.contextmanager
def line_options(trace: Path | None, retries: int, lock_timeout: float, progress: LineProgress | None = None,
                 *,
                 json_out: bool = False) -> Iterator[LineOptions]:
    """The `LineOptions` of a command: its trace file, Ctrl-C handling, progress on the terminal (or
    `progress`: `--json`'s events; with `json_out` its notes on stderr, stdout kept for the document);
    after a command that succeeded, a note for every line that had to repeat exchanges, and one if a
    line was slower than its settings."""
    from prc3cfg.api import LineOptions

    used: list[Link] = []
    with contextlib.ExitStack() as stack:
        options = LineOptions(
            retries=retries, lock_timeout=lock_timeout, cancel=CANCEL, progress=progress
                              or TerminalProgress(stack, sys.stderr if json_out else None),
            trace=stack.enter_context(open_text(trace, "a")) if trace else None,
            waiting=lambda text: print(text, file=sys.stderr, flush=True), used=used.extend,
            notice=lambda text: print(f"⚠ warning: {text}", file=sys.stderr, flush=True),
            command_line=tuple(COMMAND_LINE) or None,
        )
        yield options
        # a command that talked on no line (`plan --actual`) has nothing to note, and loads nothing for it
        if used:
            note_repeats(used)
            note_slow(used)
            note_unshared(used)


def note_unshared(links: Iterable[Link]) -> None:
    """One line after a command on a real line (not an `emulator://` one) whose records no other user of
    this machine sees: where they are, and the administrator's one command that shares them."""
    from prc3cfg.api import measurable, unshared_records

    if any(measurable(link.port_name) for link in links) and (hint := unshared_records()) is not None:
        print(f"note: {hint}", file=sys.stderr)


def note_repeats(links: Iterable[Link]) -> None:
    """One line per line that had to repeat exchanges: a noisy line is worth knowing about."""
    from prc3cfg.core.render import plural

    for link in links:
        if link.repeated:
            were = "was" if link.repeated == 1 else "were"
            print(f"note: bus {link.bus}: {link.repeated} of {plural(link.exchanges, 'exchange')} {were} "
                  "lost or damaged and "
                  "made again — check the cabling if this is not a test line (--trace shows every frame)",
                  file=sys.stderr)


def note_slow(links: Iterable[Link]) -> None:
    """One line if any line's answered exchanges took clearly longer than the plant file's line settings
    price them (`prc3cfg.core.bustime.slower_than_priced`): the figures, the turnaround they amount to,
    and how to measure the line — estimates, and waits that depend on the turnaround, are that far off."""
    from prc3cfg.api import measurable, slower_than_priced
    from prc3cfg.core.render import plural
    from prc3cfg.core.text import shown

    said, ports = [], []
    for link in slower_than_priced(links):
        assert link.cost is not None  # (priced: `slower_than_priced` says so)
        answer = link.cost.turnaround + (link.answered_time - link.priced_time) / link.answered
        said.append(f"bus {link.bus}: {plural(link.answered, 'exchange')} took {link.answered_time:.1f} s, "
                    "its settings price them at "
                    f"{link.priced_time:.1f} s (the modules answered after {answer * 1000:.0f} ms on "
                    "average, turnaround: "
                    f"{link.cost.turnaround:g} in the plant file)")
        ports.append(shown(link.port_name))
    if not said:
        return
    measured = [command_line("prc3cfg", "doctor", "--port", port) for port in ports if measurable(port)]
    remedies = [f"measure the line with {' and '.join(measured)} and put the bus keys it prints into the "
                "plant file"] if measured else []
    if len(measured) < len(ports):  # an emulator:// port answers as its URL says: doctor cannot reach it
        remedies.append("an emulator:// port's line-speed and turnaround are slower than its bus's keys: "
                        "give both the same")
    print(f"note: the line is slower than the plant file's line settings say — {'; '.join(said)}: "
          f"{'; '.join(remedies)}", file=sys.stderr)
