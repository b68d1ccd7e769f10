"""Terraform habits a plant engineer brings along: targeting warnings, what leaves the plant file
stays on the hardware, drift reported as drift, colour on terminals, whole tables when piped,
shell completion."""

from __future__ import annotations

import fcntl
import itertools
import json
import os
import re
import shlex
import struct
import subprocess
import sys
import termios

import yaml
from emulated import DEMO, run_cli

from prc3cfg.core import render


def edit(plant, change) -> None:
    document = yaml.safe_load(plant.path.read_text())
    change(document)
    plant.path.write_text(yaml.safe_dump(document, sort_keys=False))


def test_a_targeted_plan_and_apply_say_that_the_rest_is_left_out(plant, capsys):
    planned = run_cli(capsys, "plan", plant.path, "--module", "booth-a-top")
    assert planned.out.startswith("⚠ Only booth-a-top (--module): the rest of the plant file is left out of "
                                  "this plan")
    applied = run_cli(capsys, "apply", plant.path, "--module", "booth-a-top", "--auto-approve",
                      "--allow-axis-release")
    assert applied.code == 0 and applied.out.startswith("⚠ Only booth-a-top (--module)")


def test_modules_and_kept_programs_that_leave_the_plant_file_stay_on_the_hardware(plant, capsys):
    assert run_cli(capsys, "apply", plant.path, "--auto-approve", "--allow-axis-release").code == 0

    def remove(document):
        booth_b = document["buses"][1]
        booth_b["modules"] = [m for m in booth_b["modules"] if m["name"] != "booth-b-pretreat"]
        right = next(m for m in booth_b["modules"] if m["name"] == "booth-b-right")
        del right["programs"][4]  # under keep

    edit(plant, remove)
    result = run_cli(capsys, "plan", plant.path, "--detailed-exitcode")
    assert result.code == 0  # nothing to write: leaving them alone is not a change
    assert ("Left as it is: booth-b/booth-b-pretreat (address 4) is no longer in the plant file: it "
            "stays on the "
            "hardware as it is, no longer managed") in result.out
    assert ("Left as it is: booth-b/booth-b-right: program 4 no longer in the plant file "
            "(unmanaged_programs: keep): "
            "it stays on the module as it is") in result.out
    assert plant.emulators["booth-b"].module(3).image.program(4).T == 120  # still there, untouched


def test_a_previous_plant_file_says_what_left_it_and_a_broken_one_is_said(plant, capsys, tmp_path):
    previous = tmp_path / "main.yaml"
    previous.write_bytes(plant.path.read_bytes())  # the plant file as it is: nothing has left it
    unchanged = run_cli(capsys, "plan", plant.path, "--previous", previous)
    assert unchanged.code == 0 and "Left as it is" not in unchanged.out
    edit(plant, lambda document: document["buses"][1].update(modules=document["buses"][1]["modules"][:-1]))
    edited = run_cli(capsys, "plan", plant.path, "--previous", previous)
    assert "Left as it is: booth-b/booth-b-pretreat (address 4) is no longer in the plant file" in edited.out
    previous.write_text("plant: [\n")
    broken = run_cli(capsys, "plan", plant.path, "--previous", previous)
    assert broken.code == 1 and broken.err.startswith(f"error: {previous}:"), broken.err


def test_refresh_only_reports_drift_not_a_plan(plant, capsys):
    assert run_cli(capsys, "apply", plant.path, "--auto-approve", "--allow-axis-release").code == 0
    assert run_cli(capsys, "plan", plant.path, "--refresh-only",
                   "--detailed-exitcode").out.startswith("No drift")
    plant.emulators["booth-a"].teach_in(2, 1, 1987)  # taught on the floor
    result = run_cli(capsys, "plan", plant.path, "--refresh-only", "--detailed-exitcode")
    assert result.code == 2
    assert result.out.splitlines() == [
        "~ bus booth-a, module 2 (booth-a-right) drifted from the plant file (file → module):",
        "    program 1 position 2.000 m → 1.987 m",
        "Drift: 1 of 6 modules holds something other than the plant file says.",
    ]
    assert "steps" not in result.out


