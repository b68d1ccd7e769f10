"""`prc3cfg adopt`: positions taught in on the floor written back into the plant file, in place.

Against real emulators (`prc3cfg.shell.testing`, through tests/emulated.py) and the real command line:
the plant repository tests/adopt/plant.yaml (comments, flow and block mappings, quoted names) is
applied, positions are taught in on the emulated modules, and adopt must change exactly the
lines of those values — in the module, in the profile when every user drifted alike, as an
override otherwise — after which validate passes and plan has nothing to do. The property at
the end adopts random teach-ins on the demo plant without a line (`prc3cfg.plant.adopt` is pure).
"""

from __future__ import annotations

import contextlib
import difflib
import json
import os
import subprocess
import sys
import tempfile
from collections import Counter
from dataclasses import replace
from pathlib import Path

import pytest
from emulated import DEMO, emulated_plant, run_cli
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from prc3cfg import api
from prc3cfg.plant import adopt, splice
from prc3cfg.shell.plant_files import load_plant

REPOSITORY = Path(__file__).resolve().parent / "adopt" / "plant.yaml"


@pytest.fixture
def repository(tmp_path, capsys):
    """The plant repository on emulators, applied: its file (comments and all) beside the emulated copy."""
    (tmp_path / "emulated").mkdir()
    with emulated_plant(tmp_path / "emulated", source=REPOSITORY) as emulated:
        text = REPOSITORY.read_text()
        for name, bus in zip(("adopt-a", "adopt-b"), emulated.plant.buses):
            text = text.replace(f"emulator://{name}", bus.port)
        plant = tmp_path / "plant.yaml"
        plant.write_text(text)
        assert run_cli(capsys, "apply", plant, "--auto-approve", "--allow-axis-release").code == 0
        yield plant, emulated.emulators


def edited(text: str, changes: dict[str, list[str]]) -> list[str]:
    """The lines of `text` with each line that is a key of `changes` replaced by its lines."""
    lines = text.splitlines()
    assert all(lines.count(line) == 1 for line in changes), "each line to change is in the file once"
    return [new for line in lines for new in changes.get(line, [line])]


def test_taught_positions_are_adopted_where_they_came_from_and_nothing_else_changes(repository, capsys):
    plant, emulators = repository
    line_a, line_b = emulators["line-a"], emulators["line-b"]
    for bus, address in ((line_a, 1), (line_a, 2), (line_a, 3), (line_b, 1)):
        bus.teach_in(address, 2, 160)  # every module that takes program 2 from the profile: alike
    line_a.teach_in(1, 3, 1150)        # one user of the profile's program 3: an override
    line_a.teach_in(3, 1, 2050)        # the same in a module written as one flow mapping
    line_a.teach_in(2, 1, 1987)        # the module's own value
    line_b.teach_in(1, 4, 950)         # the module's own value, in a block mapping
    original = plant.read_text()

    checked = run_cli(capsys, "adopt", plant, "--check")
    assert checked.code == 2, checked.err
    assert plant.read_text() == original
    assert checked.out.splitlines()[:5] == [
        "~ profile booth: program 2 position 0.150 m → 0.160 m (every module that takes it from there "
        "holds it: "
        "line-a/a-left, line-a/a-right, line-a/a-top, line-b/b-left)",
        "+ line-a/a-left: program 3 position 1.200 m → 1.150 m (new in the module: profile booth keeps "
        "its value)",
        "~ line-a/a-right: program 1 position 2.000 m → 1.987 m (in the module)",
        "+ line-a/a-top: program 1 position 2.100 m → 2.050 m (new in the module: profile booth keeps "
        "its value)",
        "~ line-b/b-left: program 4 position 0.900 m → 0.950 m (in the module)",
    ]
    assert (f"--- {plant}" in checked.out
            and "+      2: {position: 0.160, speed: 0.350, dwell: 0.5}   # stroke down" in checked.out)

    adopted = run_cli(capsys, "adopt", plant, "--auto-approve")
    assert adopted.code == 0, adopted.err
    assert adopted.out.splitlines()[-1].startswith(f"Adopted 5 values into {plant}")
    assert plant.read_text().splitlines() == edited(original, {
        "      2: {position: 0.150, speed: 0.350, dwell: 0.5}   # stroke down":
            ["      2: {position: 0.160, speed: 0.350, dwell: 0.5}   # stroke down"],
        "        profiles: [booth, 'spray-gun']":
            ["        profiles: [booth, 'spray-gun']", "        programs:", "          3: {position: 1.150}"],
        "          1: {position: 2.000}       # the right side has a lower hood":
            ["          1: {position: 1.987}       # the right side has a lower hood"],
        "      - {address: 3, name: a-top, profiles: [booth], programs: {4: {position: 1.000, speed: "
        "0.100}}}  # one flow mapping":
            ["      - {address: 3, name: a-top, profiles: [booth], programs: {1: {position: 2.050}, 4: "
             "{position: 1.000, "
             "speed: 0.100}}}  # one flow mapping"],
        "            position: 0.900          # park "
        "for cleaning": ["            position: 0.950          # park for cleaning"],
    })
    assert run_cli(capsys, "validate", plant).code == 0
    planned = run_cli(capsys, "plan", plant, "--detailed-exitcode")
    assert planned.code == 0, planned.out + planned.err

    again = plant.read_bytes()
    nothing = run_cli(capsys, "adopt", plant, "--check")
    assert (nothing.code,
            nothing.out) == (0, "No drift to adopt: the modules hold what the plant file says.\n")
    assert run_cli(capsys, "adopt", plant, "--auto-approve").code == 0
    assert plant.read_bytes() == again


