"""Hostile JSON inputs on the command line: every one is refused in one line (file, what is
wrong, what to do), exit 1, no traceback — and before the line, or the emulator, is started.

Numbers longer than Python will convert, documents that would take gigabytes to parse, and
plan files whose structure was damaged (a hypothesis test: drop a key or an item, change a
type), and an emulator state file in a folder that does not exist. The plant points at ports
where nothing listens, so an error about the line would mean the input was not checked first.
"""

from __future__ import annotations

import copy
import json
import os
import re
import subprocess
import sys
from pathlib import Path

import pytest
from emulated import DEMO, run_cli
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from prc3cfg.core.device import ModuleState
from prc3cfg.core.image import DEFAULT_SYSTEM
from prc3cfg.shell import files
from prc3cfg.shell.plant_files import load_plant

#: What a message a person reads must never show: Python's own words for what went wrong.
PYTHON = re.compile(r"Traceback|Error:|Error\b|NoneType|object of type|has no len|not subscriptable"
                    r"|\bdict\b|\bstr\b|\bint\b")


def nowhere_plant(folder: Path) -> Path:
    """The demo plant on ports where nothing listens."""
    plant = folder / "plant.yaml"
    plant.write_text(DEMO.read_text().replace("emulator://demo-a", "socket://127.0.0.1:9")
                     .replace("emulator://demo-b", "socket://127.0.0.1:19"))
    return plant


def factory_images(plant: Path, out: Path) -> Path:
    """A `read --json` file of the plant's modules at factory defaults (made without a line)."""
    entries = [{"bus": bus.name, **ModuleState.factory(module.address).image.to_json()}
               for bus, module in load_plant(plant).modules()]
    out.write_text(json.dumps(entries, indent=1))
    return out


@pytest.fixture
def nowhere(tmp_path) -> Path:
    return nowhere_plant(tmp_path)


def one_line(result, start: str) -> str:
    """The only line on stderr, which starts with `start` and shows no Python."""
    assert result.code == 1, (result.out, result.err)
    (line,) = result.err.splitlines()
    assert line.startswith(start), line
    assert not PYTHON.search(line), line
    return line


# -- a number of more than 4,300 digits ------------------------------------------------------------

BIG = "9" * 5000


def big_number_inputs(tmp_path: Path, plant: Path) -> dict[str, tuple[list[str], Path, str]]:
    """(command line, the file, the remedy) for every JSON input, each holding a 5,000-digit number."""
    def write(name: str, text: str) -> Path:
        (tmp_path / name).write_text(text)
        return tmp_path / name

    plan = write("plan.json", f'{{"format": "prc3cfg-plan/1", "buses": [], "estimated_bus_time_s": {BIG}}}')
    images = write("images.json", f'[{{"bus": "booth-a", "address": {BIG}}}]')
    snapshot = write("snapshot.json", f'{{"format": "prc3cfg-snapshot/1", "taken": {BIG}}}')
    state = write("state.json", f'{{"format": "prc3-emulator/1", "modules": [{{"address": {BIG}}}]}}')
    return {
        "show PLAN": (["show", plan], plan, "make the plan again"),
        "apply --plan": (["apply", plant, "--plan", plan], plan, "make the plan again"),
        "apply --plan, no plant": (["apply", "--plan", plan], plan, "make the plan again"),
        "plan --actual": (["plan", plant, "--actual", images], images,
                          "save the images again with prc3cfg read --json"),
        "restore": (["restore", snapshot], snapshot, "name a file under .prc3cfg/snapshots/"),
        "emulator serve --state": (["emulator", "serve", "--state", state, "--listen", "127.0.0.1:0"], state,
                                   "fix or delete it"),
    }


@pytest.mark.parametrize("case", ["show PLAN", "apply --plan", "apply --plan, no plant", "plan --actual",
                                  "restore", "emulator serve --state"])
def test_a_number_of_5000_digits_is_refused_in_one_line(nowhere, tmp_path, capsys, case):
    args, path, remedy = big_number_inputs(tmp_path, nowhere)[case]
    line = one_line(run_cli(capsys, *args), f"error: {path}: ")
    assert "more than 4300 digits" in line and line.endswith(f" — {remedy}")
    assert not (tmp_path / ".prc3cfg" / "journal").exists()


