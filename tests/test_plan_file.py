"""A plan file is written and read back by one module (`prc3cfg.core.plan_file`) and judged by its
data, never by its spelling: the file another tool wrote again — indented otherwise, its keys in
another order, CRLF, a byte-order mark, without escapes, 0 for 0.0 — is the plan file prc3cfg
wrote, and `apply --plan` proves it; one whose any single value was changed, a key added or one
left out is refused before anything is written.

The plant is the contracts' (`contracts/plant.yaml`), planned without a line (`plan --actual`) from
factory modules but one, which already holds what its plan would leave: its figures are 0.0, which
JavaScript's `JSON.stringify` and jq 1.6 write as 0. The proof is the API's (`_apply.read_plan`, then
`_apply.prove` from the same images), as `apply --plan` makes it before the first write.
"""

from __future__ import annotations

import contextlib
import copy
import hashlib
import json
import shutil
import subprocess
import sys
import unicodedata
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import pytest
from emulated import emulated_plant, run_cli
from hypothesis import HealthCheck, event, given, settings
from hypothesis import strategies as st
from tools import require

from prc3cfg import api
from prc3cfg.api import _apply
from prc3cfg.api._plan import RECORD, as_it_stands
from prc3cfg.core import plan_file, render
from prc3cfg.core.device import ModuleState
from prc3cfg.core.image import ModuleImage
from prc3cfg.core.plant_plan import PlantPlan
from prc3cfg.errors import UserError
from prc3cfg.plant import Plant
from prc3cfg.shell.testing import EmulatedPlant

CONTRACTS = Path(__file__).resolve().parent / "contracts"


@dataclass(frozen=True)
class Made:
    """The plant, the images its plan was made from, and the plan file (not shown: a failing example shows the
    document)."""

    plant: Plant = field(repr=False)
    images: dict[tuple[str, int], ModuleImage] = field(repr=False)
    text: str = field(repr=False)  # the plan file as `plan --out` wrote it
    message_count: int


@pytest.fixture(scope="module")
def made(tmp_path_factory) -> Made:
    """The contracts' plant, its images (booth-a-right as its plan would leave it), and the plan file `plan
    --out` wrote."""
    folder = tmp_path_factory.mktemp("made")
    (folder / "plant.yaml").write_bytes((CONTRACTS / "plant.yaml").read_bytes())
    plant = api.load(folder / "plant.yaml")
    images = {(bus.name, m.address): ModuleState.factory(m.address).image for bus, m in api.select(plant)}
    right = next(change for change in api.plan(plant, images=images).modules
                 if change.name == "booth-a-right")
    images[(right.bus, right.address)] = right.plan.predicted
    (folder / "images.json").write_text(json.dumps([{"bus": bus, **image.to_json()}
                                                    for (bus, _), image in images.items()]))
    out = folder / "plan.json"
    with pytest.MonkeyPatch.context() as patch:
        patch.setenv("PRC3CFG_LOCK_DIR", str(folder / "locks"))
        patch.setenv("PRC3CFG_STATE_DIR", str(folder / "state"))
        from prc3cfg.cli import main

        with pytest.raises(SystemExit) as done:
            main(["plan", str(folder / "plant.yaml"), "--actual", str(folder / "images.json"), "--out",
                  str(out)])
    assert done.value.code in (0, None)
    return Made(plant, images, out.read_text(), json.loads(out.read_text())["message_count"])


def prove(made: Made, path: Path) -> PlantPlan:
    """What `apply --plan` does with the plan file at `path` before its first write: read it, prove it."""
    return _apply.prove(path, _apply.read_plan(path, made.plant), made.plant, api.select(made.plant),
                        made.images,
                        as_it_stands(made.plant, made.plant.buses))


def test_a_plan_file_is_read_back_as_the_plan_written(made):
    """The writer and the reader agree: each module's steps as messages, its broadcasts, its read-back's
    hash."""
    plan = api.plan(made.plant, images=made.images)
    read = plan_file.parse(json.loads(json.dumps(plan_file.write(plan, [], render))))
    assert [(e.bus, e.address, e.name, e.state_sha256, e.steps, e.broadcasts) for e in read.modules] == [
        (c.bus, c.address, c.name, plan_file.image_sha256(c.actual), tuple(s.message for s in c.steps),
         c.broadcasts) for c in plan.modules]
    # what plan --out wrote
    assert json.loads(made.text) == json.loads(json.dumps(plan_file.write(plan, api.left_alone(made.plant),
                                                                          render)))


def reordered(value: Any) -> Any:
    """Every object's keys in reverse order."""
    if isinstance(value, dict):
        return {key: reordered(value[key]) for key in reversed(value)}
    return [reordered(item) for item in value] if isinstance(value, list) else value