def test_every_program_field_and_system_parameter_is_adopted_in_its_own_layer(repository, capsys, tmp_path):
    plant, _ = repository
    original = plant.read_text()
    floor = tmp_path / "floor.yaml"  # what another tool wrote to the modules since
    floor.write_text(original.replace("min_speed: 0.020", "min_speed: 0.030")
                     .replace("f1: {action: set, distance: 0.020}", "f1: {action: reset, distance: 0.030}")
                     .replace("max_speed: 0.450", "max_speed: 0.440")
                     .replace("            dwell: 12.0",
                              "            dwell: 9.5\n            relative_speed: -0.015")
                     .replace("1: {position: 2.000}",
                              "1: {position: 2.000, f2: {action: set, distance: 0.005}}"))
    assert run_cli(capsys, "apply", floor, "--auto-approve", "--allow-axis-release").code == 0

    adopted = run_cli(capsys, "adopt", plant, "--auto-approve")
    assert adopted.code == 0, adopted.err
    assert plant.read_text().splitlines() == edited(original, {
        "      min_speed: 0.020               # S5": ["      min_speed: 0.030               # S5"],
        "        f1: {action: set, distance: 0.020}             # gun on after START":
            ["        f1: {action: reset, distance: 0.030}           # gun on after START"],
        "          max_speed: 0.450           # a "
        "slower drive": ["          max_speed: 0.440           # a slower drive"],
        "          1: {position: 2.000}       # the right side has a lower hood":
            ["          1: {position: 2.000, f2: {action: set, distance: 0.005}}  # the right side has a "
             "lower hood"],
        "            speed: 0.200": ["            speed: 0.200", "            relative_speed: -0.015"],
        "            dwell: 12.0": ["            dwell: 9.5"],
    })
    assert run_cli(capsys, "plan", plant, "--detailed-exitcode").code == 0


def test_module_and_program_limit_what_is_adopted(repository, capsys):
    plant, emulators = repository
    line_a, line_b = emulators["line-a"], emulators["line-b"]
    for bus, address in ((line_a, 1), (line_a, 2), (line_a, 3), (line_b, 1)):
        bus.teach_in(address, 2, 170)
    line_b.teach_in(1, 4, 950)
    original = plant.read_text()

    one = run_cli(capsys, "adopt", plant, "--module", "a-left", "--auto-approve")
    assert one.code == 0, one.err
    # the others drifted alike but were not read: the profile stays, a-left gets an override
    assert plant.read_text().splitlines() == edited(original, {
        "        profiles: [booth, 'spray-gun']":
            ["        profiles: [booth, 'spray-gun']", "        programs:", "          2: {position: 0.170}"],
    })
    before = plant.read_text()
    program = run_cli(capsys, "adopt", plant, "--program", "4", "--auto-approve")
    assert program.code == 0, program.err
    assert plant.read_text().splitlines() == edited(before, {
        "            position: 0.900          # park "
        "for cleaning": ["            position: 0.950          # park for cleaning"],
    })
    assert run_cli(capsys, "plan", plant, "--module", "a-left", "--detailed-exitcode").code == 0
    # program 2 left alone
    assert run_cli(capsys, "plan", plant, "--module", "b-left", "--detailed-exitcode").code == 2
    unmanaged = run_cli(capsys, "adopt", plant, "--program", "9", "--check")
    assert unmanaged.code == 1 and unmanaged.problems == [
        "error: program 9: no chosen module manages it — name a program the plant file lists"]


