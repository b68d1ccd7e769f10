"""The time an apply takes, told before (the plan's estimate by phase) and after (estimated against
taken, in one line), and its progress through every phase on a terminal (tmux) — on emulated
9600-baud lines (`line_speed`), where the phases take the time a real line takes; and a line slower
than its settings, noted once."""

from __future__ import annotations

import json
import re

import pytest
import yaml
from emulated import DEMO, emulated_plant, run_cli
from terminal import Pane, environment, needs_tmux, prc3cfg

from prc3cfg import api
from prc3cfg.core.bustime import slower_than_priced

TIME = re.compile(r"Time: (\S+) s \(estimated (\S+) s\) — reading back (\S+) s \((\S+) s\), writing (\S+) s "
                  r"\((\S+) s\), "
                  r"verifying (\S+) s \((\S+) s\)")


def test_an_apply_ends_with_its_time_by_phase_against_the_estimate(tmp_path, capsys):
    """Commissioning the factory-fresh demo with no question, each line written as soon as it is read:
    booth-b reads less before writing than booth-a (booth-b-pretreat's programs are planned as the
    factory's, not read: test_commissioning) and verifies more after, while booth-a is still read — its
    estimate by phase is reckoned so, and is not above what the line took. Then, on the commissioned
    plant, a reviewed plan file's apply: its time by phase against the estimate the plan gave."""
    with emulated_plant(tmp_path, line_speed=True, timeout=0.5) as plant:
        commissioned = api.apply(plant.plant, gates=api.Gates(allow_axis_release=True))
        api.told(commissioned)
        # on every module that has one
        plant.path.write_text(plant.path.read_text().replace("dwell: 0.5\n", "dwell: 0.6\n"))
        planned = run_cli(capsys, "plan", plant.path, "--json", "--out", tmp_path / "plan.json")
        applied = run_cli(capsys, "apply", plant.path, "--plan", tmp_path / "plan.json", "--auto-approve",
                          "--allow-axis-release")
    reckoned = commissioned.plan.phases()
    assert commissioned.plan.by_line and commissioned.took.keys() == reckoned.keys()
    # an emulator at line speed is never faster than the line: the model is not an overestimate — in all, and
    # until every line is read and has written (a phase boundary is a thread's wake-up: 0.1 s; verifying ends
    # where booth-b ends and begins where booth-a's writes end, and a busy machine moves each its own way)
    assert sum(commissioned.took.values()) >= 0.85 * sum(reckoned.values()), (commissioned.took, reckoned)
    for phase in ("reading", "writing"):
        assert commissioned.took[phase] >= 0.85 * reckoned[phase] - 0.1, (commissioned.took, reckoned)
    assert applied.code == 0, applied.err
    last = applied.out.splitlines()[-1]
    found = TIME.fullmatch(last)
    assert found is not None, last
    (took, estimated, reading, reading_estimate, writing, writing_estimate, verifying,
     verifying_estimate) = map(float, found.groups())
    phases = json.loads(planned.out)["estimated_phases_s"]
    assert (reading_estimate, writing_estimate, verifying_estimate) == tuple(round(phases[p], 1)
                                                                             for p in ("reading", "writing",
                                                                                       "verifying"))
    # an emulator at line speed is never faster than the line: the model is not an overestimate
    # the totals: sums, rounded
    assert (abs(took - (reading + writing + verifying)) <= 0.15
            and abs(estimated - sum(phases.values())) <= 0.05)
    assert reading >= 0.85 * phases["reading"] and writing >= 0.85 * phases["writing"]


#: A phase on the progress display: its name, steps done of all, time taken, time left at the rate so far.
SHOWN = re.compile(r"^(reading modules|writing|verifying) .*? (\d+)/(\d+) +(\d+):(\d\d):(\d\d) "
                   r"+(?:(\d+):(\d\d):(\d\d)|-:--:--) left$",
                   re.MULTILINE)


