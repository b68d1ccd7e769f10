"""The motion of a module's chains (`prc3cfg.core.motion`) against hand calculations and properties.

The known chain (issue 13's acceptance case), worked out by hand with S6 = 1.2 m/s²:

    S2 = 0.050 m (the pass starts there), S1 = 2.500 m
    program 1: P 2.000 m, V 0.500 m/s, T 1.0 s, F1 = 1100 (set 0.100 m after START),
               F2 = 1050 (set 0.050 m before P), A 2
    program 2: P 0.200 m, V 0.400 m/s, T 0.0 s, F1 = 200 (reset 0.200 m after START),
               F2 = 100 (reset 0.100 m before P), A 1 (a loop)

    move 1: 0.050 → 2.000, d = 1.95 m; ramp v/a = 5/12 s over v²/2a = 5/48 m (2·5/48 < 1.95:
            trapezoid); cruise (1.95 − 5/24) / 0.5 = 209/60 s; move 2·5/12 + 209/60 = 259/60 s
    dwell 1: 259/60 .. 319/60 s at 2.000 m
    move 2: 2.000 → 0.200, d = 1.8 m; ramp 1/3 s over 1/15 m; move 1.8/0.4 + 0.4/1.2 = 29/6 s,
            ends at 319/60 + 290/60 = 609/60 s (10.15 s); dwell 2 of no time
    pass: 609/60 s. Cycle in production: move 1 from 0.200 (1.8 m at 0.5: 3.6 + 5/12 = 241/60 s)
            + 1 s + 290/60 s = 591/60 s (9.85 s)
    F1 set at 0.100 m < 5/48 m, while accelerating: √(2·0.1/1.2) = √(1/6) s
    F2 set 0.050 m before P1, while decelerating (0.05 < 5/48): 259/60 − √(2·0.05/1.2) = 259/60 − √(1/12) s
    F1 reset 0.200 m after move 2 starts, cruising (0.2 > 1/15): 319/60 + 1/3 + (0.2 − 1/15)/0.4 = 359/60 s
    F2 reset 0.100 m before P2, cruising (0.1 > 1/15): 609/60 − 1/3 − (0.1 − 1/15)/0.4 = 584/60 s
"""

from __future__ import annotations

import itertools
import math
from dataclasses import replace
from fractions import Fraction

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from prc3cfg.core.image import DEFAULT_SYSTEM, PROGRAM_COUNT, ModuleImage, Program
from prc3cfg.core.motion import (
    DWELL,
    MOVE,
    MotionError,
    OutputInterval,
    TurningPoint,
    chain_motions,
    paired_chains,
)

TOLERANCE = 1e-9


def image(programs: dict[int, Program], **system: int) -> ModuleImage:
    """A module image holding only `programs` (others not read), with these system parameters."""
    return ModuleImage(1, replace(DEFAULT_SYSTEM, **system),
                       tuple(programs.get(n) for n in range(1, PROGRAM_COUNT + 1)))


TWO_PROGRAMS = image(
    {1: Program(P=2000, V=500, T=10, F1=1100, F2=1050, A=2),
     2: Program(P=200, V=400, T=0, F1=200, F2=100, A=1)},
    S1=2500, S2=50, S6=1200,
)


def close(value: float, expected: Fraction | float) -> bool:
    return abs(value - float(expected)) <= TOLERANCE


def test_the_known_two_program_loop_matches_the_hand_calculation():
    (motion,) = chain_motions(TWO_PROGRAMS)
    assert motion.programs == (1, 2) and motion.then == 1 and motion.loops
    assert motion.label == "chain 1 → 2 → 1"
    move1, dwell1, move2, dwell2 = motion.segments
    assert [s.kind for s in motion.segments] == [MOVE, DWELL, MOVE, DWELL]
    assert [s.program for s in motion.segments] == [1, 1, 2, 2]
    # move 1: a trapezoid from the reference point
    assert (move1.start, move1.start_position, move1.end_position) == (0.0, 0.05, 2.0)
    assert close(move1.ramp, Fraction(5, 12)) and move1.peak == 0.5
    assert close(move1.end, Fraction(259, 60))
    # end of acceleration
    assert close(move1.position(float(Fraction(5, 12))), Fraction(1, 20) + Fraction(5, 48))
    # start of deceleration
    assert close(move1.position(float(Fraction(259, 60) - Fraction(5, 12))), 2 - Fraction(5, 48))
    # dwell 1: a plateau of 1.0 s at P1
    assert close(dwell1.start, Fraction(259, 60)) and close(dwell1.end, Fraction(319, 60))
    assert dwell1.start_position == dwell1.end_position == 2.0
    # move 2 and a dwell of no time
    assert close(move2.ramp, Fraction(1, 3)) and move2.peak == 0.4
    assert close(move2.end, Fraction(609, 60)) and move2.end_position == 0.2
    assert dwell2.start == dwell2.end == move2.end
    # turning points, the pass, the cycle
    assert [(p.program, p.position) for p in motion.turning_points] == [(1, 2.0), (2, 0.2)]
    assert close(motion.turning_points[0].time, Fraction(259, 60)) and close(motion.turning_points[1].time,
                                                                             Fraction(609, 60))
    assert close(motion.duration, Fraction(609, 60))
    assert close(motion.cycle_time, Fraction(591, 60))
    # the outputs
    f1, f2 = motion.outputs
    assert (f1.output, f2.output) == ("F1", "F2")
    assert close(f1.start, math.sqrt(1 / 6)) and close(f1.end, Fraction(359, 60))
    assert close(f2.start, float(Fraction(259, 60)) - math.sqrt(1 / 12)) and close(f2.end, Fraction(584, 60))
    # the axis is where the hand calculation says at every switching time
    assert close(motion.position(f1.start), Fraction(15, 100))
    assert close(motion.position(f2.start), Fraction(195, 100))
    assert close(motion.position(f1.end), Fraction(18, 10))
    assert close(motion.position(f2.end), Fraction(3, 10))