def whole_as_int(value: Any) -> Any:
    """Every float that is a whole number written as an integer, as JavaScript's `JSON.stringify` writes
    it."""
    if isinstance(value, dict):
        return {key: whole_as_int(item) for key, item in value.items()}
    if isinstance(value, list):
        return [whole_as_int(item) for item in value]
    return int(value) if isinstance(value, float) and value.is_integer() else value


#: How other tools write a plan file again: the same data, spelt otherwise (bytes).
RESPELT = {
    "indented by 4": lambda d: json.dumps(d, indent=4).encode(),
    "every object's keys reversed": lambda d: json.dumps(reordered(d)).encode(),
    "CRLF line endings": lambda d: json.dumps(d, indent=1).replace("\n", "\r\n").encode(),
    "a byte-order mark and CRLF": lambda d: ("\ufeff"
                                             + json.dumps(d, indent=2).replace("\n", "\r\n")).encode(),
    "UTF-8 instead of escapes": lambda d: json.dumps(d, ensure_ascii=False).encode(),
    "0 for 0.0": lambda d: json.dumps(whole_as_int(d), separators=(",", ":")).encode(),
    "all of them at once": (
        lambda d: ("\ufeff" + json.dumps(whole_as_int(reordered(d)), indent=4, ensure_ascii=False))
        .replace("\n", "\r\n")
        .encode()
    ),
}


@pytest.mark.parametrize("case", RESPELT, ids=list(RESPELT))
def test_a_plan_file_written_again_by_another_tool_is_the_plan_file(made, tmp_path, case):
    path = tmp_path / "plan.json"
    path.write_bytes(RESPELT[case](json.loads(made.text)))
    assert path.read_bytes() != made.text.encode()  # spelt otherwise
    assert '"estimated_bus_time_s": 0.0' in made.text  # a figure that "0 for 0.0" spells otherwise
    proved = prove(made, path)
    assert proved.message_count == made.message_count
    assert api.plan_document(path)["message_count"] == made.message_count  # and `show` shows it


#: Tools found on the machine that read JSON and write it again, as a CI step may.
TOOLS = {
    "jq": ["jq", "."],
    "node": ["node", "-e",
             "process.stdout.write(JSON.stringify(JSON.parse(require('fs').readFileSync(0, 'utf8')), "
             "null, 2))"],
}


@pytest.mark.parametrize("tool", TOOLS)
def test_a_plan_file_passed_through_jq_or_node_is_the_plan_file(made, tmp_path, tool):
    require(tool)
    path = tmp_path / "plan.json"
    path.write_bytes(subprocess.run(TOOLS[tool], input=made.text.encode(), capture_output=True, check=True,
                                    timeout=60).stdout)
    assert path.read_bytes() != made.text.encode()
    assert prove(made, path).message_count == made.message_count


def places(value: Any, at: tuple = ()) -> list[tuple]:
    """Every place in a JSON document, as the keys and indexes leading there, the document's own first."""
    if isinstance(value, dict):
        return [at] + [p for key, item in value.items() for p in places(item, (*at, key))]
    if isinstance(value, list):
        return [at] + [p for index, item in enumerate(value) for p in places(item, (*at, index))]
    return [at]


def at(document: Any, place: tuple) -> Any:
    for key in place:
        document = document[key]
    return document


def by_field(document: Any, holding: Callable[[Any], bool]) -> dict[str, list[tuple]]:
    """The places whose value `holding` takes, by field: the JSON path with its indexes left out
    ("buses[].modules[].steps[].summary"), so that a key of one place counts as much as one of 200."""
    found: dict[str, list[tuple]] = {}
    for place in places(document):
        if holding(at(document, place)):
            found.setdefault("".join("[]" if isinstance(k, int) else f".{k}" for k in place).lstrip("."),
                             []).append(place)
    return found


def is_value(value: Any) -> bool:
    return not isinstance(value, dict | list)


#: The one value the proof leaves to the file: where the plant file was when the plan was made
#: (a plan made in another checkout applies in this one).
ANYWHERE = "plant_path"


def refusal(made: Made, tmp_path: Path, document: dict[str, Any]) -> str | None:
    """The one line `apply --plan` refuses the plan file `document` with, before the first write; None if it
    proves it."""
    path = tmp_path / "changed.json"
    path.write_text(json.dumps(document, indent=1))
    try:
        prove(made, path)
    except UserError as refused:
        assert str(refused).startswith(f"{path}: ") and "\n" not in str(refused), str(refused)
        return str(refused)
    return None


def changed(document: dict[str, Any], place: tuple, value: Any) -> dict[str, Any]:
    copied = copy.deepcopy(document)
    at(copied, place[:-1])[place[-1]] = value
    return copied


def test_each_field_of_a_plan_file_changed_is_refused(made, tmp_path):
    """Every field, at its first place: a flag flipped, a number or a text changed, a null given a value."""
    document = json.loads(made.text)
    fields = {field: found[0] for field, found in by_field(document, is_value).items() if field != ANYWHERE}
    assert (len(fields) > 30 and "estimated_phases_s.reading" in fields
            and "buses[].modules[].changes.fields[].text" in fields)
    accepted = [field for field, place in fields.items()
                if refusal(made, tmp_path, changed(document, place, other(at(document, place)))) is None]
    assert accepted == []