# -- module images and snapshots whose structure is damaged -----------------------------------------

IMAGES = {
    "an image without its system": (
        '[{"bus": "booth-a", "address": 1, "programs": []}]',
        '[0] has no "system"',
    ),
    "a program that is a list": (
        (
            f'[{{"bus": "booth-a", "address": 1, "system": {json.dumps(DEFAULT_SYSTEM.to_json())},'
            ' "programs": [[1]]}]'
        ),
        "[0].programs[0] is a list, where an object or null belongs",
    ),
    "programs that are an object": (
        (
            f'[{{"bus": "booth-a", "address": 1, "system": {json.dumps(DEFAULT_SYSTEM.to_json())},'
            ' "programs": {}}]'
        ),
        "[0].programs is an object, where a list belongs",
    ),
    "a system parameter missing": (
        '[{"bus": "booth-a", "address": 1, "system": {"S1": 1}, "programs": []}]',
        '[0].system has no "S2"',
    ),
}


@pytest.mark.parametrize("case", IMAGES, ids=list(IMAGES))
def test_a_damaged_images_file_says_what_is_missing_in_words(nowhere, tmp_path, capsys, case):
    text, said = IMAGES[case]
    images = tmp_path / "images.json"
    images.write_text(text)
    line = one_line(run_cli(capsys, "plan", nowhere, "--actual", images), f"error: {images}: ")
    assert said in line, line


SNAPSHOTS = {
    "no modules": ('{"format": "prc3cfg-snapshot/1", "plant": "/p.yaml"}', 'the snapshot has no "modules"'),
    "a module without its bus": ('{"format": "prc3cfg-snapshot/1", "modules": [{"address": 1}]}',
                                 'modules[0] has no "bus"'),
    "an image without programs": ('{"format": "prc3cfg-snapshot/1", "plant": "/p.yaml", "plant_sha256": '
                                  '"0", "taken": "t", '
                                  '"modules": [{"bus": "a", "address": 1}]}',
                                  'modules[0] has no "system"'),
}


@pytest.mark.parametrize("case", SNAPSHOTS, ids=list(SNAPSHOTS))
def test_a_damaged_snapshot_says_what_is_missing_in_words(tmp_path, capsys, case):
    text, said = SNAPSHOTS[case]
    snapshot = tmp_path / "snapshot.json"
    snapshot.write_text(text)
    line = one_line(run_cli(capsys, "restore", snapshot), f"error: {snapshot}: not a readable snapshot (")
    assert said in line, line


# -- too many objects and lists --------------------------------------------------------------------


def test_a_document_of_too_many_objects_is_refused_before_it_is_parsed(nowhere, tmp_path, capsys):
    plan = tmp_path / "bomb.json"
    plan.write_text("[" + "{}," * files.MAX_CONTAINERS + "{}]")  # 1.5 MB here; 63 MB took 1.6 GB to parse
    line = one_line(run_cli(capsys, "apply", nowhere, "--plan", plan), f"error: {plan}: ")
    assert line == (f"error: {plan}: more than {files.MAX_CONTAINERS:,} objects and lists (counting "
                    f"'{{' and '['), more than any "
                    "file prc3cfg writes holds — name the plan file prc3cfg plan --out wrote")


@pytest.mark.parametrize("case", ["show PLAN", "plan --actual", "restore", "emulator serve --state"])
def test_every_json_input_counts_its_objects_and_lists(nowhere, tmp_path, capsys, case):
    args, path, _ = big_number_inputs(tmp_path, nowhere)[case]
    path.write_text("[" + "[]," * files.MAX_CONTAINERS + "[]]")
    line = one_line(run_cli(capsys, *args),
                    f"error: {path}: more than {files.MAX_CONTAINERS:,} objects and lists")
    assert "Traceback" not in line


def test_a_document_at_the_limit_is_read(tmp_path):
    path = tmp_path / "many.json"
    path.write_text("[" + ",".join(["{}"] * (files.MAX_CONTAINERS - 1)) + "]")
    assert len(files.read_json(path)) == files.MAX_CONTAINERS - 1