def test_a_move_too_short_to_reach_its_speed_is_triangular():
    (motion,) = chain_motions(image({1: Program(P=100, V=500, A=1)}, S2=50, S6=1200))
    move = motion.segments[0]
    # d = 0.05 m < v²/a = 0.2083 m: peak √(a·d) = √0.06 m/s after √(d/a) s, the move 2·√(0.05/1.2) s
    assert close(move.peak, math.sqrt(0.06)) and close(move.ramp, math.sqrt(0.05 / 1.2))
    assert close(move.end, 2 * math.sqrt(0.05 / 1.2))
    assert close(move.position(move.ramp), 0.075)
    assert motion.cycle_time == 0.0  # a loop of one program that stays at its P without a dwell


def test_function_outputs_act_as_section_1_1_says():
    programs = {
        1: Program(P=500, V=100, F1=1900, F2=1950, A=2),  # both distances longer than the 0.45 m move
        2: Program(P=800, V=100, F1=1010, F2=0, A=3),  # F1 set 0.010 m after START; F2 0 = reset on arrival
        3: Program(P=700, V=100, F1=0, F2=0),  # F1 0: reset at START
    }
    (motion,) = chain_motions(image(programs, S2=50, S6=1000))
    move1, _, move2, _, move3, _ = motion.segments
    # F1 of program 1 never acts (0.9 m > 0.45 m); its F2 sets at START; program 2's F2 resets on arrival
    assert motion.outputs == (
        OutputInterval("F1", move2.time_at(0.010), move3.start),
        OutputInterval("F2", move1.start, move2.end),
    )


def test_an_output_set_for_no_time_has_no_interval():
    # F2 set on arrival at 0.500 m; program 2 does not move and resets F2 at its START, the same moment
    programs = {1: Program(P=500, V=100, F2=1000, A=2), 2: Program(P=500, V=100, F2=0)}
    (motion,) = chain_motions(image(programs, S2=50))
    assert motion.outputs == ()


def test_chains_are_paths_of_jumps_and_loops_are_measured_in_production():
    programs = {
        # 1 runs into the loop 2 ⇄ 3
        1: Program(P=300, V=100, A=2), 2: Program(P=600, V=100, A=3), 3: Program(P=400, V=100, T=5, A=2),
        5: Program(P=300, V=100, A=6), 6: Program(P=200, V=100),  # stops
        7: Program(P=300, V=100, A=9),  # jumps to a program the image does not hold
        8: Program(P=900, V=100),  # neither jumps nor is jumped to: not a chain
    }
    motions = {m.programs: m for m in chain_motions(image(programs, S2=50, S6=1000))}
    assert set(motions) == {(1, 2, 3), (5, 6), (7,)}
    lasso, stops, unheld = motions[(1, 2, 3)], motions[(5, 6)], motions[(7,)]
    assert lasso.label == "chain 1 → 2 → 3 → 2" and lasso.loops
    assert stops.label == "chain 5 → 6 → stop" and stops.cycle_time is None
    assert unheld.label == "chain 7 → 9 (not held)" and unheld.cycle_time is None
    # the loop 2 → 3 → 2 in production: 0.400 → 0.600 and back, 0.2 m at 0.1 m/s each way, and 0.5 s at 3
    assert close(lasso.cycle_time, 2 * (0.2 / 0.1 + 0.1 / 1.0) + 0.5)


def test_the_relative_speed_does_not_change_the_stroke():
    with_vr = image({1: Program(P=2000, V=500, Vr=300, T=10, F1=1100, F2=1050, A=2),
                     2: Program(P=200, V=400, Vr=-600, T=0, F1=200, F2=100, A=1)}, S1=2500, S2=50,
                    S6=1200)
    assert chain_motions(with_vr) == chain_motions(TWO_PROGRAMS)