def test_a_plan_file_s_version_text_is_refused_escaped_on_one_line(made, tmp_path):
    """The version a plan file says made it is the file's text: refused in one line, escaped (the soak tier's
    example: a new line in it split the refusal)."""
    document = changed(json.loads(made.text), ("prc3cfg_version",), "9.9\n\x1b[2J error: forged")
    assert refusal(made, tmp_path, document).endswith("made by prc3cfg 9.9\\n\\x1b[2J error: forged, this is "
                                                      f"{json.loads(made.text)['prc3cfg_version']} — plan "
                                                      "again with this version")


def test_a_bus_the_plant_file_does_not_have_is_refused_escaped_on_one_line(made, tmp_path):
    """The soak tier's example: a bus renamed "\\n" split the refusal that named it."""
    document = changed(json.loads(made.text), ("buses", 0, "name"), "\n\x1b[2J")
    assert "bus \\n\\x1b[2J, module 1 is not among the modules to apply" in refusal(made, tmp_path, document)


def other(value: Any) -> Any:
    """Another value of the kind of `value` (a null becomes a text)."""
    return {bool: lambda: not value, int: lambda: value + 1, float: lambda: value + 0.001,
            str: lambda: value + "0"}.get(type(value), lambda: "")()


def same_value(a: Any, b: Any) -> bool:
    """The same JSON value: 0 and 0.0 are one number; true is no number."""
    numbers = all(type(v) in (int, float) for v in (a, b))
    return a == b and (type(a) is type(b) or numbers)


OTHERS = [None, True, False, 0, -1, 2.5, "", "x", [], {}, ["x"], {"note": "reviewed"}]


def another(value: Any) -> st.SearchStrategy[Any]:
    """A value that is not `value`: of its kind, or of another."""
    kind = {bool: st.just(not value), int: st.integers(-(10**6), 10**6),
            float: st.floats(-1e6, 1e6, allow_nan=False),
            str: st.text(max_size=12)}.get(type(value), st.nothing())
    return st.one_of(kind, st.sampled_from(OTHERS)).filter(lambda other: not same_value(other, value))


def one_value_changed(data: st.DataObject, document: dict[str, Any]) -> dict[str, Any]:
    """`document` with the value of one field, at one of its places, replaced."""
    fields = by_field(document, is_value)
    place = data.draw(st.sampled_from(fields[data.draw(st.sampled_from(sorted(set(fields) - {ANYWHERE})))]))
    return changed(document, place, copy.deepcopy(data.draw(another(at(document, place)))))


def one_key_changed(data: st.DataObject, document: dict[str, Any]) -> dict[str, Any]:
    """`document` with a key left out of one object, or one added to it."""
    objects = by_field(document, lambda value: isinstance(value, dict))
    place = data.draw(st.sampled_from(objects[data.draw(st.sampled_from(sorted(objects)))]))
    copied = copy.deepcopy(document)
    keys = at(copied, place)
    if keys and data.draw(st.booleans()):
        del keys[data.draw(st.sampled_from(sorted(keys)))]
    else:
        names = st.sampled_from(["note", "reviewed_by", "summary"])
        keys[data.draw(names.filter(lambda key: key not in keys))] = "ok"
    return copied


