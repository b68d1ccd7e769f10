"""The plant file as written (docs/plant-files.md): pydantic models, their ranges, their JSON Schema.

Owns the structure of a plant file and every rule about one value on its own: key names, types, ranges in
human units (from `units.QUANTITIES`), whole device units, and the draft-07 schema generated from these models
(`plant_schema`). Does not own rules that span values (P ≤ S1, chains, unique names: `rules`), profile
layering (`profiles`) or where a value is in the file (`loader`).

The schema is written for editors (yaml-language-server): every key described, every value with its range, and
either the default a key left out stands for (the factory's S1..S12) or an example, which completion inserts;
program keys checked as YAML integers and JSON strings; `$id` the same in every version.

Every model is frozen and forbids unknown keys. A key left out is `None` ("not given here"), so profiles can
be layered: "given" and "given as the default" differ.

Numbers arrive as `Decimal` (the loader keeps the text as written) or `int`, of at most 28 digits written out
(`scalars.MAX_DIGITS`), so that no conversion here is slow or infinite. A number field rejects booleans and
strings, checks its range and its step, and hands back an `int`, an exact `Decimal` (human units) or, for the
bus's times, a `float` of seconds. Its failures are `PydanticCustomError`s whose type names the problem
(`not_number`, `not_finite`, `out_of_range`, `not_whole`, `not_allowed`; `port_handler`, `port_not_device`,
`port_not_a_line`, `tcp_port`, `emulator_name` for a port) and whose context carries the words; `messages`
turns them into sentences.

Decisions about the bus (docs/line.md): `port` is a port a plant file may name (`core.line.port_refusal`: a
serial device's path, `socket://`, `rfc2217://`, `emulator://NAME` — never another of pyserial's URL handlers,
which a reviewed file must not choose) without control characters (a NUL would cut a device path); a
`socket://` or `rfc2217://` URL must end its host in a TCP port 1..65535 (pyserial would fail later, or
compare None with 0), and an emulator name must be plain — letters, digits, `-`, `_`, `.` not first — as it
names the file `.prc3cfg/emulators/NAME.json` (its query only tunes the emulator:
`prc3cfg.shell.link.ports.emulator_query`); the schema's `PORT_PATTERN` says the same. `baud` any positive
whole number (with a gateway, `rules` asks the Open Driver's own list); `timeout` at least 0.001 s;
`turnaround` at least 0 s; `zvz` whole milliseconds, 0.001..65.535 s (ZVZTIM is a count of ms; ≥ 4 ms on an
open-driver line is a `rules` check, SYSTAT 8Eh). The gateway's fields have the ranges its INIT-DB bytes and
the Open Driver allow (receive_db ≥ 3 SYSTAT 8Fh, cpu ≤ 4 SYSTAT 90h, identifier 1..223 SYSTAT 91h), from
`prc3cfg.core.gateway`.

It is long because it is the plant file's whole format, one model per section, from which the one
schema is generated: the sections refer to each other, and the schema needs them all.
"""

from __future__ import annotations

import json
import math
import re
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from decimal import Decimal
from typing import Annotated, Any, Literal, TypeVar
from urllib.parse import urlsplit

from annotated_types import GroupedMetadata
from pydantic import (
    AfterValidator,
    BaseModel,
    BeforeValidator,
    ConfigDict,
    Field,
    GetJsonSchemaHandler,
    PlainValidator,
    StrictBool,
    WithJsonSchema,
    model_validator,
)
from pydantic.config import JsonDict
from pydantic.json_schema import GenerateJsonSchema, JsonSchemaMode, JsonSchemaValue
from pydantic_core import PydanticCustomError, core_schema

from prc3cfg.core import gateway
from prc3cfg.core.framing import FramingName
from prc3cfg.core.image import DEFAULT_SYSTEM, MAX_MODULE_ADDRESS, PROGRAM_COUNT, default_program
from prc3cfg.core.line import (
    DEVICE_FOLDER,
    EMULATOR_SCHEME,
    FRAME_DATA_BITS,
    NOT_A_LINE,
    STOP_BITS,
    TCP_SCHEMES,
    Parity,
    port_refusal,
)
from prc3cfg.core.text import has_control
from prc3cfg.core.units import DISTANCE, QUANTITIES, Action, Quantity, human_text