def test_tables_are_never_cut_when_piped(tmp_path):
    plant = tmp_path / "plant.yaml"
    long_name = "booth-a-left-with-a-name-long-enough-to-overflow-eighty-columns-of-a-narrow-terminal"
    plant.write_text(DEMO.read_text().replace("name: booth-a-left", f"name: {long_name}"))
    shown = subprocess.run([sys.executable, "-m", "prc3cfg", "show", plant], capture_output=True, text=True,
                           env={**os.environ, "COLUMNS": "40"})
    assert shown.returncode == 0, shown.stderr
    assert long_name in shown.stdout and "…" not in shown.stdout


def test_shell_completion_is_offered():
    """What bash asks of the script `--install-completion` installs (the same `--show-completion`
    prints, for the shell it finds running it): its script, then the words that complete a line."""
    env = {key: value for key, value in os.environ.items() if "COMP" not in key}
    script = subprocess.run([sys.executable, "-m", "prc3cfg"], capture_output=True, text=True,
                            env=env | {"_PRC3CFG_COMPLETE": "source_bash"})
    assert (script.returncode == 0 and "_prc3cfg_completion" in script.stdout
            and "complete_bash" in script.stdout)
    asked = env | {"_PRC3CFG_COMPLETE": "complete_bash", "COMP_WORDS": "prc3cfg pl", "COMP_CWORD": "1"}
    completed = subprocess.run([sys.executable, "-m", "prc3cfg"], capture_output=True, text=True, env=asked)
    assert completed.stdout.split() == ["plan"], completed.stderr


def on_a_terminal(args: list, env: dict, columns: int = 0) -> bytes:
    """What `prc3cfg ARGS` writes to stdout when stdout is a terminal (`columns` wide, as the kernel tells
    whoever asks; 0: a size the terminal does not say, as a pseudo-terminal is made)."""
    master, slave = os.openpty()
    fcntl.ioctl(slave, termios.TIOCSWINSZ, struct.pack("HHHH", 24, columns, 0, 0))
    sized = {k: v for k, v in os.environ.items() if k not in ("COLUMNS", "LINES")}  # (pytest-xdist's workers
    process = subprocess.Popen([sys.executable, "-m", "prc3cfg", *map(str, args)], stdout=slave,  # say 80)
                               stderr=subprocess.DEVNULL, env=sized | env)
    os.close(slave)
    chunks = []
    while True:
        try:
            chunk = os.read(master, 65536)
        except OSError:  # the other end closed
            break
        if not chunk:
            break
        chunks.append(chunk)
    process.wait()
    os.close(master)
    return b"".join(chunks)


def shown_lines(raw: bytes) -> list[str]:
    """The lines a terminal shows of `raw`: without its colours, links and carriage returns."""
    return re.sub(r"\x1b\[[0-9;]*m|\x1b\]8;[^\x1b]*\x1b\\", "", raw.decode()).replace("\r", "").splitlines()


def test_plans_are_coloured_on_a_terminal_unless_no_color(tmp_path):
    """Coloured on a terminal that shows colour, whatever TERM the tests run under (a maintainer's editor
    shell, `env -i`, a CI runner may say "dumb"); not with NO_COLOR, nor on a terminal that says it is dumb,
    nor into a pipe."""
    plant = tmp_path / "plants" / "demo-line.yaml"
    plant.parent.mkdir()
    plant.write_text(DEMO.read_text())
    env = {"PRC3CFG_LOCK_DIR": str(tmp_path / "locks"), "TERM": "xterm-256color"}
    coloured = on_a_terminal(["plan", plant], env)
    assert b"\x1b[32m    + program 1: position" in coloured  # what the plan sets up: green
    assert b"\x1b[3" not in on_a_terminal(["plan", plant], env | {"NO_COLOR": "1"})
    assert b"\x1b[3" not in on_a_terminal(["plan", plant], env | {"TERM": "dumb"})
    piped = subprocess.run([sys.executable, "-m", "prc3cfg", "plan", plant], capture_output=True,
                           env={**os.environ, **env})
    assert b"\x1b[" not in piped.stdout


