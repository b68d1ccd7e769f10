"""The motion of a reciprocator's program chains: position over time, from a module image.

A PRC 3 runs a program by moving its axis to the position P at the speed V and waiting the
dwell time T there; the jump address A names the program that follows (0: the axis stops).
This module turns a module image (device units, `prc3cfg.core.image`) into that motion, chain by
chain, as frozen values in metres and seconds: the segments (a move, then a dwell, for each
program), the turning points, the time of a pass and of a loop's cycle, and when the function
outputs F1 and F2 are set. The units are `prc3cfg.core.units`; the chains are
`prc3cfg.core.chains.jumps_as_chains`. Pictures of the motion are `prc3cfg.core.plot`. Pure: no I/O,
no plotting library.

The manual gives the numbers, not the kinematics; these are the project's readings:

- (reading) A pass starts at the reference point S2: the axis travels there to be referenced
  before production (manual §2.3.1, §2.3.6: "a new Travel to reference point command must be
  given"), so a chain's first program moves from S2.
- (reading) A move has a trapezoidal speed profile: from rest it accelerates at S6
  (0.001 m/s²) to V, travels at V and decelerates at S6 to rest at P. A move too short to
  reach V is triangular: it peaks at sqrt(S6 · distance) halfway. The axis comes to rest at
  every P (the manual's "reversing point") — a turning point — even where the next move goes
  on in the same direction; then it dwells T (0.1 s) there.
- (reading) The relative speed Vr is a speed relative to the conveyor (manual §2.2; S10..S12
  synchronise with it). It does not change the stroke drawn here and is not used.
- (reading) F = action × 1000 + distance (docs/protocol.md "Values"; action 1 sets the output, 0
  resets it). F1 acts once the axis has travelled the distance since the START of the
  program's move; F2 once it is the distance or less before P. On a move shorter than the
  distance F1 does not act and F2 acts at START. F = 0 resets the output at START (manual §3,
  code 70: "Delete output at START"). Both outputs are reset when a pass starts and keep
  their state from program to program until an action changes it; an output set for no
  time at all has no interval.
- Chains are those `jumps_as_chains` finds (a path ending in A = 0, a loop), and every path of
  other jumps (`next:` in a plant file) from a program no other program jumps to.
  (reading) A program that neither jumps nor is jumped to is not a chain and is not drawn.
  A chain that comes back to one of its programs is drawn for one pass; its `cycle_time` is
  one turn of that loop in production, where the loop's first move starts from the last
  program's P. A jump to a program the image does not hold (not read, not managed) ends the
  drawn pass there.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Iterable
from dataclasses import dataclass

from prc3cfg.core.chains import jumps_as_chains
from prc3cfg.core.device import widest_range
from prc3cfg.core.image import ModuleImage, Program
from prc3cfg.core.units import BY_SYMBOL, function_output_parts
from prc3cfg.errors import UserError

MOVE = "move"
DWELL = "dwell"
OUTPUTS = ("F1", "F2")
#: Function output values the motion can read (docs/protocol.md "Values"): those a module holds.
OUTPUT_RANGE = range(widest_range("F1")[0], widest_range("F1")[1] + 1)


class MotionError(UserError):
    """A value the motion cannot be worked out from (a speed or acceleration of 0, a function
    output outside 0..1999): only a damaged or foreign read-back holds one."""


@functools.lru_cache(maxsize=4096)
def _si(symbol: str, device: int) -> float:
    """A device value in metres, m/s, seconds or m/s² (`prc3cfg.core.units`): kept, as a module's values
    repeat (a plan's charts of 8 × 30 modules convert 200,000 of them, some 3,000 different)."""
    return float(BY_SYMBOL[symbol].to_human(device))


@dataclass(frozen=True, slots=True)
class Segment:
    """One program's move to P, or its dwell at P: times in s from the start of the pass,
    positions in m. A move goes `distance` m (from the device values: exactly the double nearest
    the whole millimetres), accelerating for `ramp` seconds to the speed `peak` (m/s: V, or less
    on a triangular move), and decelerating for as long at its end."""

    kind: str
    program: int
    start: float
    end: float
    start_position: float
    end_position: float
    distance: float = 0.0
    ramp: float = 0.0
    peak: float = 0.0

    def position(self, time: float) -> float:
        """Where the axis is at `time` (s from the start of the pass), within this segment."""
        if self.kind == DWELL or self.end == self.start:
            return self.end_position
        elapsed = min(max(time - self.start, 0.0), self.end - self.start)
        left = self.end - self.start - elapsed
        acceleration = self.peak / self.ramp
        direction = math.copysign(1.0, self.end_position - self.start_position)
        # decelerating: measured back from P, so it ends there exactly
        if left < self.ramp and left < elapsed:
            return self.end_position - direction * acceleration * left**2 / 2
        if elapsed <= self.ramp:
            return self.start_position + direction * acceleration * elapsed**2 / 2
        return self.start_position + direction * (self.peak * self.ramp / 2
                                                  + self.peak * (elapsed - self.ramp))

    def time_at(self, travelled: float) -> float:
        """When a move has travelled `travelled` m (0 ≤ travelled ≤ distance) since its START."""
        if self.end == self.start:
            return self.start
        acceleration = self.peak / self.ramp
        ramp_distance = self.peak * self.ramp / 2
        if travelled <= ramp_distance:
            return self.start + math.sqrt(2 * travelled / acceleration)
        if travelled <= self.distance - ramp_distance:
            return self.start + self.ramp + (travelled - ramp_distance) / self.peak
        return self.end - math.sqrt(2 * max(self.distance - travelled, 0.0) / acceleration)


@dataclass(frozen=True, slots=True)
class TurningPoint:
    """Where a program's move comes to rest: at its P, at `time` s."""

    program: int
    time: float
    position: float


@dataclass(frozen=True, slots=True)
class OutputInterval:
    """A function output ("F1" or "F2") is set from `start` until `end` (s)."""

    output: str
    start: float
    end: float


@dataclass(frozen=True, slots=True)
class ChainMotion:
    """One pass of a chain from the reference point: its programs in order, the jump after the
    last (`then`: 0 stops; one of `programs`: the loop goes on there; another: a program the
    image does not hold), the segments (a move and a dwell per program, either possibly of no
    time), when the outputs are set, and one turn of the loop in production (None: it stops).
    `reference` (S2) and `upper` (S1) are in m."""

    programs: tuple[int, ...]
    then: int
    segments: tuple[Segment, ...]
    outputs: tuple[OutputInterval, ...]
    cycle_time: float | None
    reference: float
    upper: float

    @property
    def loops(self) -> bool:
        return self.then in self.programs

    @property
    def duration(self) -> float:
        """The pass: from the reference point to the end of the last program's dwell (s)."""
        return self.segments[-1].end

    @property
    def turning_points(self) -> tuple[TurningPoint, ...]:
        return tuple(TurningPoint(s.program, s.end, s.end_position) for s in self.segments if s.kind == MOVE)

    @property
    def label(self) -> str:
        """As the plan names chains: "chain 1 → 2 → stop", "chain 1 → 2 → 1"."""
        last = "stop" if self.then == 0 else str(self.then) + ("" if self.loops else " (not held)")
        return "chain " + " → ".join([*map(str, self.programs), last])

    def position(self, time: float) -> float:
        """Where the axis is at `time` s; before the pass at S2, after it at its last position."""
        if time <= 0:
            return self.reference
        segment = next((s for s in self.segments if time <= s.end), self.segments[-1])
        return segment.position(time)

    def curve(self, per_ramp: int = 8) -> tuple[tuple[float, float], ...]:
        """(time, position) points that draw the pass exactly at every corner: each segment's ends
        and the ends of its ramps, and `per_ramp` points along each ramp's parabola."""
        points = [(0.0, self.reference)]
        for s in self.segments:
            times = [s.start, s.end]
            if s.kind == MOVE and s.end > s.start:
                times += [s.start + s.ramp * i / per_ramp for i in range(1, per_ramp + 1)]
                times += [s.end - s.ramp * i / per_ramp for i in range(1, per_ramp + 1)]
            points += [(t, s.position(t)) for t in sorted(set(times))]
        return tuple(points)

    def samples(self, count: int, until: float | None = None) -> tuple[tuple[float, float], ...]:
        """`count` (time, position) points evenly spaced over 0..`until` s (default: the pass), for a
        compact chart; past the pass the axis stays where the pass left it."""
        until = self.duration if until is None else until
        return tuple((until * i / (count - 1), self.position(until * i / (count - 1))) for i in range(count))


def _move(number: int, start: float, start_position: int, acceleration: float, target: Program) -> Segment:
    begin, end_position = _si("P", start_position), _si("P", target.P)
    distance = _si("P", abs(target.P - start_position))
    speed = _si("V", target.V)
    if distance == 0:
        return Segment(MOVE, number, start, start, begin, end_position)
    if speed**2 / acceleration <= distance:  # reaches V: accelerate, travel at V, decelerate
        peak = speed
        duration = distance / speed + speed / acceleration
    else:  # too short to reach V: triangular
        peak = math.sqrt(acceleration * distance)
        duration = 2 * peak / acceleration
    return Segment(MOVE, number, start, start + duration, begin, end_position, distance, peak / acceleration,
                   peak)


def _action(move: Segment, output: str, value: int, travel: int) -> tuple[float, bool] | None:
    """(when, set?) of an output's action on a move of `travel` mm; None: it does not act on it.
    In whole mm until the time is worked out, as the module counts them."""
    action, distance = function_output_parts(value)
    if output == "F1":
        if distance > travel:
            return None
        return move.time_at(_si("F", distance)), action == "set"
    return move.time_at(_si("F", max(travel - distance, 0))), action == "set"


@dataclass(slots=True)
class _Run:
    segments: list[Segment]
    actions: dict[str, list[tuple[float, bool]]]


def _run(numbers: Iterable[int], programs: dict[int, Program], start_position: int,
         acceleration: float) -> _Run:
    """The programs `numbers` one after the other from `start_position` (mm) at time 0: their
    segments, and the actions of each output in time order."""
    run = _Run([], {output: [] for output in OUTPUTS})
    time, position = 0.0, start_position
    for number in numbers:
        program = programs[number]
        move = _move(number, time, position, acceleration, program)
        travel = abs(program.P - position)
        for output in OUTPUTS:
            if (action := _action(move, output, getattr(program, output), travel)) is not None:
                run.actions[output].append(action)
        dwell_end = move.end + _si("T", program.T)
        run.segments.extend((move, Segment(DWELL, number, move.end, dwell_end, move.end_position,
                                           move.end_position)))
        time, position = dwell_end, program.P
    return run


def _intervals(run: _Run) -> tuple[OutputInterval, ...]:
    """When each output is set: reset at the start, then as the actions say."""
    intervals: list[OutputInterval] = []
    end = run.segments[-1].end
    for output, actions in run.actions.items():
        since: float | None = None  # set since then; None: reset
        for time, sets in actions:
            if sets and since is None:
                since = time
            elif not sets and since is not None:
                intervals.append(OutputInterval(output, since, time))
                since = None
        if since is not None:
            intervals.append(OutputInterval(output, since, end))
    return tuple(i for i in intervals if i.end > i.start)


def _check(image: ModuleImage, numbers: Iterable[int], programs: dict[int, Program]) -> None:
    if image.system.S6 < 1:
        raise MotionError(f"module {image.address}: acceleration S6 = {image.system.S6} — the motion cannot "
                          "be worked out without one")
    for number in numbers:
        program = programs[number]
        if program.V < 1:
            raise MotionError(f"module {image.address}, program {number}: speed V = {program.V} — the axis "
                              "does not move at it")
        if program.T < 0:
            raise MotionError(f"module {image.address}, program {number}: dwell T = {program.T} is below 0")
        for output in OUTPUTS:
            if getattr(program, output) not in OUTPUT_RANGE:
                raise MotionError(f"module {image.address}, program {number}: {output} = "
                                  f"{getattr(program, output)} "
                                  f"is outside {OUTPUT_RANGE.start}..{OUTPUT_RANGE.stop - 1}")


def _chains(programs: dict[int, Program]) -> list[tuple[tuple[int, ...], int]]:
    """(programs in order, the jump after the last) of every chain among `programs`."""
    found, nexts = jumps_as_chains(programs)
    chains = [(tuple(c["programs"]), c["programs"][0]) if isinstance(c, dict) else (tuple(c), 0)
              for c in found]
    jumped_to = {p.A for p in programs.values()}
    for start in sorted(set(nexts) - jumped_to):
        path = [start]
        while (target := programs[path[-1]].A) in programs and target not in path:
            path.append(target)
        chains.append((tuple(path), programs[path[-1]].A))
    return sorted(chains)


def chain_motions(image: ModuleImage) -> tuple[ChainMotion, ...]:
    """The motion of every chain of the image, by its first program."""
    programs = {n: p for n, p in enumerate(image.programs, start=1) if p is not None}
    system = image.system
    motions = []
    for numbers, then in _chains(programs):
        _check(image, numbers, programs)
        motions.append(_chain_motion(numbers, then, tuple(programs[n] for n in numbers), system.S1, system.S2,
                                     system.S6))
    return tuple(motions)


@functools.lru_cache(maxsize=1024)
def _chain_motion(numbers: tuple[int, ...], then: int, chained: tuple[Program, ...], s1: int, s2: int,
                  s6: int) -> ChainMotion:
    """The motion of one chain, the programs `numbers` (`chained`) then `then`, on a module of
    these S1, S2 and S6: all it depends on. Kept, as a chain a plan does not change is drawn
    before and after it (and modules of one profile hold the same chains)."""
    programs = dict(zip(numbers, chained))
    acceleration = _si("S6", s6)
    run = _run(numbers, programs, s2, acceleration)
    cycle_time = None
    if then in numbers:
        loop = numbers[numbers.index(then) :]
        cycle_time = _run(loop, programs, programs[numbers[-1]].P, acceleration).segments[-1].end
    return ChainMotion(numbers, then, tuple(run.segments), _intervals(run), cycle_time, _si("S2", s2),
                       _si("S1", s1))


def paired_chains(before: ModuleImage, after: ModuleImage, *, changed_only: bool = False
                  ) -> tuple[tuple[ChainMotion | None, ChainMotion | None], ...]:
    """The chains of two images of one module, paired by their first program (None: the chain is
    not in that image); with `changed_only`, only pairs whose motion differs."""
    was = {m.programs[0]: m for m in chain_motions(before)}
    will = {m.programs[0]: m for m in chain_motions(after)}
    pairs = tuple((was.get(n), will.get(n)) for n in sorted(was.keys() | will.keys()))
    return tuple(p for p in pairs if p[0] != p[1]) if changed_only else pairs