T = TypeVar("T")

SCHEMA_DIALECT = "http://json-schema.org/draft-07/schema#"
#: The schema's `$id`: the same for every version, since plant files only gain keys.
SCHEMA_ID = "urn:prc3cfg:plant-file"
#: A program number key: "1".."64" where keys are strings (JSON), 1..64 where a YAML editor
#: keeps them integers. A quoted "7" passes here; the loader asks for it without quotes.
PROGRAM_KEY: JsonDict = {"type": ["string", "integer"], "pattern": "^([1-9]|[1-5][0-9]|6[0-4])$",
                         "minimum": 1, "maximum": 64}
#: An emulator's name: it names the file of its state.
EMULATOR_NAME = "[A-Za-z0-9_-][A-Za-z0-9_.-]*"
#: `?line-speed=9600` and the like, which the link reads (and names what it does not know).
EMULATOR_QUERY = r"(\?[^#\s]*)?"


def _either_case(word: str) -> str:
    """`word` as an ECMA 262 pattern without the `i` flag finds it in either case: `[cC][oO][mM]`."""
    return "".join(f"[{c.lower()}{c.upper()}]" if c.isalpha() else re.escape(c) for c in word)


#: A port as the schema checks it (`core.line.port_refusal`, `_port`): a path under /dev, without `://` or a
#: `..`, not the machine's own terminal; a COM port; a TCP URL with HOST:DIGITS; a plain emulator name.
#: Draft-07 `pattern` is an ECMA 262 search, without flags (a scheme pyserial lowercases is spelt in either
#: case); the end is a lookahead, not `$`, which Python (but not ECMA) also finds before a final newline.
PORT_PATTERN = (rf"^(?![\s\S]*://)(?![\s\S]*/\.\.(?![^/])){DEVICE_FOLDER}(?!{NOT_A_LINE})[\s\S]"
                rf"|^(\\\\\.\\)?{_either_case('COM')}[1-9][0-9]*(?![\s\S])"
                f"|^({'|'.join(map(_either_case, TCP_SCHEMES))})://[^/?#]*:[0-9]+(?![^/?#])"
                rf"|^{EMULATOR_SCHEME}{EMULATOR_NAME}{EMULATOR_QUERY}(?![\s\S])")


def _plain(number: Decimal) -> int | float:
    return int(number) if number == number.to_integral_value() else float(number)


@dataclass(frozen=True)
class _Number(GroupedMetadata):
    """The metadata of a number field, `Annotated[int | None, _number(...)]`: its validator and its
    schema. `out` is the type the validator hands back, which the field's annotation names."""

    out: type[int | float | Decimal]
    validator: PlainValidator
    schema: WithJsonSchema

    def __iter__(self) -> Iterator[object]:
        yield self.validator
        yield self.schema