def test_what_the_plant_file_cannot_say_is_refused_naming_module_and_program(repository, capsys, tmp_path):
    plant, emulators = repository
    original = plant.read_bytes()
    emulators["line-a"].teach_in(2, 1, 2300)  # above the upper reversing point 2.200 m
    refused = run_cli(capsys, "adopt", plant, "--auto-approve")
    assert refused.code == 1 and refused.problems == [
        "error: bus line-a, module 2 (a-right): program 1 holds position 2.300 m, outside 0.000 m..2.200 m "
        "— a plant "
        "file cannot say that: set it right on the module (teach it again), then adopt again"]
    assert plant.read_bytes() == original

    emulators["line-a"].teach_in(2, 1, 2000)
    floor = tmp_path / "floor.yaml"
    floor.write_text(original.decode().replace("{programs: [1, 2], loop: true}", "[1, 2]"))
    assert run_cli(capsys, "apply", floor, "--auto-approve", "--allow-axis-release").code == 0
    jumps = run_cli(capsys, "adopt", plant, "--check")
    assert jumps.code == 1 and jumps.problems == [
        "error: bus line-a, module 1 (a-left): program 2 jumps to no program on the module where the plant "
        "file says 1 "
        "— adopt leaves jumps (chains, next:) alone: edit them in the plant file by hand, or apply it to "
        "set the jump "
        "back, then adopt again"]
    assert plant.read_bytes() == original


def test_without_a_terminal_adopt_asks_for_auto_approve_and_writes_nothing(repository, capsys):
    plant, emulators = repository
    emulators["line-a"].teach_in(2, 1, 1987)
    original = plant.read_bytes()
    refused = run_cli(capsys, "adopt", plant)
    assert refused.code == 1 and refused.problems == [
        f"error: Write 1 value into {plant}? — no terminal to ask: pass --auto-approve to write it without "
        "asking, or --check to see the diff only"]
    assert plant.read_bytes() == original


def answered(args: list, answer: str) -> str:
    """What `prc3cfg ARGS` prints when its input is a terminal on which the user types `answer`:
    stdout, stderr, and what it wrote on that terminal (its questions)."""
    master, terminal = os.openpty()
    try:
        os.write(master, answer.encode())
        done = subprocess.run([sys.executable, "-m", "prc3cfg", *map(str, args)], stdin=terminal,
                              capture_output=True,
                              text=True, timeout=60)
        os.set_blocking(master, False)
        shown = b""
        with contextlib.suppress(BlockingIOError):
            while chunk := os.read(master, 65536):
                shown += chunk
    finally:
        os.close(terminal)
        os.close(master)
    return done.stdout + done.stderr + shown.decode()


def test_on_a_terminal_adopt_asks_before_it_writes_and_keeps_the_file_mode(repository):
    plant, emulators = repository
    emulators["line-a"].teach_in(2, 1, 1987)
    plant.chmod(0o664)
    original = plant.read_bytes()
    declined = answered(["adopt", plant], "n\n")
    assert (f"Write 1 value into {plant}? [y/N]" in declined
            and "error: not adopted — the plant file was not changed" in declined)
    assert plant.read_bytes() == original
    accepted = answered(["adopt", plant], "y\n")
    assert f"Adopted 1 value into {plant}" in accepted
    assert plant.read_text() == original.decode().replace("1: {position: 2.000}", "1: {position: 1.987}")
    assert plant.stat().st_mode & 0o777 == 0o664


def test_a_file_with_crlf_line_ends_and_no_final_newline_keeps_both():
    text = "\r\n".join([
        "plant: tiny", "profiles:", "  r:", "    programs:", "      1: {position: 0.300, speed: 0.100}",
        "buses:", "  - name: b", "    port: emulator://tiny", "    modules:",
        "      - {address: 1, name: m1, profiles: r}", "      - address: 2", "        name: m2",
                        "        profiles: r",
    ])
    with tempfile.TemporaryDirectory() as folder:
        path = Path(folder) / "plant.yaml"
        path.write_bytes(text.encode())
        plant = load_plant(path)
    images = {(bus.name, m.address): m.desired_image() for bus, m in plant.modules()}
    taught = images[("b", 2)]
    images[("b", 2)] = taught.with_programs({1: replace(taught.program(1), P=250)})
    adoption = adopt.adopt(plant, images, text)
    assert adoption.text == text + "\r\n        programs:\r\n          1: {position: 0.250}"