@needs_tmux
def test_each_phase_shows_the_time_left_at_its_rate_so_far(tmp_path):
    """On a terminal, reading and verifying each say how long is left — before any module is done
    "-:--:--", then the modules to go at the time a module has taken so far (9600 baud, `--verify full`:
    seconds a module), counting down: never more than that rate gives for the modules still to go. And
    the apply's snapshot and its time by phase on the same screen (`--verify full` reads every program back).
    """
    with emulated_plant(tmp_path, line_speed=True, timeout=0.5) as plant:
        pane = Pane(tmp_path, prc3cfg("apply", plant.path, "--auto-approve", "--allow-axis-release",
                                      "--verify", "full"), environment())
        try:
            seen: dict[str, list[tuple[int, int, int, int | None]]] = {}

            def verifying_half_done(screen: str) -> bool:
                for found in SHOWN.finditer(screen):
                    phase, done, total, h, m, s, *left = found.groups()
                    took = int(h) * 3600 + int(m) * 60 + int(s)
                    to_go = (None if left[0] is None else int(left[0]) * 3600 + int(left[1]) * 60
                             + int(left[2]))
                    seen.setdefault(phase, []).append((int(done), int(total), took, to_go))
                return any(done >= 3 and to_go is not None for done, _, _, to_go in seen.get("verifying", []))

            shown = pane.wait(verifying_half_done, "verifying 3/6 or more with the time left")
            assert "Snapshot of the modules before writing" in shown
            assert pane.exit_status() == 0, pane.screen()
            assert TIME.search(" ".join(pane.screen().split())) is not None  # (broken for the pane's width)
        finally:
            pane.close()
    for phase in ("reading modules", "verifying"):
        assert phase in seen, seen
        for done, total, took, to_go in seen[phase]:
            # a time left once a module is done, not before
            assert (to_go is None) == (done == 0), (phase, seen[phase])
            # the rate so far, counted down: at most the time per module so far for those to go (whole
            # seconds)
            if to_go is not None:
                assert to_go <= (took + 1) / done * (total - done) + 1, (phase, seen[phase])


SLOW = re.compile(r"note: the line is slower than the plant file's line settings say — bus booth-a: (\d+) "
                  r"exchanges took (\S+) s, its "
                  r"settings price them at (\S+) s \(the modules answered after (\d+) ms on average, "
                  r"turnaround: 0\.01 in the plant "
                  r"file\): (.*)")


@pytest.mark.parametrize(
    ("measured", "priced", "slow"),
    [
        (1.0, 1.0, False),  # as priced
        (0.9, 1.0, False),  # faster: an emulator that answers at once
        (1.24, 0.2, True),  # a short command on a line six times slower
        (0.6, 0.2, False),  # three times slower, but not half a second over: a few exchanges say little
        (12.4, 10.0, False),  # 24 % over: a busy machine, an adapter's latency
        (12.6, 10.0, True),  # 26 % and 2.6 s over
    ],
)
def test_a_line_is_slower_than_its_settings_when_clearly_over_its_price(measured, priced, slow):
    assert slower_than_priced(measured, priced) is slow


def slow_notes(err: str) -> list[re.Match[str]]:
    """The slow-line notes of a command's stderr (any other line saying the line is slower fails)."""
    notes = [line for line in err.splitlines() if "slower than" in line]
    found = [SLOW.fullmatch(line) for line in notes]
    assert all(found), notes
    return [f for f in found if f is not None]


@pytest.mark.parametrize(("query", "noted"),
                         [("?line-speed=9600&turnaround=0.060", True), ("?line-speed=9600", False)])
def test_a_line_slower_than_its_settings_is_noted_once_per_command(tmp_path, capsys, query, noted):
    """Modules that answer after 60 ms on a bus whose plant file says turnaround: 0.010: plan and
    apply (reading, writing, verifying) each end with one note giving the figures; with the emulator
    answering as the bus's keys say, none."""
    document = yaml.safe_load(DEMO.read_text())
    for bus in document["buses"]:
        bus["port"] += query
        bus["turnaround"] = 0.010
    plant = tmp_path / "plant.yaml"
    plant.write_text(yaml.safe_dump(document, sort_keys=False))
    planned = run_cli(capsys, "plan", plant, "--module", "booth-a-left")
    applied = run_cli(capsys, "apply", plant, "--module", "booth-a-left", "--auto-approve",
                      "--allow-axis-release")
    assert planned.code == applied.code == 0, applied.err
    for result in (planned, applied):
        notes = slow_notes(result.err)
        assert len(notes) == noted, result.err
        for note in notes:
            _, took, priced, answered, remedy = note.groups()
            assert float(took) > 1.25 * float(priced) and int(answered) >= 55
            assert remedy == ("an emulator:// port's line-speed and turnaround are slower than its bus's "
                              "keys: give both the same")


def test_a_slow_line_points_at_doctor_with_its_port(tmp_path, capsys):
    """A real port (here the emulator behind socket://) whose module answers after 60 ms: the note
    says which command measures it."""
    with emulated_plant(tmp_path, line_speed=True, timeout=0.5) as plant:
        # booth-a-left, as emulator serve --module-turnaround 1=60ms
        plant.emulators["booth-a"].turnarounds[1] = 0.060
        planned = run_cli(capsys, "plan", plant.path, "--module", "booth-a-left")
        port = plant.plant.buses[0].port
    assert planned.code == 0, planned.err
    note, = slow_notes(planned.err)
    assert note.group(5) == (f"measure the line with prc3cfg doctor --port {port} and put the bus keys it "
                             "prints into the plant file")