def _number(
    lo: Decimal | int,
    hi: Decimal | int | None = None,
    *,
    step: Decimal | int | None = None,
    unit: str = "",
    step_name: str = "",
    what: str = "",
    note: str = "",
    out: type[int | float | Decimal] = Decimal,
    description: str = "",
    default: Decimal | int | None = None,
    example: Decimal | int | None = None,
) -> _Number:
    """A number: at least `lo`, at most `hi` (if any), whole `step`s (if any), as `out`.

    The schema names what an editor completes the key with: `default` (what a key left out stands
    for, where the model's own default is None), else an example: `example`, else `lo`. Not both:
    given both, yaml-language-server completes with neither.
    """
    lo_, hi_ = Decimal(lo), None if hi is None else Decimal(hi)
    step_ = None if step is None else Decimal(step)
    with_unit: Callable[[object], str] = (lambda x: f"{x} {unit}") if unit else str
    allowed = with_unit(f"{lo_}..{hi_}") if hi_ is not None else f"at least {with_unit(lo_)}"
    # The whole numbers that pass, where they are a range (an `int` out, a step of 1 or none, a top): an
    # `int` is looked up there, not worked out in decimals. Program numbers (keys, chains) are a third of the
    # numbers of 8 × 30 modules as `prc3cfg import` writes them; with a `Decimal` taken as it is, without the
    # checks for other types, those modules validate in 0.08 s, not 0.11 (bench/plan_time_bench.py --mixes).
    whole = (range(math.ceil(lo_), math.floor(hi_) + 1) if out is int and hi_ is not None
             and step_ in (None, 1) else range(0))

    def validate(value: Any) -> Any:
        if type(value) is int and value in whole:
            return value
        if type(value) is Decimal:  # every number with a point, as the reader gives it
            number = value
        elif type(value) is bool or not isinstance(value, (int, float, Decimal)):
            raise PydanticCustomError("not_number", "not a number", {"whole": out is int, "unit": unit})
        else:
            number = (value if isinstance(value, Decimal) else Decimal(repr(value))
                      if isinstance(value, float) else Decimal(value))
        if not number.is_finite():
            raise PydanticCustomError("not_finite", "not a finite number", {"value": str(value)})
        out_of_range = number < lo_ or (hi_ is not None and number > hi_)
        if out_of_range or (step_ is not None and number % step_):  # the words are made only for a message
            context = {"value": with_unit(number), "allowed": allowed, "note": note, "unit": unit}
            if out_of_range:
                raise PydanticCustomError("out_of_range", "out of range", context)
            step_words = {"step": with_unit(step_), "step_name": step_name, "what": what}
            raise PydanticCustomError("not_whole", "not a whole number", context | step_words)
        return number if out is Decimal else out(number)

    schema: dict[str, Any] = {"type": "integer" if out is int else "number", "minimum": _plain(lo_)}
    schema |= {"maximum": _plain(hi_)} if hi_ is not None else {}
    schema |= {"description": description} if description else {}
    if default is not None:
        schema["default"] = _plain(Decimal(default))
    else:
        schema["examples"] = [_plain(Decimal(lo_ if example is None else example))]
    return _Number(out, PlainValidator(validate), WithJsonSchema(schema))


def _quantity(q: Quantity, description: str, *, default: Decimal | int | None = None,
              example: Decimal | int | None = None) -> _Number:
    """A value of `QUANTITIES`: an `int` if it is a plain count, else a `Decimal` (the field's annotation says
    which)."""
    return _number(
        q.human_lo, q.human_hi, step=q.step, unit=q.unit, step_name=q.step_name, what=q.what,
        out=int if q.integer else Decimal,
        description=f"{q.symbol}{', ' + q.unit if q.unit else ''}: {description}", default=default,
                   example=example,
    )


def _system(key: str, description: str) -> _Number:
    """S1..S12 (not S8, S9): a key left out is the factory default, which the schema names."""
    q = QUANTITIES[key]
    factory = q.to_human(getattr(DEFAULT_SYSTEM, q.symbol))
    return _quantity(q, f"{description} (factory {human_text(q.symbol, getattr(DEFAULT_SYSTEM, q.symbol))})",
                     default=factory)


def _one_of(allowed: tuple[int | float, ...], description: str) -> _Number:
    """A number that must be one of `allowed` (stop bits: 1, 1.5, 2); returned as float."""

    def validate(value: Any) -> float:
        if isinstance(value, bool) or not isinstance(value, (int, float, Decimal)) or value not in allowed:
            raise PydanticCustomError("not_allowed", "not allowed",
                                      {"expected": ", ".join(map(str, allowed))})
        return float(value)

    return _Number(float, PlainValidator(validate),
                   WithJsonSchema({"enum": list(allowed), "description": description}))


def _data_bits() -> _Number:
    """Data bits: always 8 — a PRC 3 frame is binary, and fewer bits lose the top of each byte."""

    def validate(value: Any) -> int:
        if isinstance(value, bool) or not isinstance(value, (int, Decimal)):
            raise PydanticCustomError("not_number", "not a number", {"whole": True, "unit": ""})
        if value != FRAME_DATA_BITS:
            raise PydanticCustomError("data_bits", "not 8 data bits",
                                      {"value": str(value), "bits": FRAME_DATA_BITS})
        return FRAME_DATA_BITS

    description = f"always {FRAME_DATA_BITS}: a PRC 3 frame is binary"
    return _Number(int, PlainValidator(validate),
                   WithJsonSchema({"enum": [FRAME_DATA_BITS], "description": description,
                                                                  "default": FRAME_DATA_BITS}))


