"""Hostile JSON inputs on the command line: every one is refused in one line (file, what is
wrong, what to do), exit 1, no traceback — and before the line, or the emulator, is started.

Numbers longer than Python will convert, and documents that would take gigabytes to parse.
The plant points at ports where nothing listens, so an error about the line would mean the
input was not checked first.
"""

from __future__ import annotations

import re
from pathlib import Path

import pytest
from emulated import DEMO, run_cli

from prc3cfg.shell import files

#: What a message a person reads must never show: Python's own words for what went wrong.
PYTHON = re.compile(r"Traceback|Error:|Error\b|NoneType|object of type|has no len|not subscriptable|\bdict\b|\bstr\b|\bint\b")


@pytest.fixture(autouse=True)
def private_locks(tmp_path, monkeypatch):
    monkeypatch.setenv("PRC3CFG_LOCK_DIR", str(tmp_path / "locks"))


def nowhere_plant(folder: Path) -> Path:
    """The demo plant on ports where nothing listens."""
    plant = folder / "plant.yaml"
    plant.write_text(DEMO.read_text().replace("emulator://demo-a", "socket://127.0.0.1:9").replace("emulator://demo-b", "socket://127.0.0.1:19"))
    return plant


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
        "plan --actual": (["plan", plant, "--actual", images], images, "save the images again with prc3cfg read --json"),
        "restore": (["restore", snapshot], snapshot, "name a file under .prc3cfg/snapshots/"),
        "emulator serve --state": (["emulator", "serve", "--state", state, "--listen", "127.0.0.1:0"], state, "fix or delete it"),
    }


@pytest.mark.parametrize("case", ["show PLAN", "apply --plan", "apply --plan, no plant", "plan --actual", "restore", "emulator serve --state"])
def test_a_number_of_5000_digits_is_refused_in_one_line(nowhere, tmp_path, capsys, case):
    args, path, remedy = big_number_inputs(tmp_path, nowhere)[case]
    line = one_line(run_cli(capsys, *args), f"error: {path}: ")
    assert "more than 4300 digits" in line and line.endswith(f" — {remedy}")
    assert not (tmp_path / ".prc3cfg" / "journal").exists()


# -- too many objects and lists --------------------------------------------------------------------


def test_a_document_of_too_many_objects_is_refused_before_it_is_parsed(nowhere, tmp_path, capsys):
    plan = tmp_path / "bomb.json"
    plan.write_text("[" + "{}," * files.MAX_CONTAINERS + "{}]")  # 1.5 MB here; 63 MB took 1.6 GB to parse
    line = one_line(run_cli(capsys, "apply", nowhere, "--plan", plan), f"error: {plan}: ")
    assert line == (f"error: {plan}: more than {files.MAX_CONTAINERS:,} objects and lists (counting '{{' and '['), more than any "
                    "file prc3cfg writes holds — name the plan file prc3cfg plan --out wrote")  # fmt: skip


@pytest.mark.parametrize("case", ["show PLAN", "plan --actual", "restore", "emulator serve --state"])
def test_every_json_input_counts_its_objects_and_lists(nowhere, tmp_path, capsys, case):
    args, path, _ = big_number_inputs(tmp_path, nowhere)[case]
    path.write_text("[" + "[]," * files.MAX_CONTAINERS + "[]]")
    line = one_line(run_cli(capsys, *args), f"error: {path}: more than {files.MAX_CONTAINERS:,} objects and lists")
    assert "Traceback" not in line


def test_a_document_at_the_limit_is_read(tmp_path):
    path = tmp_path / "many.json"
    path.write_text("[" + ",".join(["{}"] * (files.MAX_CONTAINERS - 1)) + "]")
    assert len(files.read_json(path)) == files.MAX_CONTAINERS - 1