def test_a_document_of_too_many_values_is_refused_before_it_is_parsed(nowhere, tmp_path, capsys):
    plan = tmp_path / "numbers.json"
    plan.write_text("[" + "1e1," * files.MAX_VALUES + "1]")  # 10 MB here; 64 MiB of them took 0.8 GB to parse
    line = one_line(run_cli(capsys, "apply", nowhere, "--plan", plan), f"error: {plan}: ")
    assert line == (f"error: {plan}: more than {files.MAX_VALUES:,} values (counting ','), more than any "
                    "file prc3cfg "
                    "writes holds — name the plan file prc3cfg plan --out wrote")
    at_the_limit = tmp_path / "at-the-limit.json"
    at_the_limit.write_text("[" + "0," * (files.MAX_VALUES - 1) + "0]")
    assert len(files.read_json(at_the_limit)) == files.MAX_VALUES


def test_a_long_integer_is_refused_even_where_python_would_convert_it(tmp_path):
    """PYTHONINTMAXSTRDIGITS=0 lifts Python's limit (and int() of a huge number takes quadratic time)."""
    path = tmp_path / "big.json"
    path.write_text(f"[{BIG}]")
    script = "import sys; from pathlib import Path; from prc3cfg.shell import files\n" \
             "try: files.read_json(Path(sys.argv[1]))\nexcept files.FileProblem as problem: print(problem)"
    done = subprocess.run([sys.executable, "-c", script, str(path)], capture_output=True, text=True,
                          env={**os.environ, "PYTHONINTMAXSTRDIGITS": "0"})
    assert done.stdout == (f"a number of more than {files.MAX_DIGITS} digits, which no file prc3cfg "
                           "writes holds\n"), done.stderr


# -- plan files whose structure is damaged ------------------------------------------------------------


@pytest.fixture(scope="module")
def made_plan(tmp_path_factory) -> tuple[Path, dict]:
    """A plant on no line, and a plan file for it made from factory-default images (`plan --actual`)."""
    folder = tmp_path_factory.mktemp("made")
    plant = nowhere_plant(folder)
    images = factory_images(plant, folder / "images.json")
    out = folder / "plan.json"
    with pytest.MonkeyPatch.context() as patch:
        patch.setenv("PRC3CFG_LOCK_DIR", str(folder / "locks"))
        from prc3cfg.cli import main

        with pytest.raises(SystemExit) as done:
            main(["plan", str(plant), "--actual", str(images), "--out", str(out)])
    assert done.value.code in (0, None)
    return plant, json.loads(out.read_text())


def damage(document: dict, change) -> dict:
    damaged = copy.deepcopy(document)
    change(damaged)
    return damaged


def first_module(document: dict) -> dict:
    return document["buses"][0]["modules"][0]


DAMAGE = {
    "no buses": (lambda d: d.pop("buses"), 'the plan has no "buses"'),
    "buses null": (lambda d: d.update(buses=None), "buses is null, where a list belongs"),
    "a bus that is a number": (lambda d: d["buses"].__setitem__(0, 7),
                               "buses[0] is 7, where an object belongs"),
    "a bus without modules": (lambda d: d["buses"][0].pop("modules"), 'buses[0] has no "modules"'),
    "steps null": (lambda d: first_module(d).update(steps=None),
                   "buses[0].modules[0].steps is null, where a list belongs"),
    "a step without its message": (lambda d: first_module(d)["steps"][0].pop("message"),
                                   'buses[0].modules[0].steps[0] has no "message"'),
    "a message that is not hex": (lambda d: first_module(d)["steps"][0].update(message="zz"),
                                  "buses[0].modules[0].steps[0].message is not a PRC 3 message in hex"),
    "a message as a number": (lambda d: first_module(d)["steps"][0].update(message=2000),
                              "buses[0].modules[0].steps[0].message is 2000, where text belongs"),
    "no plant": (lambda d: d.pop("plant"), 'has no "plant"'),
    "plant_sha256 false": (lambda d: d.update(plant_sha256=False), "plant_sha256 is false, where "
                                                                   "text belongs"),
    "a name that is a list": (lambda d: first_module(d).update(name=["a"]),
                              "buses[0].modules[0].name is a list, where text belongs"),
}