def _given(value: T | None) -> T:
    if value is None:  # `key:` with no value, which YAML reads as null: `messages` says it is empty
        raise PydanticCustomError("empty", "no value")
    return value


#: A key a file may leave out: None on the model is "not given here" (profiles are layered over
#: it), never a value a file writes; the schema shows the value alone (`Draft07.nullable_schema`).
#: (A number field's own validator refuses None: `Annotated[Decimal | None, _number(...)]`.)
Omittable = Annotated[T | None, BeforeValidator(_given)]

Text = Annotated[str, Field(min_length=1, strict=True)]


def _printable(name: str) -> str:
    """A name is printable text: every output shows it, a terminal, a CI log, a pull request (`core.text`)."""
    if has_control(name):
        raise PydanticCustomError("name_control", "a control character")
    return name


Name = Annotated[Text, AfterValidator(_printable)]


def _port(url: str) -> str:
    if has_control(url):
        raise PydanticCustomError("port_control", "a control character")
    refusal = port_refusal(url)
    if refusal is not None:
        kind, handler = refusal
        raise PydanticCustomError(kind, "not a port a plant file may name", {"scheme": handler})
    scheme = url.partition("://")[0]
    if scheme.lower() in TCP_SCHEMES and not _tcp_port(url):
        raise PydanticCustomError("tcp_port", "no TCP port", {"scheme": scheme})
    if url.startswith(EMULATOR_SCHEME) and not re.fullmatch(EMULATOR_NAME + EMULATOR_QUERY,
                                                            url.removeprefix(EMULATOR_SCHEME)):
        raise PydanticCustomError("emulator_name", "not a plain emulator name")
    return url


def _tcp_port(url: str) -> bool:
    """A TCP port 1..65535 as pyserial reads it (`urlsplit`), written as the schema wants it."""
    try:
        port = urlsplit(url).port
    except ValueError:  # not digits, out of range, a broken [IPv6] host
        return False
    return bool(port) and re.search(PORT_PATTERN, url) is not None


Port = Annotated[
    Text, AfterValidator(_port),
    Field(description="a serial device (/dev/ttyUSB0, COM3), socket://HOST:PORT, rfc2217://HOST:PORT or "
                      "emulator://NAME",
          json_schema_extra={"pattern": PORT_PATTERN},
          examples=["/dev/ttyUSB0", "emulator://line-1", "socket://192.0.2.10:4001"]),
]
ProgramNumber = Annotated[int, _number(1, PROGRAM_COUNT, step=1, out=int,
                                       description="a program number, 1..64")]


class FileModel(BaseModel):
    """A part of a plant file: frozen, unknown keys refused."""

    model_config = ConfigDict(frozen=True, extra="forbid")


class SystemSpec(FileModel):
    """System parameters S1..S12 (not S9) in human units; a key left out is the factory default."""

    upper_reversing_point: Annotated[Decimal | None,
                                     _system("upper_reversing_point", "upper reversing point")] = None
    reference_point: Annotated[Decimal | None, _system("reference_point", "reference point")] = None
    increment_pulses: Annotated[int | None,
                                _system("increment_pulses", "increment pulse generator, pulses/dm")] = None
    max_speed: Annotated[Decimal | None, _system("max_speed", "maximum speed")] = None
    min_speed: Annotated[Decimal | None, _system("min_speed", "minimum speed")] = None
    acceleration: Annotated[Decimal | None, _system("acceleration", "acceleration")] = None
    circuit_gain: Annotated[int | None, _system("circuit_gain", "circuit amplification")] = None
    alarm: Annotated[Omittable[StrictBool], WithJsonSchema({
        "type": "boolean", "description": "S8: alarm (factory false)", "default": False})] = None
    sync_increment: Annotated[int | None, _system("sync_increment", "sync increment")] = None
    sync_circuit_gain: Annotated[int | None,
                                 _system("sync_circuit_gain", "sync circuit amplification")] = None
    sync_conveyor_sequence: Annotated[Decimal | None,
                                      _system("sync_conveyor_sequence", "sync conveyor sequence")] = None