#: A plant file with what editors write into one: non-ASCII names before a changed value on its
#: line, tabs in comments; each `FORMS` case saves it another way (a test of each splice's offsets).
ODD = "\n".join([
    "plant: Anlage Süd", "profiles:", "  r:\t# a tab\tbefore and inside a comment", "    programs:",
    "      1: {position: 0.300, speed: 0.100}\t# 塗装 läuft", "buses:", "  - name: Kabine-Süd",
                 "    port: emulator://tiny",
    "    modules:", "      - {address: 1, name: 塗装, profiles: r, programs: {2: {position: 0.350, speed: "
                    "0.100}}}  # 塗装",
    "      - address: 2", '        name: "Kabine Süd 2"\t# über', "        profiles: r", "",
])
ADOPTED = (ODD.replace("{2: {position: 0.350,", "{2: {position: 0.320,")
           + "        programs:\n          1: {position: 0.250}\n")
FORMS = {
    "as written": lambda text: text,
    "byte order mark": lambda text: "\ufeff" + text,
    "crlf": lambda text: text.replace("\n", "\r\n"),
    "byte order mark and crlf": lambda text: "\ufeff" + text.replace("\n", "\r\n"),
    "no final newline": lambda text: text.removesuffix("\n"),
}


def taught_odd(text: str, tmp_path: Path) -> tuple[Path, dict]:
    """`text` saved as a plant file, and its modules as taught: 塗装's program 2 at 0.320 m, module 2's
    program 1 at 0.250 m."""
    path = tmp_path / "plant.yaml"
    path.write_bytes(text.encode())
    plant = load_plant(path)
    images = {(bus.name, m.address): m.desired_image() for bus, m in plant.modules()}
    for address, number, position in ((1, 2, 320), (2, 1, 250)):
        image = images[("Kabine-Süd", address)]
        images[("Kabine-Süd", address)] = image.with_programs({number: replace(image.program(number),
                                                                               P=position)})
    return path, images


@pytest.mark.parametrize("form", FORMS)
def test_every_splice_lands_in_files_saved_by_any_editor(tmp_path, form):
    path, images = taught_odd(FORMS[form](ODD), tmp_path)
    adoption = adopt.adopt(load_plant(path), images, path.read_bytes().decode())
    assert adoption.text == FORMS[form](ADOPTED)
    path.write_bytes(adoption.text.encode())
    assert not api.plan(load_plant(path), images=images).changes


def test_a_rewrite_that_does_not_describe_the_modules_is_refused_and_nothing_is_written(tmp_path, monkeypatch,
                                                                                        capsys):
    path, images = taught_odd(ODD, tmp_path)
    plant = load_plant(path)
    # a splice gone wrong
    monkeypatch.setattr(splice, "rewrite", lambda text, wanted: text.replace("0.350", "0.380"))
    with pytest.raises(adopt.AdoptRefused) as refused:
        adopt.adopt(plant, images, ODD)
    assert str(refused.value) == (
        f"{path}: the rewritten plant file would not describe what the modules hold — bus Kabine-Süd, "
        "module 1 (塗装): "
        "program 2 position 0.320 m → 0.380 m (held → written); nothing was adopted: this is a bug in "
        "prc3cfg, "
        "please report it with the plant file")
    assert path.read_text() == ODD


#: An editor saving the plant file while adopt runs (argv: the file, what it waits for, the text it
#: adds). It passes adopt's output on, and saves — reads the file, writes it back with a line
#: added, in place as most editors do — when adopt prints its first value ("value"), the last line
#: of its diff ("diff"), or when adopt's temporary file appears beside the plant file ("temporary");
#: after adopt, if it missed that moment (a temporary file on tmpfs lives for microseconds).
EDITOR = """
import os, select, sys
path, trigger, mark = sys.argv[1:]
folder, name = os.path.split(path)
def save():
    with open(path) as file:
        text = file.read()
    with open(path, "w") as file:
        file.write(text + mark)
    print("edited", flush=True)
out, pending, done = "", True, False
while not done:
    if pending and trigger == "temporary":
        if any(n.startswith("." + name + ".") and n.endswith(".tmp") for n in os.listdir(folder)):
            save()
            pending = False
        if not select.select([0], [], [], 0)[0]:
            continue
    chunk = os.read(0, 65536).decode()
    done = not chunk
    out += chunk
    lines = out.split("\\n")
    if pending and trigger == "value" and any(l[:2] in ("~ ", "+ ") for l in lines[:-1]):
        save()
        pending = False
    if pending and trigger == "diff" and any(l.startswith("Write") or l.startswith("Adopted") for l in lines):
        save()
        pending = False
if pending:  # adopt was done before the editor saw its moment: it saves after adopt
    save()
sys.stdout.write(out)
"""