def test_paired_chains_pair_by_first_program_and_keep_the_changed():
    changed = TWO_PROGRAMS.with_programs({1: Program(P=1800, V=500, T=10, A=2), 5: Program(P=400, V=100, A=6),
                                          6: Program(P=300, V=100)})
    pairs = paired_chains(TWO_PROGRAMS, changed)
    assert [(b and b.programs, a and a.programs) for b, a in pairs] == [((1, 2), (1, 2)), (None, (5, 6))]
    unchanged = TWO_PROGRAMS.with_programs({5: Program(P=400, V=100, A=6), 6: Program(P=300, V=100)})
    assert [a.programs for _, a in paired_chains(TWO_PROGRAMS, unchanged, changed_only=True)] == [(5, 6)]


@pytest.mark.parametrize(("program", "system", "message"), [
    (Program(P=300, V=0, A=1), {}, "module 1, program 1: speed V = 0 — the axis does not move at it"),
    (Program(P=300, V=100, F2=2000, A=1), {}, "module 1, program 1: F2 = 2000 is outside 0..1999"),
    (Program(P=300, V=100, A=1), {"S6": 0},
     "module 1: acceleration S6 = 0 — the motion cannot be worked out without one"),
])
def test_a_damaged_read_back_is_one_line(program, system, message):
    with pytest.raises(MotionError) as raised:
        chain_motions(image({1: program}, **system))
    assert str(raised.value) == message


# -- properties ---------------------------------------------------------------------------------


@st.composite
def chain_images(draw) -> tuple[ModuleImage, tuple[int, ...], bool]:
    """An image with one chain of 1..6 programs (numbers in any order), looping or not; S2 ≤ S1."""
    s1 = draw(st.integers(100, 9999))
    system = {"S1": s1, "S2": draw(st.integers(50, min(500, s1))), "S6": draw(st.integers(1000, 1500))}
    numbers = tuple(draw(st.lists(st.integers(1, PROGRAM_COUNT), min_size=1, max_size=6, unique=True)))
    loop = draw(st.booleans()) and len(numbers) > 1
    programs = {}
    for i, number in enumerate(numbers):
        target = numbers[i + 1] if i + 1 < len(numbers) else (numbers[0] if loop else 0)
        programs[number] = Program(
            P=draw(st.integers(0, s1)), V=draw(st.integers(1, 600)), Vr=draw(st.integers(-600, 600)),
            T=draw(st.integers(0, 600)), F1=draw(st.integers(0, 1999)), F2=draw(st.integers(0, 1999)),
                                   A=target,
        )
    return image(programs, **system), numbers, loop


@settings(max_examples=300, deadline=None)
@given(chain_images())
def test_the_motion_keeps_to_the_axis_and_to_the_programs(case):
    img, numbers, loop = case
    motions = chain_motions(img)
    if len(numbers) == 1:
        assert motions == ()  # a single program that does not jump is not a chain
        return
    (motion,) = motions
    upper = img.system.S1 / 1000
    if loop:  # a loop is drawn from its lowest program
        first = numbers.index(min(numbers))
        numbers = numbers[first:] + numbers[:first]
    assert motion.programs == numbers and motion.loops == loop
    # positions stay within [0, S1]; time increases
    points = motion.curve() + motion.samples(37)
    assert all(-TOLERANCE <= x <= upper + TOLERANCE for _, x in points)
    curve_times = [t for t, _ in motion.curve()]
    assert curve_times == sorted(curve_times)
    previous_end, previous_position = 0.0, img.system.S2 / 1000
    for s in motion.segments:
        assert s.start == previous_end and s.end >= s.start and s.start_position == previous_position
        previous_end, previous_position = s.end, s.end_position
    for number, move, dwell in zip(numbers, motion.segments[::2], motion.segments[1::2]):
        program = img.program(number)
        # a move ends at its P, no faster than V allows
        assert move.kind == MOVE and move.program == number and move.end_position == program.P / 1000
        assert close(move.position(move.end), program.P / 1000)
        assert move.peak <= program.V / 1000 + TOLERANCE
        assert move.end - move.start >= move.distance / (program.V / 1000) - TOLERANCE
        # each dwell is a plateau of length T
        assert dwell.kind == DWELL and dwell.program == number
        assert close(dwell.end - dwell.start, program.T / 10)
        assert dwell.start_position == dwell.end_position == move.end_position
        assert close(motion.position((dwell.start + dwell.end) / 2), program.P / 1000)
    assert motion.turning_points == tuple(TurningPoint(s.program, s.end, s.end_position)
                                          for s in motion.segments[::2])
    for output in ("F1", "F2"):
        intervals = [i for i in motion.outputs if i.output == output]
        assert all(0 <= i.start < i.end <= motion.duration for i in intervals)
        assert all(a.end <= b.start for a, b in itertools.pairwise(intervals))
    if loop:
        # in production the loop comes round from the last P: a pass that starts there takes the cycle time
        from_last = image({n: img.program(n) for n in numbers},
                          **{**img.system.to_json(), "S2": img.program(numbers[-1]).P})
        assert close(motion.cycle_time, chain_motions(from_last)[0].duration)