class FunctionOutputSpec(FileModel):
    """F1 or F2: set or reset the output at a distance after START (F1) or before the reversing point (F2)."""

    action: Action = Field(description="set or reset the output", examples=["set"])
    distance: Annotated[Decimal, _quantity(DISTANCE, "where the output switches, 0.000..0.999")]


_FACTORY_PROGRAM = default_program(DEFAULT_SYSTEM)
_RESET_AT_ZERO: JsonDict = {"action": "reset", "distance": 0}


class ProgramSpec(FileModel):
    """One program in human units; every field may come from a profile instead."""

    position: Annotated[Decimal | None,
                        _quantity(QUANTITIES["position"], "position, at most the upper reversing point",
                                  example=QUANTITIES["position"].to_human(_FACTORY_PROGRAM.P))] = None
    speed: Annotated[Decimal | None,
                     _quantity(QUANTITIES["speed"], "speed, between min_speed and max_speed",
                               example=QUANTITIES["speed"].to_human(_FACTORY_PROGRAM.V))] = None
    relative_speed: Annotated[Decimal | None,
                              _quantity(QUANTITIES["relative_speed"], "relative speed (default 0)",
                                        default=0)] = None
    dwell: Annotated[Decimal | None,
                     _quantity(QUANTITIES["dwell"], "dwell time (default 0)", default=0)] = None
    f1: Omittable[FunctionOutputSpec] = Field(None, description="F1, counted after START (default: "
                                                                "reset at 0)",
                                   json_schema_extra={"default": _RESET_AT_ZERO})
    f2: Omittable[FunctionOutputSpec] = Field(None, description="F2, counted before the reversing point "
                                                                "(default: reset at 0)",
                                   json_schema_extra={"default": _RESET_AT_ZERO})
    next: Annotated[int | None,
                    _number(1, PROGRAM_COUNT, step=1, out=int,
                            description="A: the program to jump to next")] = None


class ChainSpec(FileModel):
    """Programs run one after the other (A = the next one); `loop` makes the last jump to the first.

    Written as a list of program numbers or as `{programs: [...], loop: true}`.
    """

    programs: tuple[ProgramNumber, ...] = Field(min_length=1,
                                                description="program numbers in the order they run",
                                                examples=[[1, 2]])
    loop: Annotated[bool, Field(strict=True, description="true: the last program jumps back to "
                                                         "the first")] = False

    @model_validator(mode="before")
    @classmethod
    def _from_list(cls, data: Any) -> Any:
        if isinstance(data, list):
            return {"programs": data}
        if data is not None and not isinstance(data, dict):
            raise PydanticCustomError("chain_type", "not a chain")
        return data

    @classmethod
    def __get_pydantic_json_schema__(cls, schema: core_schema.CoreSchema,
                                     handler: GetJsonSchemaHandler) -> JsonSchemaValue:
        as_object = handler.resolve_ref_schema(handler(schema))
        as_list = {"type": "array", "items": as_object["properties"]["programs"]["items"], "minItems": 1}
        return {"anyOf": [as_list, dict(as_object)], "description": (cls.__doc__ or "").split("\n")[0]}


UnmanagedPrograms = Literal["keep", "reset"]
def _program_key(value: Any) -> Any:
    """A program number as a key is written whole: `1.0:` is refused, as the schema's `propertyNames`
    refuses it (a JSON key is text, and its pattern takes digits only)."""
    if isinstance(value, (float, Decimal)) and not isinstance(value, bool):
        fix = f"write it as {int(value)}:" if value == int(value) else "program numbers are whole, 1..64"
        raise PydanticCustomError("program_key", "a program number with a point", {"fix": fix})
    return value