# A few examples in the fast tier (a proof takes 0.17 s: 100 took 17 s of a worker), the soak tier's many
# below.
@settings(max_examples=20, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(data=st.data())
def test_a_plan_file_with_any_one_value_changed_is_refused(made, tmp_path, data):
    assert refusal(made, tmp_path, one_value_changed(data, json.loads(made.text))) is not None


@settings(max_examples=10, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(data=st.data())
def test_a_plan_file_with_a_key_added_or_left_out_is_refused(made, tmp_path, data):
    assert refusal(made, tmp_path, one_key_changed(data, json.loads(made.text))) is not None


@pytest.mark.soak
@settings(suppress_health_check=[HealthCheck.function_scoped_fixture])  # the soak profile's count
@given(data=st.data())
def test_a_plan_file_with_any_one_of_many_more_values_or_keys_changed_is_refused(made, tmp_path, data):
    document = json.loads(made.text)
    changed = data.draw(st.sampled_from([one_value_changed, one_key_changed]))(data, document)
    assert refusal(made, tmp_path, changed) is not None


def test_the_one_value_left_to_the_file_is_where_the_plant_file_was(made, tmp_path):
    """The check above leaves `plant_path` out: a plan made in another checkout names the plant file there."""
    document = json.loads(made.text) | {"plant_path": "/elsewhere/plant.yaml"}
    path = tmp_path / "plan.json"
    path.write_text(json.dumps(document))
    assert prove(made, path).message_count == made.message_count


# -- a targeted plan's `read`: proved by the apply, or shown as what the file says --------------------------
#
# A plan made from a targeted read-back (plan --out after an apply on emulators) holds a `read` section:
# the base it compared with, the modules not read, what it took as known and whose verification that rests
# on (`taken`), and the modules read in full with why (`not_as_verified`). `base`, `modules_not_read` and
# `taken` are worked out again by `apply --plan` from what it reads and the line's record, and a file that
# says otherwise is refused naming the field; `not_as_verified` rests on the record as it was before the
# plan's own read and cannot be: `show` prints it (and `taken`, which only an apply can prove) as what the
# plan file says, and the apply never shows it as its own.

SAFETY_OFFICER = "verified by the safety officer"


@dataclass(frozen=True)
class Targeted:
    emulated: EmulatedPlant = field(repr=False)
    plan: Path  # as plan --out wrote it
    document: dict[str, Any] = field(repr=False)


@pytest.fixture
def targeted(tmp_path, capsys) -> Iterator[Targeted]:
    """The demo plant applied on emulators, then program 1 of three modules changed in the plant file and
    planned with --out: a plan from a targeted read-back, which took 79 programs as known from the record."""
    with emulated_plant(tmp_path) as emulated:
        assert run_cli(capsys, "apply", emulated.path, "--auto-approve", "--allow-axis-release").code == 0
        emulated.path.write_text(emulated.path.read_text().replace("position: 2.1", "position: 2.0", 1))
        out = tmp_path / "plan.json"
        assert run_cli(capsys, "plan", emulated.path, "--out", out).code == 0
        document = json.loads(out.read_text())
        assert document["read"]["taken"] and document["read"]["base"] == RECORD
        yield Targeted(emulated, out, document)


def edited_read(targeted: Targeted, key: str, value: Any) -> Path:
    document = copy.deepcopy(targeted.document)
    if key == "taken":
        document["read"]["taken"][next(iter(document["read"]["taken"]))] = value
    else:
        document["read"][key] = value
    path = targeted.plan.with_name("edited.json")
    path.write_text(json.dumps(document, indent=1))
    return path


def claimed(out: str, words: str) -> None:
    """`words` are on one line of `out`, after "the plan file says", never as prc3cfg's own."""
    lines = [line for line in out.splitlines() if words in line]
    assert lines and all("the plan file says: " in line
                         and line.index("the plan file says: ") < line.index(words) for line in lines), out


def test_show_says_who_a_plan_file_claims_verified_what_it_did_not_read_as_the_files_words(targeted, capsys):
    said = run_cli(capsys, "show", edited_read(targeted, "taken", SAFETY_OFFICER))
    assert said.code == 0, said.err
    claimed(said.out, SAFETY_OFFICER)
    said = run_cli(capsys, "show",
                   edited_read(targeted, "not_as_verified", [f"booth-a/booth-a-top ({SAFETY_OFFICER})"]))
    assert said.code == 0, said.err
    claimed(said.out, SAFETY_OFFICER)
    # its path and user as markdown escapes them
    claimed(run_cli(capsys, "show", "--markdown", targeted.plan).out, "read or verified them")


#: An edit of a proved field of `read`: what `apply --plan` then names.
PROVED_READ = {
    "taken": (SAFETY_OFFICER, "read.taken."),  # the first module taken (`edited_read`)
    "base": (f"the records of the safety officer ({SAFETY_OFFICER})", "read.base"),
    "modules_not_read": (["booth-b/booth-b-pretreat"], "read.modules_not_read"),
}


@pytest.mark.parametrize("key", PROVED_READ)
def test_apply_of_a_plan_file_whose_read_was_edited_names_the_field_and_writes_nothing(targeted, capsys, key):
    value, named = PROVED_READ[key]
    before = targeted.emulated.images()
    refused = run_cli(capsys, "apply", targeted.emulated.path, "--plan", edited_read(targeted, key, value),
                      "--auto-approve")
    assert refused.code == 1, refused.out
    (line,) = refused.problems
    assert named in line and ("nothing was written" in line or line.endswith(plan_file.AGAIN)), line
    assert targeted.emulated.images() == before


def test_what_a_plan_file_says_it_read_in_full_and_why_steers_nothing_and_is_not_said_by_the_apply(targeted,
                                                                                                   capsys):
    """The reasons rest on the record before the plan's own read: the apply cannot work them out again, so it
    applies the proved steps and says only what it saw itself."""
    path = edited_read(targeted, "not_as_verified", [f"booth-a/booth-a-top ({SAFETY_OFFICER})"])
    applied = run_cli(capsys, "apply", targeted.emulated.path, "--plan", path, "--auto-approve")
    assert applied.code == 0, applied.err
    assert SAFETY_OFFICER not in applied.out + applied.err
    assert targeted.emulated.matches_plant()


# -- every text of a plan file is shown escaped
# ---------------------------------------------------------------

#: What no output may hold raw (the test's own account, by Unicode category): control, format — bidirectional
#: overrides and isolates, zero-width joiners —, surrogates, line and paragraph separators; a new line apart.
UNPRINTABLE = {"Cc", "Cf", "Cs", "Zl", "Zp"}
HOSTILE = "\u202eevil\u2066\u2028\x1b[2J\u200d\ufeff"


def raw(output: str) -> list[str]:
    """The characters of `output` no output may hold raw."""
    return sorted({f"U+{ord(c):04X}" for c in output if c != "\n" and unicodedata.category(c) in UNPRINTABLE})


def test_every_text_of_a_plan_file_is_shown_escaped(made, tmp_path, capsys):
    """Each text of the file, in turn, given bidirectional overrides, a line separator, an escape sequence and
    zero-width characters: `show` (human, markdown, JSON) shows the file or refuses it, in words with none of
    them raw."""
    document = json.loads(made.text)
    texts = by_field(document, lambda value: isinstance(value, str))
    assert len(texts) > 15 and "buses[].modules[].changes.fields[].text" in texts
    path = tmp_path / "hostile.json"
    for field_, places_ in texts.items():
        path.write_text(json.dumps(changed(document, places_[0], at(document, places_[0]) + HOSTILE)))
        for output in ([], ["--markdown"], ["--json"]):
            said = run_cli(capsys, "show", path, *output)
            assert said.code in (0, 1) and raw(said.out + said.err) == [], (field_, output, said)


def test_a_plan_file_of_hostile_texts_reaches_the_terminal_as_escapes(made, tmp_path):
    """Every text `show` shows at once, from a process of its own: its bytes hold no override, separator or
    escape."""
    document = json.loads(made.text)
    document["plant"] += HOSTILE
    document["left_alone"] = [f"booth-a/old{HOSTILE} is no longer in the plant file"]
    document["axis_releases"] = [name + HOSTILE for name in document["axis_releases"]]
    for bus in document["buses"]:
        for module in bus["modules"]:
            module["name"] += HOSTILE
            for f in module["changes"]["fields"]:
                f["text"] += HOSTILE
    path = tmp_path / "hostile.json"
    path.write_text(json.dumps(document, ensure_ascii=False))
    for output in ([], ["--markdown"], ["--json"]):
        done = subprocess.run([sys.executable, "-m", "prc3cfg", "show", str(path), *output],
                              capture_output=True, timeout=120)
        assert done.returncode == 0, done.stderr
        assert "\\u202eevil\\u2066\\u2028" in done.stdout.decode() or "\\\\u202eevil" in done.stdout.decode()
        assert raw(done.stdout.decode()) == [] and not any(c.encode() in done.stdout for c in HOSTILE
                                                           if raw(c)), output


# -- mutations of a real plan file, shown and applied on the emulators ---------------------------------------

#: The values that are the file's words (docs/files.md): an edit there may be applied; anywhere else it
#: never writes.
WORDS = ("plant_path", "left_alone", "read.not_as_verified")
#: What a mutation puts in: hostile text, values of other kinds, deep, long and wide values.
MUTANTS = st.one_of(
    st.sampled_from([None, True, 0, -1, 2.5, "", [], {}, SAFETY_OFFICER, HOSTILE, "\u202e", "\u2028",
                     "\x1b[2J", "\u200d"]),
    st.text(st.characters(whitelist_categories=["Cc", "Cf", "Zl", "Zp", "Ll"]), max_size=12),
    st.integers(8, 100_000).map(lambda n: Deep(n)),
    st.sampled_from([65_537, 2_000_000]).map(lambda n: "x" * n),
    st.sampled_from([100_001, 300_000]).map(lambda n: [0] * n),
)


@dataclass(frozen=True)
class Deep:
    """Lists in lists, `levels` deep: written as text (`as_text`), as Python's own JSON would recurse that
    deep."""

    levels: int


def as_text(document: dict[str, Any]) -> str:
    deep: list[int] = []
    text = json.dumps(document, default=lambda value: f"Deep-{len(deep)}"
                      if deep.append(value.levels) is None else "")
    for index, levels in enumerate(deep):
        text = text.replace(json.dumps(f"Deep-{index}"), "[" * levels + "]" * levels)
    return text


def mutated(data: st.DataObject, document: dict[str, Any]) -> tuple[dict[str, Any], str]:
    """`document` with a value replaced, a key left out or one added, at a place drawn from all of them; and
    that place's field ("buses[].modules[].name")."""
    copied = copy.deepcopy(document)
    place = data.draw(st.sampled_from(places(copied)[1:]))
    parent, key = at(copied, place[:-1]), place[-1]
    how = data.draw(st.sampled_from(["replace", "drop", "add"] if isinstance(parent, dict) else ["replace"]))
    if how == "drop":
        del parent[key]
    elif how == "add":
        names = st.sampled_from(["note", "reviewed_by", "\u202ereviewed"])
        parent[data.draw(names.filter(lambda k: k not in parent))] = SAFETY_OFFICER
    else:
        parent[key] = data.draw(MUTANTS.filter(lambda value: not same_value(value, at(document, place))))
    return copied, "".join("[]" if isinstance(k, int) else f".{k}" for k in place).lstrip(".")


@contextlib.contextmanager
def as_found(targeted: Targeted) -> Iterator[dict[tuple[str, int], ModuleImage]]:
    """The modules' images now; then the modules and the line's record put back as the plan found them, for
    the next example."""
    before, state = targeted.emulated.images(), targeted.plan.parent / "state"
    kept = targeted.plan.parent / "state-before"
    shutil.rmtree(kept, ignore_errors=True)
    shutil.copytree(state, kept)
    try:
        yield before
    finally:
        for (bus, address), image in before.items():
            targeted.emulated.emulators[bus].update(address, image=image)
        shutil.rmtree(state)
        shutil.copytree(kept, state)


def shown_and_applied(targeted: Targeted, capsys: pytest.CaptureFixture, data: st.DataObject) -> None:
    document, where = mutated(data, targeted.document)
    path = targeted.plan.with_name("mutated.json")
    path.write_text(as_text(document))
    with as_found(targeted) as before:
        for args in (["show", path], ["show", path, "--markdown"],
                     ["apply", targeted.emulated.path, "--plan", path, "--auto-approve",
                      "--allow-axis-release"]):
            done = run_cli(capsys, *args)
            assert done.code in (0, 1) and raw(done.out + done.err) == [], (where, args, done)
            assert done.code == 0 or len(done.problems) == 1, (where, args, done.err)
        if targeted.emulated.images() != before:  # written: only where the file's words changed
            assert where.startswith(WORDS) and targeted.emulated.matches_plant(), where


@settings(max_examples=6, deadline=None,
          suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow])
@given(data=st.data())
def test_a_mutated_plan_file_is_shown_escaped_and_writes_only_where_its_words_changed(targeted, capsys, data):
    """A value replaced (hostile text, another kind, 3,000 deep, 2 MB long, 300,000 wide), a key left out or
    added, anywhere: `show` and `apply --plan` on the emulators answer in words — no traceback, no raw
    control or bidirectional character — and nothing is written unless the change was to the file's words."""
    shown_and_applied(targeted, capsys, data)


@pytest.mark.soak
@settings(max_examples=100, deadline=None,
          suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow])
