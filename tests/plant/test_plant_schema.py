"""The JSON Schema: up to date, draft-07, accepts every example plant, rejects unknown keys."""

from __future__ import annotations

import json
from pathlib import Path

import jsonschema
import pytest
import yaml
from hypothesis import given, settings
from hypothesis import strategies as st
from pydantic import ValidationError

from prc3cfg.plant import plant_schema, plant_schema_text
from prc3cfg.plant.models import BusLine

ROOT = Path(__file__).parents[2]
SCHEMA_FILE = ROOT / "schemas" / "plant.schema.json"
PLANTS = sorted((ROOT / "plants").rglob("*.yaml"))
VALIDATOR = jsonschema.Draft7Validator(plant_schema())


def as_json(path: Path) -> dict:
    """The plant as a YAML language server sees it: JSON, so program numbers are string keys."""
    return json.loads(json.dumps(yaml.safe_load(path.read_text())))


def test_the_committed_schema_is_the_generated_one() -> None:
    assert SCHEMA_FILE.read_text() == plant_schema_text(), "run: python -m prc3cfg schema > schemas/plant.schema.json"


def test_it_is_a_draft_07_schema_without_later_keywords() -> None:
    schema = plant_schema()
    jsonschema.Draft7Validator.check_schema(schema)
    assert schema["$schema"] == "http://json-schema.org/draft-07/schema#"
    text = SCHEMA_FILE.read_text()
    for later in ("$defs", "prefixItems", "unevaluatedProperties", "dependentRequired", "multipleOf"):
        assert later not in text
    assert '"string"' not in json.dumps(schema["definitions"]["ProgramSpec"])  # numbers only, no anyOf string


def test_objects_forbid_unknown_keys_and_program_keys_have_names() -> None:
    definitions = plant_schema()["definitions"]
    objects = [d for d in definitions.values() if d.get("type") == "object"]
    objects.append(definitions["ChainSpec"]["anyOf"][1])
    assert all(d["additionalProperties"] is False for d in objects)
    programs = definitions["ModuleSpec"]["properties"]["programs"]
    assert programs["propertyNames"] == {"pattern": "^([1-9]|[1-5][0-9]|6[0-4])$"}


@pytest.mark.parametrize("path", PLANTS, ids=lambda p: p.name)
def test_accepts_every_plant_and_names_the_schema_in_its_first_line(path: Path) -> None:
    VALIDATOR.validate(as_json(path))
    first = path.read_text().splitlines()[0]
    prefix = "# yaml-language-server: $schema="
    assert first.startswith(prefix)
    assert (path.parent / first.removeprefix(prefix)).resolve() == SCHEMA_FILE.resolve()


@pytest.mark.parametrize(
    ("change", "where"),
    [
        (lambda p: p["buses"][0]["modules"][0].update(sped=1), "modules"),
        (lambda p: p["buses"][0]["modules"][0].update(programs={"1": {"position": 1.0, "sped": 0.3}}), "sped"),
        (lambda p: p["buses"][0]["modules"][0].update(programs={"65": {"position": 1.0, "speed": 0.3}}), "65"),
        (lambda p: p["buses"][0].update(framing="modbus"), "modbus"),
        (lambda p: p["buses"][0]["modules"][0].update(system={"max_speed": 0.7}), "0.7"),
        (lambda p: p.update(site="hall 4"), "site"),
        (lambda p: p["buses"][0].update(port="emulator://../../etc"), "emulator://../../etc"),
        (lambda p: p["buses"][0].update(port="socket://127.0.0.1"), "socket://127.0.0.1"),
        (lambda p: p["buses"][0].update(port="rfc2217://host:notaport"), "rfc2217://host:notaport"),
    ],
)
def test_rejects_what_the_loader_rejects(change, where: str) -> None:
    plant = as_json(ROOT / "plants" / "demo-line.yaml")
    change(plant)
    errors = list(VALIDATOR.iter_errors(plant))
    assert errors and any(where in str(e.message) or where in str(list(e.path)) for e in errors)


def test_a_chain_may_be_a_list_or_a_mapping() -> None:
    chain = {"$ref": "#/definitions/ChainSpec", "definitions": plant_schema()["definitions"]}
    validator = jsonschema.Draft7Validator(chain)
    assert validator.is_valid([1, 2]) and validator.is_valid({"programs": [3], "loop": True})
    assert not validator.is_valid([]) and not validator.is_valid({"programs": [1], "lop": True})


JUNK = ["", "/", "?logging=debug", "#", "@", "..", ".", "-", "_", "\n", "\t", " ", "a", "é", "٣", ":", "[", "]"]
PORTS = st.builds(
    "".join,
    st.tuples(
        st.sampled_from(["socket://", "rfc2217://", "emulator://", "SOCKET://", "/dev/ttyUSB", ""]),
        st.sampled_from(["host", "127.0.0.1", "[::1]", "booth-a", ".x", "", "a_b.c"]),
        st.sampled_from([":", ""]),
        st.sampled_from(["7001", "0", "65535", "70000", "", "x"]),
        st.lists(st.sampled_from(JUNK), max_size=2).map("".join),
    ),
)


@settings(max_examples=500, derandomize=True, deadline=None)
@given(PORTS)
def test_the_schema_takes_every_port_the_loader_takes(port: str) -> None:
    try:
        BusLine.model_validate({"name": "a", "port": port})
    except ValidationError:
        return
    plant = {"plant": "p", "buses": [{"name": "a", "port": port, "modules": [{"address": 1, "name": "m"}]}]}
    assert VALIDATOR.is_valid(plant), port