ProgramKey = Annotated[ProgramNumber, BeforeValidator(_program_key)]
Programs = dict[ProgramKey, ProgramSpec]


class ProfileSpec(FileModel):
    """What modules share: system parameters, programs, chains, the unmanaged-program policy."""

    system: Omittable[SystemSpec] = Field(None, description="system parameters S1..S12 (not S9); a key left "
                                                            "out is the factory default")
    programs: Omittable[Programs] = Field(None, json_schema_extra={"propertyNames": PROGRAM_KEY},
                                          description="programs by number 1..64")
    chains: Omittable[tuple[ChainSpec, ...]] = Field(
        None, description="jump addresses A: [1, 2, 3] means 1→2→3→stop",
        examples=[[[1, 2, 3]], [{"programs": [1, 2], "loop": True}]])
    unmanaged_programs: Omittable[UnmanagedPrograms] = Field(
        None, description="keep (default): programs not listed are neither read nor written; "
        "reset: they must hold factory defaults", json_schema_extra={"default": "keep"},
    )


def _names(value: Any) -> Any:
    return [value] if isinstance(value, str) else value


class ModuleSpec(ProfileSpec):
    """One PRC 3 module: its address (S9), its name, the profiles it uses, its own settings."""

    address: Annotated[int, _number(1, MAX_MODULE_ADDRESS, step=1, out=int,
                                    description="S9, 1..30, set by Address Init on the module")]
    name: Name = Field(description="unique in the plant", examples=["booth-1-left"])
    profiles: Annotated[
        tuple[Name, ...],
        BeforeValidator(_names),
        WithJsonSchema({
            "anyOf": [{"type": "string"}, {"type": "array", "items": {"type": "string"}}],
            "description": "profile names, applied in order (later wins); the module's own keys win over all",
            "examples": ["reciprocator", ["reciprocator", "short-stroke"]],
        }),
    ] = ()


class Gateway(FileModel):
    """The CP 524/525 running the Open Driver that this line ends in (docs/line.md, INIT-DB words 1 and 2)."""

    receive_db: Annotated[int, _number(
        gateway.MIN_RECEIVE_DB, 255, step=1, out=int, description="EMPFDB, the receive data block",
        note=f" (the Open Driver refuses a receive DB below {gateway.MIN_RECEIVE_DB}: SYSTAT 8Fh)",
    )]
    receive_dw: Annotated[int, _number(0, 255, step=1, out=int, description="EMPFDW, the first data word")]
    cpu: Annotated[int, _number(
        0, gateway.MAX_CPU, step=1, out=int, description="ECPUNR, the CPU number",
        note=f" (the Open Driver refuses a CPU number above {gateway.MAX_CPU}: SYSTAT 90h)",
    )]
    identifier: Annotated[int, _number(
        gateway.IDENTIFIERS.start, gateway.IDENTIFIERS.stop - 1, step=1, out=int,
        description="EKENN, the receive identifier",
        note=" (the Open Driver refuses any other EKENN: SYSTAT 91h)",
    )]


