"""The time an apply takes, told before (the plan's estimate by phase) and after (estimated against
taken, in one line), and its progress through every phase on a terminal (tmux) — on emulated
9600-baud lines (`line_speed`), where the phases take the time a real line takes."""

from __future__ import annotations

import json
import re

from emulated import emulated_plant, run_cli
from terminal import Pane, environment, needs_tmux, prc3cfg

TIME = re.compile(r"Time: (\S+) s \(estimated (\S+) s\) — reading back (\S+) s \((\S+) s\), writing (\S+) s \((\S+) s\), "
                  r"verifying (\S+) s \((\S+) s\)")  # fmt: skip


def test_an_apply_ends_with_its_time_by_phase_against_the_estimate(tmp_path, capsys):
    with emulated_plant(tmp_path, line_speed=True, timeout=0.5) as plant:
        planned = run_cli(capsys, "plan", plant.path, "--json")
        applied = run_cli(capsys, "apply", plant.path, "--auto-approve", "--allow-axis-release")
    assert applied.code == 0, applied.err
    last = applied.out.splitlines()[-1]
    found = TIME.fullmatch(last)
    assert found is not None, last
    took, estimated, reading, reading_estimate, writing, writing_estimate, verifying, verifying_estimate = map(float, found.groups())
    phases = json.loads(planned.out)["estimated_phases_s"]
    assert (reading_estimate, writing_estimate, verifying_estimate) == tuple(round(phases[p], 1) for p in ("reading", "writing", "verifying"))
    # an emulator at line speed is never faster than the line: the model is not an overestimate
    assert abs(took - (reading + writing + verifying)) <= 0.15 and abs(estimated - sum(phases.values())) <= 0.05  # the totals: sums, rounded
    assert reading >= 0.85 * phases["reading"] and writing >= 0.85 * phases["writing"]


@needs_tmux
def test_verification_shows_its_progress_on_a_terminal(tmp_path):
    """`--verify full` reads every program back: seconds at 9600 baud, counted module by module."""
    with emulated_plant(tmp_path, line_speed=True, timeout=0.5) as plant:
        pane = Pane(tmp_path, prc3cfg("apply", plant.path, "--auto-approve", "--allow-axis-release", "--verify", "full"), environment())
        try:
            shown = pane.wait(lambda screen: re.search(r"^verifying .* \d/6 ", screen, re.MULTILINE) is not None, "verifying n/6")
            assert "Snapshot of the modules before writing" in shown
            assert pane.exit_status() == 0, pane.screen()
            assert TIME.search(pane.screen()) is not None
        finally:
            pane.close()