@given(data=st.data())
def test_many_mutated_plan_files_are_shown_escaped_and_write_only_where_their_words_changed(targeted, capsys,
                                                                                            data):
    shown_and_applied(targeted, capsys, data)


# -- the review: the file's words, said with a digest; the steps and figures proved -------------------------
#
# What a plan file holds for people to read beside a module's steps — its `changes`, its `warning` and its
# steps' `summary` — is the file's claim about itself, written with the SHA-256 of that text
# (`review_sha256`, docs/files.md: worked out here as the docs say, not by prc3cfg's function). `apply --plan`
# proves the steps and figures against the plan it makes now, and of the words only that they are the text
# their digest was written for: a plan file worded by an earlier prc3cfg applies; words edited after the
# plan was made are refused, naming where, and `show` says so.

#: How an earlier prc3cfg might have worded the review: each replacement one sentence of it.
EARLIER_WORDS = {" → ": " to ",
                 "releases the axes: travel to reference point required after apply": "releases the axes — a "
                 "reference travel is needed after the apply", "write ": "send "}


def review_digest(module: dict[str, Any]) -> str:
    """A module's `review_sha256` as docs/files.md defines it."""
    review = {"changes": module["changes"], "warning": module["warning"],
              "summaries": [step["summary"] for step in module["steps"]]}
    return hashlib.sha256(json.dumps(review, sort_keys=True, separators=(",", ":")).encode()).hexdigest()