class BusLine(FileModel):
    """A bus without its modules: where it is and how it talks (docs/line.md)."""

    name: Name = Field(description="unique in the plant", examples=["line-1"])
    port: Port
    framing: FramingName = Field("crc16", description="how messages are framed on the line (docs/line.md)")
    baud: Annotated[int, _number(1, step=1, out=int, description="line speed; PRC 3 lines run "
                                                                 "9600 baud")] = 9600
    parity: Parity = Field("even", description="the parity bit of each character")
    data_bits: Annotated[int, _data_bits()] = FRAME_DATA_BITS
    stop_bits: Annotated[float, _one_of(STOP_BITS, "1, 1.5 or 2")] = 1.0
    timeout: Annotated[float, _number(Decimal("0.001"), unit="s", out=float, description=(
        "s to wait for a reply beyond the line's own time (its frames at its baud and format, the "
        "turnaround)"))] = 0.5
    turnaround: Annotated[float, _number(0, unit="s", out=float, description=(
        "s, the module's turnaround, for the bus-time estimate and the wait for a reply"))] = 0.010
    zvz: Annotated[float, _number(
        Decimal("0.001"), Decimal("65.535"), step=Decimal("0.001"), unit="s", step_name="milliseconds",
        what="character delay times are", out=float, description="s, character delay time ZVZ (open-driver)",
    )] = 0.020
    gateway: Omittable[Gateway] = Field(None, description="the Siemens CP 524/525 (Open Driver) the line "
                                                          "ends in, if any")
    only_these_modules: Annotated[bool, Field(strict=True, description=(
        "true: the modules listed are every module on this line — prc3cfg may then send what they all need "
        "alike once, as a broadcast to address 0 (a full line of 30 modules needs no saying)"))] = False
    record_max_age: Annotated[float, _number(0, unit="s", out=float, description=(
        "s: how long what prc3cfg last read or verified on this line is taken as known without reading it "
        "again — past it, a plan reads every module in full (0: always)"))] = 28_800.0
    accept_undetected_damage: Annotated[bool, Field(strict=True, description=(
        "true: apply on this line although it has no error detection (open-driver with parity none), knowing "
        "that a damaged frame can become another write, a read a write, an address the broadcast — "
        "prefer parity"))] = False
    require_reason: Annotated[bool, Field(strict=True, description=(
        "true: every apply, restore and adopt of this line's modules must say why (--reason TEXT or "
        "PRC3CFG_REASON) — "
        "refused before the line is opened otherwise; the reason is kept in the journal and "
        "the snapshot"))] = False


class BusSpec(BusLine):
    """A bus as a plant file writes it: its line and its modules."""

    modules: tuple[ModuleSpec, ...] = Field(min_length=1,
                                            description="the PRC 3 modules on this line, up to 30")


class PlantSpec(FileModel):
    """A whole plant file."""

    model_config = ConfigDict(title="PRC 3 plant")

    plant: Name = Field(description="the plant's name", examples=["paint-shop"])
    profiles: Omittable[dict[Name, ProfileSpec]] = Field(
        None, description="named settings that modules use and override")
    buses: tuple[BusSpec, ...] = Field(min_length=1, description="the RS-422 lines, each with its modules")
    policy: Omittable[Text] = Field(None, description="the policy file (docs/policy.md), relative "
                                                      "to this one", examples=["line-rules.yaml"])


class Draft07(GenerateJsonSchema):
    """pydantic's schema, made draft-07: `definitions`, no `default: null` for "not given", no field
    titles."""

    def generate(self, schema: core_schema.CoreSchema,
                 mode: JsonSchemaMode = "validation") -> JsonSchemaValue:
        result = super().generate(schema, mode)
        definitions = result.pop("$defs", {})
        return {"$schema": SCHEMA_DIALECT, "$id": SCHEMA_ID, **result, "definitions": definitions}

    def default_schema(self, schema: core_schema.WithDefaultSchema) -> JsonSchemaValue:
        """A default of None is "not given": the value's own schema, with the default it names
        itself (a factory default), if any. Any other default is what an editor completes with,
        in place of an example (given both, yaml-language-server completes with neither) — but an
        empty list, which leaves the examples to show what to write."""
        if schema.get("default", ...) is None:
            return self.generate_inner(schema["schema"])
        result = super().default_schema(schema)
        unwanted = "default" if result["default"] == [] else "examples"
        return {k: v for k, v in result.items() if k != unwanted}

    def nullable_schema(self, schema: core_schema.NullableSchema) -> JsonSchemaValue:
        """None is "not given" (`Omittable`), never a value a file writes: the value's own schema."""
        return self.generate_inner(schema["schema"])

    def field_title_should_be_set(self, schema: Any) -> bool:
        return False


def plant_schema() -> dict[str, Any]:
    """The JSON Schema of a plant file."""
    return PlantSpec.model_json_schema(ref_template="#/definitions/{model}", schema_generator=Draft07)


def plant_schema_text() -> str:
    """The schema as `schemas/plant.schema.json` holds it and `prc3cfg schema` prints it."""
    return json.dumps(plant_schema(), indent=2, ensure_ascii=False) + "\n"
