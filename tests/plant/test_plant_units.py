"""Human ↔ device units: every device value in range survives device → human → device, exactly."""

from __future__ import annotations

from decimal import Decimal

import pytest
from hypothesis import given
from hypothesis import strategies as st

from prc3cfg.core.device import VALUE_RANGES, widest_range
from prc3cfg.core.image import SYSTEM_KEYS
from prc3cfg.core.units import (
    DISTANCE,
    PROGRAM_QUANTITIES,
    QUANTITIES,
    SYSTEM_QUANTITIES,
    Quantity,
    function_output,
    human_text,
    plant_value,
    split_function_output,
)
from prc3cfg.plant import plant_schema
from prc3cfg.plant.models import FunctionOutputSpec, ProgramSpec, SystemSpec

#: Which model validates each quantity's key, so the round trip goes through the plant file's rules too.
MODEL_OF = {q.key: SystemSpec for q in SYSTEM_QUANTITIES} | {q.key: ProgramSpec for q in PROGRAM_QUANTITIES}
MODEL_OF["distance"] = FunctionOutputSpec


@st.composite
def quantity_and_device_value(draw: st.DrawFn) -> tuple[Quantity, int]:
    quantity = draw(st.sampled_from(list(QUANTITIES.values())))
    return quantity, draw(st.integers(quantity.lo, quantity.hi))


@given(quantity_and_device_value())
def test_device_to_human_to_device_is_the_identity(case: tuple[Quantity, int]) -> None:
    quantity, device = case
    assert quantity.to_device(quantity.to_human(device)) == device


@given(quantity_and_device_value())
def test_the_human_text_read_by_the_plant_models_gives_the_device_value_back(
    case: tuple[Quantity, int],
) -> None:
    """What `show` prints, read back as a plant file reads a number (Decimal of its text)."""
    quantity, device = case
    text = human_text(quantity.symbol, device).split(" ")[0]
    value = text == "true" if quantity.boolean else Decimal(text)
    extra = {"action": "set"} if quantity is DISTANCE else {}
    validated = getattr(MODEL_OF[quantity.key].model_validate({quantity.key: value, **extra}), quantity.key)
    assert quantity.to_device(validated) == device


@given(st.integers(0, 1999))
def test_function_outputs_round_trip(device: int) -> None:
    action, distance = split_function_output(device)
    assert function_output(action, distance) == device


@given(st.sampled_from(["F1", "F2"]), st.integers(*widest_range("F1")))
def test_a_function_output_as_a_plant_file_writes_it_gives_the_device_value_back(symbol: str,
                                                                                 device: int) -> None:
    """`plant_value`, what import and adopt write, read back as the plant file's F1/F2 mapping."""
    written = plant_value(symbol, device)
    assert isinstance(written, dict)
    spec = FunctionOutputSpec.model_validate(written)
    assert function_output(spec.action, spec.distance) == device


def test_the_table() -> None:
    assert tuple(q.symbol for q in SYSTEM_QUANTITIES) == SYSTEM_KEYS
    assert tuple(q.symbol for q in PROGRAM_QUANTITIES) == ("P", "V", "Vr", "T")
    assert QUANTITIES["position"].human_hi == Decimal("9.999")
    assert QUANTITIES["dwell"].to_human(20) == Decimal("2.0")
    assert human_text("S6", 1500) == "1.500 m/s²"
    assert human_text("S8", 1) == "true"
    assert human_text("S3", 754) == "754"


def test_every_plant_file_bound_is_the_device_range_converted() -> None:
    """One table of ranges, the device model's: the plant file's bounds (its JSON Schema, which the
    models check) are each field's range on a module — P and V on the widest S1, S4 and S5 — in
    human units; a distance spans F1's range from "reset at the least" to "set at the most"."""
    assert widest_range("P") == (0, VALUE_RANGES["S1"][1])
    assert widest_range("V") == (VALUE_RANGES["S5"][0], VALUE_RANGES["S4"][1])
    definitions = plant_schema()["definitions"]
    fields = {"SystemSpec": SYSTEM_QUANTITIES, "ProgramSpec": PROGRAM_QUANTITIES,
              "FunctionOutputSpec": (DISTANCE,)}
    for model, quantities in fields.items():
        for quantity in quantities:
            schema = definitions[model]["properties"][quantity.key]
            if quantity.boolean:  # S8: false and true
                assert schema["type"] == "boolean" and widest_range(quantity.symbol) == (0, 1)
                continue
            low, high = (quantity.lo, quantity.hi) if quantity is DISTANCE else widest_range(quantity.symbol)
            bounds = (Decimal(str(schema["minimum"])), Decimal(str(schema["maximum"])))
            assert bounds == (low * quantity.step, high * quantity.step), quantity.key
    assert widest_range("F1") == widest_range("F2") == (
        function_output("reset", DISTANCE.human_lo), function_output("set", DISTANCE.human_hi))


def test_manual_examples_of_function_outputs() -> None:
    """docs/protocol.md "Values": F1 = 1010 sets 0.010 m after START, 50 resets at 0.050 m."""
    assert function_output("set", Decimal("0.010")) == 1010
    assert function_output("reset", Decimal("0.050")) == 50
    assert human_text("F1", 1050) == "set at 0.050 m"


@pytest.mark.parametrize(("key", "text"), [("position", "0.0005"), ("dwell", "2.05"), ("speed", "0.1001")])
def test_no_rounding(key: str, text: str) -> None:
    with pytest.raises(ValueError, match="not a whole number"):
        QUANTITIES[key].to_device(Decimal(text))


def test_every_number_field_is_annotated_with_the_type_its_validator_hands_back() -> None:
    """mypy reads a number field's annotation (`Annotated[int | None, _number(...)]`); the validator
    decides what the value is (a quantity's `integer` for `_quantity`): the two must agree."""
    from typing import get_args, get_type_hints

    from prc3cfg.plant import models

    checked = 0
    for model in vars(models).values():
        if not (isinstance(model, type) and issubclass(model, models.FileModel)):
            continue
        for name, hint in get_type_hints(model, include_extras=True).items():
            numbers = [m for m in getattr(hint, "__metadata__", ()) if isinstance(m, models._Number)]
            annotated = get_args(hint)[0]  # `int | None`, or `int`
            types = set(get_args(annotated)) - {type(None)} if get_args(annotated) else {annotated}
            for number in numbers:
                assert types == {number.out}, (f"{model.__name__}.{name} is annotated {annotated}, its "
                                               f"validator gives {number.out}")
                checked += 1
    assert checked > 20