def reworded(value: Any) -> Any:
    """`value` with every text worded as `EARLIER_WORDS` has it."""
    if isinstance(value, str):
        for now, then in EARLIER_WORDS.items():
            value = value.replace(now, then)
        return value
    if isinstance(value, list):
        return [reworded(item) for item in value]
    return {key: reworded(item) for key, item in value.items()} if isinstance(value, dict) else value


def as_worded_earlier(document: dict[str, Any]) -> dict[str, Any]:
    """`document` as an earlier prc3cfg would have written it: each module's review worded otherwise, its
    digest that of the text as written — the steps, figures and names the same."""
    copied = copy.deepcopy(document)
    for bus in copied["buses"]:
        for module in bus["modules"]:
            module["changes"], module["warning"] = reworded(module["changes"]), reworded(module["warning"])
            for step in module["steps"]:
                step["summary"] = reworded(step["summary"])
            module["review_sha256"] = review_digest(module)
        for broadcast in bus.get("broadcasts", []):
            broadcast["summary"] = reworded(broadcast["summary"])
    return copied


def modules_of(document: dict[str, Any]) -> list[tuple[tuple, dict[str, Any]]]:
    """Each module of `document`, with its place."""
    return [(("buses", b, "modules", m), module) for b, bus in enumerate(document["buses"])
            for m, module in enumerate(bus["modules"])]


