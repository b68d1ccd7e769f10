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
from prc3cfg.shell.plant_files import load_plant

ROOT = Path(__file__).parents[2]
SCHEMA_FILE = ROOT / "schemas" / "plant.schema.json"
PLANTS = sorted((ROOT / "plants").rglob("*.yaml"))
VALIDATOR = jsonschema.Draft7Validator(plant_schema())


def as_json(path: Path) -> dict:
    """The plant as a YAML language server sees it: JSON, so program numbers are string keys."""
    return json.loads(json.dumps(yaml.safe_load(path.read_text())))


def test_the_committed_schema_is_the_generated_one() -> None:
    assert SCHEMA_FILE.read_text() == plant_schema_text(), ("run: python -m prc3cfg schema > "
                                                            "schemas/plant.schema.json")


def test_it_is_a_draft_07_schema_without_later_keywords() -> None:
    schema = plant_schema()
    jsonschema.Draft7Validator.check_schema(schema)
    assert schema["$schema"] == "http://json-schema.org/draft-07/schema#"
    assert schema["$id"] == "urn:prc3cfg:plant-file"  # stable in every version: editors and caches key on it
    text = SCHEMA_FILE.read_text()
    for later in ("$defs", "prefixItems", "unevaluatedProperties", "dependentRequired", "multipleOf"):
        assert later not in text
    assert '"string"' not in json.dumps(schema["definitions"]["ProgramSpec"])  # numbers only, no anyOf string


def test_objects_forbid_unknown_keys_and_program_keys_have_names() -> None:
    definitions = plant_schema()["definitions"]
    objects = [d for d in definitions.values() if d.get("type") == "object"]
    objects.append(definitions["ChainSpec"]["anyOf"][1])
    assert all(d["additionalProperties"] is False for d in objects)
    for owner in ("ModuleSpec", "ProfileSpec"):
        keys = jsonschema.Draft7Validator(definitions[owner]["properties"]["programs"]["propertyNames"])
        # a YAML editor's integer keys, JSON's strings
        assert all(keys.is_valid(k) for k in (1, 64, "1", "64"))
        assert not any(keys.is_valid(k) for k in (0, 65, 1.5, "0", "65", "01", "1.5", "abc", True))


def properties(schema: dict, where: str = "") -> list[tuple[str, dict]]:
    """Every key a plant file may write, with its schema: (path, schema)."""
    found = []
    for name, value in schema.get("properties", {}).items():
        found.append((f"{where}.{name}", value))
    for name, value in schema.get("definitions", {}).items():
        found += properties(value, name)
    for branch in schema.get("anyOf", []):
        found += properties(branch, where)
    return found


KEYS = properties(plant_schema())


def resolved(value: dict) -> dict:
    return {**value, "definitions": plant_schema()["definitions"]}


def a_value(value: dict) -> bool:
    """Not an object or a list of objects, whose keys are checked one by one."""
    items = value.get("items", {})
    return "$ref" not in value and value.get("type") != "object" and "$ref" not in items


@pytest.mark.parametrize(("where", "value"), KEYS, ids=[w for w, _ in KEYS])
def test_every_key_has_a_description_and_every_value_a_valid_example(where: str, value: dict) -> None:
    assert value.get("description"), f"{where} has no description"
    if a_value(value):  # what yaml-language-server completes it with: one or the other, not both
        assert ("examples" in value) != ("default" in value), (f"{where}: an editor would complete it "
                                                               "with nothing")
    checker = jsonschema.Draft7Validator(resolved(value))
    for example in value.get("examples", []) + ([value["default"]] if "default" in value else []):
        assert checker.is_valid(example), (where, example)


def test_the_factory_defaults_are_the_devices():
    system = plant_schema()["definitions"]["SystemSpec"]["properties"]
    assert {k: v["default"] for k, v in system.items()} == {
        "upper_reversing_point": 0.4, "reference_point": 0.05, "increment_pulses": 754, "max_speed": 0.6,
        "min_speed": 0.01, "acceleration": 1.5, "circuit_gain": 1000, "alarm": False, "sync_increment": 583,
        "sync_circuit_gain": 1100, "sync_conveyor_sequence": 0.01,
    }  # docs/protocol.md's factory table


def from_examples(value: dict) -> object:
    """A value made of the schema's first examples, every optional key written."""
    value = plant_schema()["definitions"][value["$ref"].rpartition("/")[2]] if "$ref" in value else value
    if "examples" in value or "default" in value:
        return value["examples"][0] if "examples" in value else value["default"]
    if "anyOf" in value:
        return from_examples(value["anyOf"][-1])
    if value.get("type") == "array":
        return [from_examples(value["items"])]
    if "properties" in value:
        return {k: from_examples(v) for k, v in value["properties"].items()}
    key = 1 if "integer" in value["propertyNames"].get("type", ()) else "booth"  # a program, a profile
    return {key: from_examples(value["additionalProperties"])}


def test_a_plant_written_from_the_examples_alone_loads(tmp_path) -> None:
    """What an editor completes with is a plant prc3cfg takes: no 0 where 0 is out of range."""
    plant = from_examples(plant_schema())
    bus = plant["buses"][0]
    # the gateway's framing
    bus |= {"framing": "open-driver", "modules": [{**bus["modules"][0], "profiles": "booth"}]}
    for layer in (plant["profiles"]["booth"], bus["modules"][0]):
        del layer["chains"]  # they name programs 1..3, where the example lists program 1 only
    del bus["modules"][0]["programs"][1]["next"]  # a program's next and a chain are alternatives
    source = tmp_path / "plant.yaml"
    source.write_text(yaml.safe_dump(plant, sort_keys=False))
    loaded = load_plant(source)
    assert loaded.buses[0].modules[0].desired_programs()[1].P == 150 and VALIDATOR.is_valid(as_json(source))


JUNK = ["", "/", "?logging=debug", "#", "@", "..", ".", "-", "_", "\n", "\t", " ", "a", "é", "٣", ":", "[",
        "]"]
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