@pytest.mark.parametrize("case", DAMAGE, ids=list(DAMAGE))
@pytest.mark.parametrize("command", ["show", "apply"])
def test_a_damaged_plan_file_says_where_and_what_in_words(made_plan, tmp_path, capsys, case, command):
    plant, document = made_plan
    change, expected = DAMAGE[case]
    path = tmp_path / "damaged.json"
    path.write_text(json.dumps(damage(document, change)))
    args = ["show", path] if command == "show" else ["apply", plant, "--plan", path]
    line = one_line(run_cli(capsys, *args), f"error: {path}: ")
    assert expected in line, line
    assert line.endswith(" — make the plan again with prc3cfg plan --out"), line


def test_a_shown_plan_file_says_where_null_may_stand(made_plan, tmp_path, capsys):
    """A changed field's program is a program's number, or null for a system parameter: a value that
    may be null says so."""
    _, document = made_plan
    path = tmp_path / "damaged.json"
    path.write_text(json.dumps(damage(document,
                                      lambda d: first_module(d)["changes"]["fields"][0].update(program="3"))))
    line = one_line(run_cli(capsys, "show", path), f"error: {path}: ")
    assert ('buses[0].modules[0].changes.fields[0].program is the text "3", where a whole number or '
            'null belongs') in line, line


def paths(value, at: tuple = ()) -> list[tuple]:
    """Every place in a JSON document, as the keys and indexes that lead there."""
    found = [at]
    if isinstance(value, dict):
        for key, item in value.items():
            found += paths(item, (*at, key))
    elif isinstance(value, list):
        for index, item in enumerate(value[:3]):  # the first few of a list: the rest are alike
            found += paths(item, (*at, index))
    return found


OTHERS = [None, True, False, 0, -1, 2.5, 1e300, "", "x", "20", [], {}, [None], {"a": 1}, [[]], "ff" * 40]


#: Keys a mangled plan file may give twice (`"KEY": null, "KEY": …`, the first one added).
TWICE = ["format", "plant_sha256", "buses", "modules", "address", "steps", "message", "broadcast"]