def test_a_plan_on_a_terminal_breaks_its_long_lines_between_fields_and_a_pipe_keeps_them_whole(tmp_path):
    """On an 80-column terminal, the demo's plan has no line the terminal would break itself (mid-word, going
    on at its first column): a diff line of 198 characters is broken after its commas, the lines after its
    first under its first field, coloured as it is; so are the plans and the account of an apply, and what
    `read` read. Into a pipe (a log, grep) each change stays one line."""
    plant = tmp_path / "plant.yaml"
    plant.write_text(DEMO.read_text())
    env = {"PRC3CFG_LOCK_DIR": str(tmp_path / "locks"), "TERM": "xterm-256color"}
    piped = subprocess.run([sys.executable, "-m", "prc3cfg", "plan", plant], capture_output=True, text=True,
                           env={**os.environ, **env}, check=True).stdout.splitlines()
    whole = next(line for line in piped if line.startswith("    + program 3: ") and "F2 " in line)
    assert len(whole) > 150 and max(map(len, piped)) > 150
    raw = on_a_terminal(["plan", plant], env, columns=80)
    lines = shown_lines(raw)
    assert lines and all(len(line) < 80 for line in lines), max(lines, key=len)
    at = lines.index(whole[:whole.index(",") + 1] + whole[whole.index(",") + 1:].split(",")[0] + ",")
    block = [lines[at], *itertools.takewhile(lambda line: re.match(r" {17}\S", line), lines[at + 1:])]
    assert len(block) > 2 and " ".join(block).split() == whole.split()
    green = "\x1b[32m"
    assert all(f"{green}{line}" in raw.decode() for line in block), raw
    # each whole on a terminal wide enough for it
    assert whole in shown_lines(on_a_terminal(["plan", plant], env, columns=300))
    # and so are the plans `apply --auto-approve` shows each line's as its writes begin, and its account
    lines = shown_lines(on_a_terminal(["apply", plant, "--auto-approve", "--allow-axis-release"], env,
                                      columns=80))
    assert "Apply complete" in " ".join(lines) and sum("Writing bus" in line for line in lines) == 2
    assert all(len(line) < 80 or os.sep in line.split()[-1] for line in lines), lines  # a path is not broken
    # and what `read` read (a module's system parameters: 261 characters)
    lines = shown_lines(on_a_terminal(["read", plant], env, columns=80))
    assert sum("system: upper reversing point" in line for line in lines) == 6
    assert all(len(line) < 80 for line in lines), max(lines, key=len)


#: Module names a plant file may hold that rich, which draws prc3cfg's terminal output, would take for its own
#: markup or emoji codes: a style, a closing tag with nothing open, a link, an emoji.
MARKUP_NAMES = ["left [red]x[/]", "right [/bold]", "top [link=https://example.com]y", "b-left :smile:"]


def test_names_that_look_like_rich_markup_or_emoji_codes_are_shown_as_written(tmp_path):
    """`show`, `show --module` (whose heading and tables rich draws) and `plan` print each name exactly as the
    plant file has it, on a terminal and into a pipe: `show` ended in a traceback (rich's MarkupError), and a
    plan on a terminal showed ":smile:" as an emoji."""
    document = yaml.safe_load(DEMO.read_text())
    modules = [m for bus in document["buses"] for m in bus["modules"]]
    for module, name in zip(modules, MARKUP_NAMES):
        module["name"] = name
    plant = tmp_path / "plant.yaml"
    plant.write_text(yaml.safe_dump(document, sort_keys=False))
    env = {"PRC3CFG_LOCK_DIR": str(tmp_path / "locks"), "TERM": "xterm-256color"}
    for args in (["show", plant], *(["show", plant, "--module", name] for name in MARKUP_NAMES),
                 ["plan", plant]):
        piped = subprocess.run([sys.executable, "-m", "prc3cfg", *map(str, args)], capture_output=True,
                               text=True, env={**os.environ, **env})
        assert piped.returncode in (0, 2) and "Traceback" not in piped.stderr, (args, piped.stderr)
        on_screen = "\n".join(shown_lines(on_a_terminal(args, env, columns=200)))
        for said in (piped.stdout, on_screen):
            named = [name for name in MARKUP_NAMES if name in said]
            assert named == (MARKUP_NAMES if len(args) != 4 else [args[3]]), (args, said)
            assert "😄" not in said


