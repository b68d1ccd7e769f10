"""The offline rules that span more than one value (docs/plant-files.md, docs/protocol.md "What a module
does").

On a module's effective settings (after profiles):
- every listed program has a position and a speed (given in the module or a profile);
- S4 ≥ S5 (max_speed ≥ min_speed); P ≤ S1; S5 ≤ V ≤ S4 — the device's checks 32, 40,
  41, 110, with the S1, S4, S5 the plant file gives that module;
- chains: a chain names only listed programs, each program in at most one chain and
  once; a chain of one program must loop (it jumps to itself) — otherwise it does nothing;
- `next: N`: N must be a listed program, whether unlisted programs are kept or reset
  (a jump into a program the plant does not describe would run unknown contents); a
  program may not both have `next` and be in a chain.

On a bus: with a `gateway`, the Open Driver's own checks on the line (`prc3cfg.core.gateway`:
illegal baud rate SYSTAT 8Bh, ZVZ below 4 ms SYSTAT 8Eh, …). An `open-driver` line ends in
that driver whether or not the file describes the gateway, so its ZVZ minimum (8Eh) holds
without a `gateway:` too; the other checks need the gateway's own words.

On the whole file (read from the plain data, so that they are found even beside other
problems): bus names, ports and module names are unique in the plant; module addresses
are unique on their bus.

A value that came from a profile is reported where the profile gives it, with the
module's name in front. A rule runs wherever the values it needs are valid: a module or profile
with problems of its own is checked without the values they are about (`Unknown`), and S4 < S5
still lets P ≤ S1 be checked. Does not check single values (`models`). Pure.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator
from typing import Any

from prc3cfg.core import gateway
from prc3cfg.core.line import LineSettings
from prc3cfg.core.units import QUANTITIES
from prc3cfg.plant.document import mappings_in
from prc3cfg.plant.models import BusLine, Gateway
from prc3cfg.plant.problems import FIRST, Path_, Problem
from prc3cfg.plant.profiles import DEFAULT, Effective, Sourced

#: What a module's or its profiles' own problems took out of its settings, so that no rule judges
#: what stands in for it: ("system", KEY), (PROGRAM, FIELD), and (…, "*") for all of a section or
#: program — ("programs", "*"): a program is missing, so what is listed is not known.
Unknown = frozenset[tuple[Any, ...]]


def check_module(name: str, path: Path_, settings: Effective,
                 unknown: Unknown = frozenset()) -> list[Problem]:
    """The problems of one module's effective settings (module `name` at `path`), but of what is `unknown`."""
    problems = [*_missing_fields(settings, unknown), *_speeds_and_positions(settings, unknown),
                *_jumps(settings, unknown)]
    return [p if p.path[: len(path)] == path else Problem(p.path, p.message, p.at_key, modules=(name,))
            for p in problems]


def _known(unknown: Unknown, section: Any, key: Any) -> bool:
    return (section, key) not in unknown and (section, "*") not in unknown


def _missing_fields(settings: Effective, unknown: Unknown) -> Iterator[Problem]:
    # a key taken out of a program may be the one missing, mistyped
    taken_out = {program for program, _ in unknown}
    for number, fields in settings.programs.items():
        for key in ("position", "speed"):
            if key not in fields and number not in taken_out:
                yield Problem(settings.program_paths[number], f"program {number} has no {key} "
                              f"— give {key}: in the module or in one of its profiles", at_key=True)


def _speeds_and_positions(settings: Effective, unknown: Unknown) -> Iterator[Problem]:
    system = settings.system
    s1, s4, s5 = system["upper_reversing_point"], system["max_speed"], system["min_speed"]
    known_s1, known_speeds = _known(unknown, "system", "upper_reversing_point"), all(
        _known(unknown, "system", key) for key in ("max_speed", "min_speed"))
    if known_speeds and s4.value < s5.value:
        at = s5 if s5.source != DEFAULT else s4
        yield Problem(at.place, f"max_speed {_said(s4, 'max_speed', at)} is below min_speed "
                      f"{_said(s5, 'min_speed', at)} "
                      "— max_speed (S4) must be at least min_speed (S5)")
        known_speeds = False  # no speed is between them
    for number, fields in settings.programs.items():
        # a field's `Sourced` made for its message alone: 8 × 30 modules have 15,000 programs
        values = fields.plain_values()
        position = values.get("position") if known_s1 and _known(unknown, number, "position") else None
        speed = values.get("speed") if known_speeds and _known(unknown, number, "speed") else None
        if position is not None and position > s1.value:
            given = fields["position"]
            yield Problem(given.place, f"position {_said(given, 'position')} is above upper_reversing_point "
                          f"{_said(s1, 'upper_reversing_point', given)} — a position must be at most the "
                          "upper reversing point "
                          "(P ≤ S1): lower it or raise upper_reversing_point")
        if speed is not None and not s5.value <= speed <= s4.value:
            given = fields["speed"]
            limit, word = (s4, "max_speed") if speed > s4.value else (s5, "min_speed")
            side = "above" if limit is s4 else "below"
            yield Problem(given.place,
                          f"speed {_said(given, 'speed')} is {side} {word} {_said(limit, word, given)} "
                          "— a speed must be min_speed..max_speed (S5 ≤ V ≤ S4), here "
                          f"{s5.value}..{s4.value} m/s")