def test_a_plan_file_worded_by_an_earlier_prc3cfg_is_proved(made, tmp_path):
    """The review words prc3cfg renders now are not those of the file: the steps and figures are the plan's,
    and the words the text their digest was written for — proved (it was refused: "… is not what prc3cfg
    wrote")."""
    document = json.loads(made.text)
    # as the docs say
    assert all(module["review_sha256"] == review_digest(module) for _, module in modules_of(document))
    earlier = as_worded_earlier(document)
    assert earlier != document and any(" to " in json.dumps(module["changes"])
                                       for _, module in modules_of(earlier))
    assert any(module["warning"] and "reference travel" in module["warning"]
               for _, module in modules_of(earlier))
    assert refusal(made, tmp_path, earlier) is None


def test_an_edited_review_or_a_digest_another_is_refused_naming_where(made, tmp_path):
    """One text of a module's review changed and its digest left as written, or the digest alone changed:
    refused in one line naming that module's `review_sha256` by its path."""
    document = json.loads(made.text)
    place = next(p for p, m in modules_of(document) if m["changes"]["fields"])
    named = f"buses[{place[1]}].modules[{place[3]}].review_sha256"
    for edited in (changed(document, (*place, "changes", "fields", 0, "text"),
                           "speed 0.050 m/s → 0.050 m/s (unchanged)"),
                   changed(document, (*place, "steps", 0, "summary"), "read the module's name (no change)"),
                   changed(document, (*place, "review_sha256"), "0" * 64)):
        refused = refusal(made, tmp_path, edited)
        assert (refused is not None and named in refused
                and "changed after the plan was made" in refused), refused


@pytest.mark.parametrize("edit", ["a step left out", "a step's message", "a figure", "a name"])
def test_an_edited_step_or_figure_is_refused_though_its_review_digest_was_made_again(made, tmp_path, edit):
    document = json.loads(made.text)
    place = next(p for p, m in modules_of(document) if len(m["steps"]) > 1)
    edited = copy.deepcopy(document)
    entry = at(edited, place)
    if edit == "a step left out":
        del entry["steps"][-1]
    elif edit == "a step's message":
        entry["steps"][-1]["message"] = entry["steps"][0]["message"]
    elif edit == "a figure":
        entry["estimated_bus_time_s"] += 0.001
    else:
        entry["name"] += "-spare"
    entry["review_sha256"] = review_digest(entry)
    assert refusal(made, tmp_path, edited) is not None


def test_a_plan_file_without_review_digests_is_refused_as_made_by_an_older_prc3cfg(made, tmp_path):
    document = json.loads(made.text)
    for _, module in modules_of(document):
        del module["review_sha256"]
    refused = refusal(made, tmp_path, document)
    assert (refused is not None and "made by an older prc3cfg" in refused
            and refused.endswith("plan again")), refused


def written(targeted: Targeted, document: dict[str, Any], name: str) -> Path:
    path = targeted.plan.with_name(name)
    path.write_text(json.dumps(document, indent=1))
    return path


def test_a_plan_file_worded_by_an_earlier_prc3cfg_applies_on_the_emulators_said_in_its_own_words(targeted,
                                                                                                 capsys):
    path = written(targeted, as_worded_earlier(targeted.document), "earlier.json")
    applied = run_cli(capsys, "apply", targeted.emulated.path, "--plan", path, "--auto-approve",
                      "--allow-axis-release")
    assert applied.code == 0, applied.err
    assert targeted.emulated.matches_plant()
    # its own words
    assert (" to " not in "".join(line for line in applied.out.splitlines() if "position" in line)
            and "→" in applied.out)


def test_an_edited_review_is_refused_by_the_apply_and_marked_by_show(targeted, capsys):
    document = copy.deepcopy(targeted.document)
    (place, module), *_ = [(p, m) for p, m in modules_of(document) if m["changes"]["fields"]]
    module["changes"]["fields"][0]["text"] = SAFETY_OFFICER
    path = written(targeted, document, "edited.json")
    before = targeted.emulated.images()
    refused = run_cli(capsys, "apply", targeted.emulated.path, "--plan", path, "--auto-approve",
                      "--allow-axis-release")
    assert refused.code == 1 and targeted.emulated.images() == before
    (line,) = refused.problems
    assert (f"buses[{place[1]}].modules[{place[3]}].review_sha256" in line
            and "nothing was written" in line), line
    for output in ([], ["--markdown"]):
        said = run_cli(capsys, "show", path, *output)
        assert said.code == 0, said.err
        claimed(said.out, SAFETY_OFFICER)  # never as prc3cfg's words
        (warned,) = [line for line in said.out.splitlines() if "changed after the plan was made" in line]
        assert module["name"] in warned and "read the steps" in warned, warned
    intact = run_cli(capsys, "show", targeted.plan)
    assert ("changed after the plan was made" not in intact.out
            and "the review text is as the plan was made" in intact.out), intact.out