def test_show_renders_a_saved_plan_as_plan_showed_it_from_its_bytes(plant, capsys, tmp_path):
    made = tmp_path / "plan.json"
    planned = run_cli(capsys, "plan", plant.path, "--out", made)
    shown = run_cli(capsys, "show", made)
    # what show adds: the review is the text of its digests
    assert shown.code == 0 and f"\n{render.REVIEW_AS_WRITTEN}\n" in shown.out
    written = f"Plan written to {made}; apply it with: prc3cfg apply --plan {made}\n"
    assert shown.out.replace(f"{render.REVIEW_AS_WRITTEN}\n", "") == planned.out.replace(written, "")
    document = json.loads(made.read_text())
    # a lie beside the bytes
    document["buses"][0]["modules"][0]["steps"][1]["summary"] = "harmless, look away"
    made.write_text(json.dumps(document))
    lied = run_cli(capsys, "show", made).out
    assert ("harmless, look away" not in lied
            and "booth-a/booth-a-left was changed after the plan was made" in lied)
    markdown = run_cli(capsys, "show", made, "--markdown")
    assert markdown.out.startswith("<!-- prc3cfg-plan -->") and "`plan.json`" not in markdown.out
    document["buses"][0]["modules"][0]["steps"][0]["releases_axes"] = False
    made.write_text(json.dumps(document))
    refused = run_cli(capsys, "show", made)
    assert refused.code == 1 and "says releases_axes: false, but 20h releases the axes" in refused.err


def test_times_are_taken_as_durations(plant, capsys):
    from prc3cfg.cli.durations import parse_duration

    assert [parse_duration(t) for t in ("5s", "2m", "1h", "30", "0.5", "500ms", "1.5m")] == [5, 120, 3600, 30,
                                                                                             0.5, 0.5, 90]
    assert run_cli(capsys, "plan", plant.path, "--lock-timeout", "2m").code == 0


def every_command(command=None, path=("prc3cfg",)):
    """(path, click command) of every command, sub-commands of groups included."""
    import typer

    from prc3cfg.cli import _register_commands, app

    _register_commands()
    command = command or typer.main.get_command(app)
    for name, sub in getattr(command, "commands", {}).items():
        if hasattr(sub, "commands"):
            yield from every_command(sub, (*path, name))
        else:
            yield (*path, name), sub


def test_the_help_names_what_to_give_in_words():
    """`--module NAME`, `--trace FILE`, `PLANT`: never `<list[str]>`, `<path>`, `<float range>`, `{plant}`
    (typer braces a required argument in the usage line and writes its type after it in the list:
    `{PLANT}`, `PLANT <path>`)."""
    helps = {" ".join(path): command.get_help(command.context_class(command, info_name=" ".join(path)))
             for path, command in every_command()}
    for path, text in helps.items():
        options = text.split("\nOptions:\n", 1)[-1]
        assert not re.search(r"<[a-z]", options) and "plant" not in text.split("\n", 1)[0], text
        # an option starts its line, a wrapped help line does not
        metavars = re.findall(r"^  (?:-\w, )?--[\w-]+ (\S+)", options, re.M)
        assert all(m == m.upper() or "|" in m for m in metavars), (path, metavars)
    assert "Usage: prc3cfg plan [OPTIONS] {PLANT}" in helps["prc3cfg plan"]
    for option in ("--module NAME", "--trace FILE", "--lock-timeout TIME", "--out FILE"):
        assert option in helps["prc3cfg plan"], option


BLOCK_MATPLOTLIB = """\
import sys
class _Blocked:
    def find_spec(self, name, path=None, target=None):
        if name == "matplotlib" or name.startswith("matplotlib."):
            raise ModuleNotFoundError(f"No module named {name!r}")
sys.meta_path.insert(0, _Blocked())
"""


def test_plot_without_the_plot_extra_fails_before_the_line_is_read(plant, tmp_path):
    hidden = tmp_path / "no-matplotlib"
    hidden.mkdir()
    (hidden / "sitecustomize.py").write_text(BLOCK_MATPLOTLIB)
    env = {**os.environ, "PYTHONPATH": str(hidden)}
    trace = tmp_path / "trace.txt"
    for args in (["plan", plant.path, "--module", "booth-a-top", "--plot", tmp_path / "a.svg", "--trace",
                  trace],
                 ["show", plant.path, "--module", "booth-a-top", "--plot", tmp_path / "a.svg"]):
        done = subprocess.run([sys.executable, "-m", "prc3cfg", *map(str, args)], capture_output=True,
                              text=True, env=env)
        assert (done.returncode, done.stdout) == (1, "")
        assert done.stderr == ("error: plotting needs matplotlib, which the Python running prc3cfg does not "
                               "have — install it there: "
                               f"{shlex.quote(sys.executable)} -m pip install matplotlib\n")
        assert not trace.exists() or trace.read_text() == ""  # not one frame on the line