def _jumps(settings: Effective, unknown: Unknown) -> Iterator[Problem]:
    listed = settings.programs
    # else a jump to a program taken out is not known to be wrong
    all_listed = ("programs", "*") not in unknown
    chained: dict[int, int] = {}  # program → chain number (1-based)
    for k, chain in enumerate(settings.chains.value if ("chains", "*") not in unknown else ()):
        at = settings.chains.place + (k,)
        if len(chain.programs) == 1 and not chain.loop:
            yield Problem(at, f"a chain of one program does nothing — add loop: true to make program "
                          f"{chain.programs[0]} jump to itself, or drop the chain")
        for i, number in enumerate(chain.programs):
            item = at + ("programs", i)
            if number not in listed:
                if all_listed:
                    yield Problem(item, f"program {number} is not listed under programs — a chain may only "
                                  f"name listed programs: list program {number} or drop it from the chain")
            elif number in chained:
                where = "this chain" if chained[number] == k + 1 else f"chain {chained[number]}"
                yield Problem(item, f"program {number} is already in {where} — a program may be in one "
                                    "chain, once")
            else:
                chained[number] = k + 1
    for number, fields in listed.items():
        if (target := fields.get("next")) is None or not _known(unknown, number, "next"):
            continue
        if target.value not in listed and all_listed:
            yield Problem(target.place, f"next: {target.value} is not a listed program — list program "
                          f"{target.value} under programs, or jump to a listed one")
        if number in chained:
            yield Problem(target.place, f"program {number} has next: {target.value} and is in chain "
                          f"{chained[number]} — its jump is set by the chain or by next, not both: drop one")


def _said(value: Sourced, key: str, beside: Sourced | None = None) -> str:
    """A value with its unit, and its source when that differs from the value it is compared with."""
    text = f"{value.value} {QUANTITIES[key].unit}"
    return text + f" ({value.source})" if beside is not None and value.source != beside.source else text


#: Gateway words the Open Driver accepts, to check an `open-driver` line that has no `gateway:`.
_ANY_GATEWAY = Gateway(receive_db=gateway.MIN_RECEIVE_DB, receive_dw=0, cpu=0,
                       identifier=gateway.IDENTIFIERS.start)


#: The keys of a bus `check_bus` reads.
LINE_KEYS = frozenset({"framing", "baud", "parity", "data_bits", "stop_bits", "zvz", "gateway"})


def check_bus(path: Path_, bus: BusLine,
              pseudo_terminal: Callable[[str], bool] = lambda port: False) -> list[Problem]:
    """A parity on a port that is a pseudo-terminal (`pseudo_terminal`, the shell's to tell), which carries
    none; and what the Open Driver would refuse about this line (SYSTAT 8Bh..95h): all with a gateway, ZVZ on
    any open-driver line — and a ZVZ not longer than one character, which it takes but ends frames by after
    every byte."""
    problems = []
    if bus.parity != "none" and pseudo_terminal(bus.port):
        given = "parity" in bus.model_fields_set
        problems.append(Problem(path + (("parity",) if given else ("port",)),
                                f"port {bus.port} is a pseudo-terminal, which "
                                f"carries no parity ({'' if given else 'the default '}parity {bus.parity}) "
                                "— set parity: none",
                                at_key=not given))
    if bus.gateway is None and bus.framing != "open-driver":
        return problems
    words = bus.gateway or _ANY_GATEWAY
    settings = gateway.GatewaySettings(
        receive_db=words.receive_db, receive_dw=words.receive_dw, cpu=words.cpu,
        identifier=words.identifier, zvz_ms=round(bus.zvz * 1000),
        line=LineSettings(baud=bus.baud, data_bits=bus.data_bits, parity=bus.parity, stop_bits=bus.stop_bits),
    )
    for refusal in gateway.refusals(settings):
        key = {"zvz_ms": "zvz"}.get(refusal.field, refusal.field.removeprefix("line."))
        if bus.gateway is None and key != "zvz":
            continue
        if key in Gateway.model_fields:
            at, given = path + ("gateway", key), True
        else:
            at, given = path + (key,), key in bus.model_fields_set
        problems.append(Problem(at if given else path + ("gateway",),
                                f"{refusal.reason} — the gateway's Open "
                                f"Driver refuses it (SYSTAT {refusal.systat:02X}h): change {key}",
                                at_key=not given))
    if bus.framing == "open-driver" and (reason := gateway.zvz_too_short(bus.zvz, settings.line)) is not None:
        given = "zvz" in bus.model_fields_set
        problems.append(Problem(path + ("zvz",), reason, at_key=not given))
    return problems


def check_unique(data: Any) -> list[Problem]:
    """Unique bus names, ports and module names in the plant; unique addresses on each bus."""
    problems: list[Problem] = []
    bus_names: dict[Any, Path_] = {}
    ports: dict[Any, Path_] = {}
    module_names: dict[Any, Path_] = {}
    for bus_path, bus in mappings_in(data, ("buses",)):
        _unique(problems, bus, bus_path, "name", bus_names,
                f"bus name '{{}}' is already used ({FIRST}) — give each bus its own name")
        _unique(problems, bus, bus_path, "port", ports,
                f"port '{{}}' is already used by another bus ({FIRST}) — each bus needs its own port")
        addresses: dict[Any, Path_] = {}
        for module_path, module in mappings_in(bus, bus_path + ("modules",)):
            _unique(problems, module, module_path, "name", module_names,
                    f"module name '{{}}' is already used ({FIRST}) — module names must be unique in "
                    "the plant")
            _unique(problems, module, module_path, "address", addresses,
                    f"address {{}} is already used on this bus ({FIRST}) — each module on a bus needs its "
                    "own address (its S9)")
    return problems


def _unique(problems: list[Problem], item: dict[Any, Any], path: Path_, key: str,
            seen: dict[Any, Path_], message: str) -> None:
    value = item.get(key)
    if isinstance(value, bool) or not isinstance(value, (str, int)):
        return
    if value in seen:
        problems.append(Problem(path + (key,), message.replace("{}", str(value)), first=seen[value]))
    else:
        seen[value] = path + (key,)