def race_an_editor(plant: Path, emulators: dict, trials: int) -> list[str]:
    """Each trial teaches a position in and runs adopt while an editor saves the plant file
    (`EDITOR`, at each point in turn): the trials whose edit is not in the file afterwards."""
    lost = []
    for trial in range(trials):
        emulators["line-a"].teach_in(2, 1, 1900 + trial)
        trigger = ("value", "diff", "temporary")[trial % 3]
        mark = f"# edit {trial}\n"
        output, into = os.pipe()  # adopt → editor; the editor runs first, so that it sees the temporary file
        editor = subprocess.Popen([sys.executable, "-c", EDITOR, str(plant), trigger, mark], stdin=output,
                                  stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        adopting = subprocess.Popen([sys.executable, "-m", "prc3cfg", "adopt", plant, "--auto-approve"],
                                    stdout=into,
                                    stderr=subprocess.PIPE, text=True,
                                    env={**os.environ, "PYTHONUNBUFFERED": "1"})
        os.close(output)
        os.close(into)
        err = adopting.stderr.read()
        edited, _ = editor.communicate(timeout=120)
        assert adopting.wait(timeout=60) in (0, 1) and "Traceback" not in err, err
        assert adopting.returncode == 0 or "the plant file changed while adopting" in err, err
        assert "edited" in edited, (trigger, edited)
        if mark not in plant.read_text():
            lost.append(f"trial {trial} ({trigger}): {err or 'adopted'}")
    return lost


def test_adopt_racing_an_editor_keeps_every_edit(repository):
    plant, emulators = repository
    assert race_an_editor(plant, emulators, 6) == []
    assert run_cli_process("validate", plant).returncode == 0


@pytest.mark.soak
def test_adopt_racing_an_editor_60_times_keeps_every_edit(repository):
    plant, emulators = repository
    assert race_an_editor(plant, emulators, 60) == []


def run_cli_process(*args) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "prc3cfg", *map(str, args)], capture_output=True, text=True,
                          timeout=60)


@st.composite
def teach_ins(draw):
    """Positions taught in on the demo plant's modules, as applied: (module index, program, mm)."""
    plant = load_plant(DEMO)
    modules = plant.modules()
    taught = []
    for _ in range(draw(st.integers(1, 6))):
        index = draw(st.integers(0, len(modules) - 1))
        module = modules[index][1]
        number = draw(st.sampled_from(module.managed_programs()))
        taught.append((index, number, draw(st.integers(0, module.desired_system().S1))))
    return taught


@settings(max_examples=25, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(teach_ins())
def test_adopting_any_teach_in_leaves_a_valid_file_that_plans_no_changes(taught):
    plant = load_plant(DEMO)
    text = DEMO.read_text()
    images = {(bus.name, m.address): m.desired_image() for bus, m in plant.modules()}
    for index, number, position in taught:
        bus, module = plant.modules()[index]
        image = images[(bus.name, module.address)]
        images[(bus.name, module.address)] = image.with_programs({number: replace(image.program(number),
                                                                                  P=position)})
    adoption = adopt.adopt(plant, images, text)
    with tempfile.TemporaryDirectory() as folder:
        path = Path(folder) / "demo-line.yaml"
        path.write_text(adoption.text)
        adopted = load_plant(path)
    assert not api.plan(adopted, images=images).changes
    changed = Counter(line[0] for line in difflib.ndiff(text.splitlines(), adoption.text.splitlines())
                      if line[0] in "+-")
    # a value changed, or an override added
    assert changed["-"] <= len(taught) and changed["+"] <= 2 * len(taught)


def test_an_adopt_is_recorded_on_the_lines_it_adopted_from_by_their_whole_names(tmp_path, capsys):
    """A line named "hall/2": its adopt's run in `records list` names that line (it named "hall": each
    "bus/name" of an adopted value was cut at its first "/")."""
    source = tmp_path / "source.yaml"
    source.write_text(DEMO.read_text().replace("  - name: booth-b\n", "  - name: hall/2\n", 1))
    assert "hall/2" in source.read_text()
    (tmp_path / "emulated").mkdir()
    with emulated_plant(tmp_path / "emulated", source=source) as plant:
        assert run_cli(capsys, "apply", plant.path, "--auto-approve", "--allow-axis-release").code == 0
        plant.emulators["hall/2"].teach_in(1, 1, 1234)
        adopted = run_cli(capsys, "adopt", plant.path, "--auto-approve")
        assert adopted.code == 0, adopted.err
        runs = json.loads(run_cli(capsys, "records", "list", plant.path, "--json").out)
    assert [run["lines"] for run in runs if run["command"] == "adopt"] == [["hall/2"]], runs