def test_show_of_a_plan_file_without_review_digests_says_so(targeted, capsys):
    document = copy.deepcopy(targeted.document)
    for _, module in modules_of(document):
        del module["review_sha256"]
    said = run_cli(capsys, "show", written(targeted, document, "older.json"))
    assert said.code == 0, said.err
    assert "no review digest" in said.out, said.out
    text = next(f["text"] for _, m in modules_of(document) for f in m["changes"]["fields"])
    claimed(said.out, text)


#: How a module's review, its steps or the figures may be mutated, and whether the apply then proves the plan.
def review_mutated(data: st.DataObject, document: dict[str, Any]) -> tuple[dict[str, Any], str]:
    """`document` with one module's review words, or a value elsewhere, changed; the digest made again or
    not; and the verdict that must follow: "proved" (the words, with their digest made again), "refused"."""
    copied = copy.deepcopy(document)
    module = data.draw(st.sampled_from([m for _, m in modules_of(copied)]))
    again = data.draw(st.booleans())
    if data.draw(st.booleans()):  # the words
        words = [p for p in places({"changes": module["changes"], "warning": module["warning"],
                                    "steps": module["steps"]})
                 if p and is_value(at({"changes": module["changes"], "warning": module["warning"],
                                       "steps": module["steps"]}, p))
                 and (p[0] != "steps" or p[-1] == "summary")]
        where = data.draw(st.sampled_from(words))
        texts = st.sampled_from([SAFETY_OFFICER, HOSTILE, "", "speed 0 → 9"])
        at(module, where[:-1])[where[-1]] = data.draw(texts.filter(lambda text: text != at(module, where)))
        verdict = "proved" if again else "refused"
    else:  # a step, a figure, a name, a hash: anything else but where the plant file was
        fields = by_field(copied, is_value)
        kept = {ANYWHERE, "buses[].modules[].review_sha256", "left_alone", "read.not_as_verified"}
        chosen = data.draw(st.sampled_from(sorted(f for f in fields if f not in kept
                                                  and not f.endswith("summary")
                                                  and ".changes" not in f and not f.endswith(".warning"))))
        spot = data.draw(st.sampled_from(fields[chosen]))
        at(copied, spot[:-1])[spot[-1]] = other(at(copied, spot))
        verdict = "refused"
    if again:
        for _, entry in modules_of(copied):
            entry["review_sha256"] = review_digest(entry)
    return copied, verdict


def review_verdicts(made: Made, tmp_path: Path, data: st.DataObject) -> None:
    document, verdict = review_mutated(data, json.loads(made.text))
    event(verdict)
    refused = refusal(made, tmp_path, document)
    assert (refused is None) == (verdict == "proved"), (verdict, refused)


@settings(max_examples=12, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(data=st.data())
def test_a_plan_file_s_review_steps_or_figures_mutated_get_their_verdicts(made, tmp_path, data):
    review_verdicts(made, tmp_path, data)


@pytest.mark.soak
# 40 ms each: 16 s
@settings(max_examples=400, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(data=st.data())
def test_many_plan_files_with_review_steps_or_figures_mutated_get_their_verdicts(made, tmp_path, data):
    review_verdicts(made, tmp_path, data)


@pytest.mark.soak
@settings(max_examples=16, deadline=None,
          suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow])
@given(data=st.data())
def test_plan_files_with_review_steps_or_figures_mutated_are_applied_by_a_process_as_their_verdicts_say(
    targeted, data
):
    """`prc3cfg apply --plan` in a process of its own, on the emulators: a review worded otherwise with its
    digest made again writes the plan; an edited review, step or figure writes nothing and says why in one
    line."""
    document, verdict = review_mutated(data, targeted.document)
    event(verdict)
    path = written(targeted, document, "mutated.json")
    with as_found(targeted) as before:
        done = subprocess.run([sys.executable, "-m", "prc3cfg", "apply", str(targeted.emulated.path),
                               "--plan", str(path), "--auto-approve",
                               "--allow-axis-release"], capture_output=True, text=True,
                              timeout=300)
        problems = [line for line in done.stderr.splitlines() if not line.startswith("note: ")]
        if verdict == "proved":
            assert done.returncode == 0 and targeted.emulated.matches_plant(), done.stderr
        else:
            assert (done.returncode == 1 and len(problems) == 1
                    and targeted.emulated.images() == before), done.stderr