@settings(max_examples=25, derandomize=True, deadline=None,
          suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(data=st.data())
def test_a_plan_file_of_mangled_structure_is_refused_in_words(made_plan, tmp_path, capsys, data):
    """Drop a key or an item, give a value of another type, or a key twice, anywhere: `show` and
    `apply --plan` refuse it in one line that says where, in words — or, where the file still
    makes sense to show, show it; never a traceback."""
    mangled_plan_is_said_in_words(made_plan, tmp_path, capsys, data)


@pytest.mark.soak
@settings(max_examples=1000, derandomize=True, deadline=None,
          suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(data=st.data())
def test_1000_mangled_plan_files_are_refused_in_words(made_plan, tmp_path, capsys, data):
    mangled_plan_is_said_in_words(made_plan, tmp_path, capsys, data)


def mangled_plan_is_said_in_words(made_plan, tmp_path, capsys, data) -> None:
    plant, document = made_plan
    mangled = copy.deepcopy(document)
    for _ in range(data.draw(st.integers(1, 3))):
        places = [p for p in paths(mangled) if p]
        if not places:
            break
        place = data.draw(st.sampled_from(places))
        parent = mangled
        for key in place[:-1]:
            parent = parent[key]
        if data.draw(st.booleans()):
            del parent[place[-1]]
        else:
            # a copy: OTHERS stays as it is, no list holds itself
            parent[place[-1]] = copy.deepcopy(data.draw(st.sampled_from(OTHERS)))
    text = json.dumps(mangled)
    twice = data.draw(st.sampled_from([None, *TWICE]))
    if twice is not None:
        text = text.replace(f'"{twice}": ', f'"{twice}": null, "{twice}": ', 1)
    path = tmp_path / "mangled.json"
    path.write_text(text)
    shown = run_cli(capsys, "show", path)
    if shown.code != 0:
        one_line(shown, f"error: {path}: ")
    applied = run_cli(capsys, "apply", plant, "--plan", path, "--auto-approve")
    assert " — " in one_line(applied, "error: ")  # what is wrong — what to do (or what was expected)


@pytest.mark.soak
@settings(suppress_health_check=[HealthCheck.function_scoped_fixture])  # the soak profile's count
@given(data=st.data())
def test_a_plan_file_of_many_more_mangled_structures_is_refused_in_words(made_plan, tmp_path, capsys, data):
    test_a_plan_file_of_mangled_structure_is_refused_in_words.hypothesis.inner_test(made_plan, tmp_path,
                                                                                    capsys, data=data)


# -- plan files beyond any plan prc3cfg writes: nesting, size, texts, lists ---------------------------


def deep(levels: int) -> str:
    return "[" * levels + "]" * levels


def with_text(document: dict, change) -> str:
    return json.dumps(damage(document, change))


#: A plan file beyond what prc3cfg writes (as text, from the plan file made), and what its one line says.
BEYOND = {
    "nested 900 deep": (
        lambda d: with_text(
            d, lambda d: first_module(d)["changes"].update(symbols={"1": json.loads(deep(900))})
        ),
        "buses[0].modules[0].changes.symbols.1",
    ),
    "nested 100,000 deep": (
        lambda d: json.dumps(d)[:-1] + ', "x": ' + deep(100_000) + "}",
        "nested too deeply",
    ),
    "a text of 10 MB": (
        lambda d: with_text(d, lambda d: first_module(d).update(name="a" * 10_000_000)),
        "buses[0].modules[0].name is a text of 10,000,000 characters",
    ),
    "a file of 50 MB": (lambda d: json.dumps(d) + " " * 50_000_000, "larger than 32 MiB"),
    "a list of 200,000 items": (
        lambda d: with_text(d, lambda d: d.update(left_alone=[""] * 200_000)),
        "left_alone is a list of 200,000 items",
    ),
    "an object of 200,000 keys": (
        lambda d: with_text(
            d, lambda d: first_module(d)["changes"].update(symbols={str(n): "~" for n in range(200_000)})
        ),
        "buses[0].modules[0].changes.symbols is an object of 200,000 keys",
    ),
}


@pytest.mark.parametrize("case", BEYOND, ids=list(BEYOND))
@pytest.mark.parametrize("command", ["show", "apply"])
def test_a_plan_file_beyond_any_prc3cfg_writes_is_refused_in_one_line(made_plan, tmp_path, capsys, case,
                                                                      command):
    """Deeper, larger, longer than any plan prc3cfg writes: one line naming where and the bound, before the
    line is used."""
    plant, document = made_plan
    make, expected = BEYOND[case]
    path = tmp_path / "beyond.json"
    path.write_text(make(document))
    args = ["show", path] if command == "show" else ["apply", plant, "--plan", path, "--auto-approve"]
    line = one_line(run_cli(capsys, *args), f"error: {path}: ")
    assert expected in line and line.endswith(("make the plan again",
                                               "make the plan again with prc3cfg plan --out",
                                               "name the plan file prc3cfg plan --out wrote")), line


@pytest.mark.parametrize("case", ["nested 900 deep", "a text of 10 MB"])
def test_a_plan_file_beyond_any_prc3cfg_writes_is_one_line_from_the_console_script(made_plan, tmp_path, case):
    """The same from a process of its own (Python's own recursion limit and stack, not pytest's)."""
    _, document = made_plan
    make, expected = BEYOND[case]
    path = tmp_path / "beyond.json"
    path.write_text(make(document))
    done = subprocess.run([sys.executable, "-m", "prc3cfg", "show", str(path)], capture_output=True,
                          timeout=120)
    assert (done.returncode, done.stdout) == (1, b"")
    (line,) = done.stderr.decode().splitlines()
    assert line.startswith(f"error: {path}: ") and expected in line and not PYTHON.search(line), line


# -- the emulator's state file ----------------------------------------------------------------------


def test_a_state_file_in_a_missing_folder_is_refused_before_the_emulator_starts(tmp_path, capsys):
    state = tmp_path / "new" / "a" / "b.json"
    # an address of no host here: refused if it came first
    result = run_cli(capsys, "emulator", "serve", "--state", state, "--listen", "192.0.2.1:7001")
    assert (result.code,
            result.err) == (1, f"error: --state {state}: the folder {tmp_path}/new/a does not exist — "
                               "create it first\n")
    assert not (tmp_path / "new").exists()


def test_a_state_file_whose_folder_is_a_file_is_refused(tmp_path, capsys):
    (tmp_path / "file").write_text("")
    state = tmp_path / "file" / "b.json"
    # an address of no host here: refused if it came first
    result = run_cli(capsys, "emulator", "serve", "--state", state, "--listen", "192.0.2.1:7001")
    assert (result.code,
            result.err) == (1, f"error: --state {state}: {tmp_path}/file is not a folder — name a state "
                               "file in a folder\n")
