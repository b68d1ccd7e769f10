"""The questions of apply, restore and adopt in a real terminal (tmux): each on the screen whole, after
the plan, while its answer is awaited — no progress display drawn over it or below it — and on
the terminal the answer comes from when stdout goes to a file. Each run on an emulated 9600-baud
line (`line_speed`), so the read-back shows its progress before the question."""

from __future__ import annotations

import re

import pytest
from emulated import emulated_plant
from terminal import PROGRESS_LINE, Pane, environment, needs_tmux, prc3cfg

from prc3cfg import api

pytestmark = needs_tmux

SUMMARY = ["⚠ 1 module will release its axes (10h/20h): booth-a/booth-a-left",
           "  It loses its reference point and must travel to it before production."]
ALLOW = "Release the axes of 1 module? Only 'yes' will be accepted:"
APPROVE = re.compile(r"Every module must be in STOP and AUTOMATIC: a running one would take the new values "
                     r"on its next move\. "
                     r"Apply \d+ messages? to 1 module\? Only 'yes' will be accepted:")
#: Screens watched while a question waits: well over one redraw of a progress display (rich: 10 a second).
WATCHED = 8


def asked(pane: Pane, question: str | re.Pattern[str], after: str | None) -> str:
    """The pane waits for an answer to `question`: it is the last line of the screen, whole, below `after`
    (what was printed last before it, if it is on this terminal), and stays so with no progress display
    anywhere on the screen."""

    def last_line(screen: str) -> str:
        return (screen.rstrip().splitlines() or [""])[-1].rstrip()  # a terminal shows no trailing blank

    def shows(screen: str) -> bool:
        line = last_line(screen)
        return line == question if isinstance(question, str) else question.fullmatch(line) is not None

    first = pane.wait(shows, f"the question {question!r}")
    for screen in [first, *pane.watch(WATCHED)]:
        assert shows(screen), f"the question is not the last line of the screen, whole:\n{screen}"
        assert after is None or any(after in line for line in screen.rstrip().splitlines()[:-1]), screen
        drawn = [line for line in screen.splitlines() if PROGRESS_LINE.search(line)]
        assert not drawn, f"a progress display is on the screen while the question waits: {drawn}"
    return first


def answers_both_questions(pane: Pane, command: str = "apply") -> None:
    """The axis question, then the confirmation, each asked whole with no progress on screen; yes to
    both; the one module written and verified, as the `command`'s own words say."""
    try:
        shown = asked(pane, ALLOW, "Plan: 1 of 1 module changes")
        assert shown.rstrip().splitlines()[-3:-1] == SUMMARY, shown
        pane.type("yes")
        asked(pane, APPROVE, ALLOW + " yes")
        pane.type("yes")
        assert pane.exit_status() == 0, pane.screen()
        assert f"{command.capitalize()} complete: 1 module written and verified." in pane.screen()
    finally:
        pane.close()


def test_apply_asks_both_questions_whole_with_no_progress_on_screen(tmp_path):
    with emulated_plant(tmp_path, line_speed=True, timeout=0.5) as plant:
        answers_both_questions(Pane(tmp_path, prc3cfg("apply", plant.path, "--module", "booth-a-left"),
                                    environment()))
        assert plant.matches_plant() is False  # the other modules were left out
        assert not api.plan(plant.plant, ["booth-a-left"]).changes


def test_restore_asks_its_questions_whole_with_no_progress_on_screen(tmp_path):
    with emulated_plant(tmp_path, line_speed=True, timeout=0.5) as plant:
        api.told(api.apply(plant.plant, ["booth-a-left"], gates=api.Gates(allow_axis_release=True)))
        snapshot, = (tmp_path / ".prc3cfg" / "snapshots").iterdir()
        answers_both_questions(Pane(tmp_path, prc3cfg("restore", snapshot), environment()), "restore")


@pytest.mark.parametrize("question", ["axis release", "apply"])
def test_only_yes_typed_out_answers_a_question_that_writes(tmp_path, question):
    """'y' — click's yes, and every yes before — is no to the axis question and to the apply's
    confirmation: refused in one line, nothing written."""
    with emulated_plant(tmp_path, line_speed=True, timeout=0.5) as plant:
        before = plant.images()
        pane = Pane(tmp_path, prc3cfg("apply", plant.path, "--module", "booth-a-left"), environment())
        try:
            asked(pane, ALLOW, "Plan: 1 of 1 module changes")
            if question == "apply":
                pane.type("yes")
                asked(pane, APPROVE, ALLOW + " yes")
            pane.type("y")
            assert pane.exit_status() == 1, pane.screen()
            refused = ("error: axis release of booth-a/booth-a-left not allowed (only 'yes' allows it) — "
                       "nothing was written"
                       if question == "axis release" else "error: not applied — nothing "
                                                          "was written")
            assert refused in pane.screen()
        finally:
            pane.close()
        assert plant.images() == before


def test_with_stdout_in_a_file_the_plan_asked_about_is_on_the_terminal_too(tmp_path):
    """`prc3cfg apply plant.yaml > apply.log`: the questions are asked on the terminal, and the plan they are
    about is shown there too, not only written to the file (issue 42: the question reached the terminal, the
    plan did not) — its long lines broken for the terminal's width, as a plan on stdout is."""
    with emulated_plant(tmp_path, line_speed=True, timeout=0.5) as plant:
        log = tmp_path / "apply.log"
        pane = Pane(tmp_path, prc3cfg("apply", plant.path, "--module", "booth-a-left"), environment(),
                    stdout=log)
        try:
            screen = asked(pane, ALLOW, None)
            assert ("~ bus booth-a, module 1 (booth-a-left):" in screen
                    and "Plan: 1 of 1 module changes" in screen), screen
            # broken for the pane's 160 columns after a comma, under the first field (the file has it whole)
            assert "\n" + " " * 17 + "F2 reset at 0.000 m → reset at 0.050 m\n" in screen, screen
            pane.type("no")
            assert pane.exit_status() == 1, pane.screen()
        finally:
            pane.close()
        logged = log.read_text()
        assert ("~ bus booth-a, module 1 (booth-a-left):" in logged
                and "set at 0.020 m, F2 reset at 0.000 m → reset at 0.050 m\n" in logged)  # one line there


@pytest.mark.parametrize("stdout", ["terminal", "file"])
def test_adopt_asks_on_the_terminal_the_answer_comes_from(tmp_path, stdout):
    """With stdout in a file (`prc3cfg adopt plant.yaml > adopt.log`) the question is still asked
    on the terminal that answers it — the diff goes to the file."""
    with emulated_plant(tmp_path, line_speed=True, timeout=0.5) as plant:
        api.told(api.apply(plant.plant, ["booth-a-left"], gates=api.Gates(allow_axis_release=True)))
        plant.emulators["booth-a"].teach_in(1, 1, 2080)
        log = tmp_path / "adopt.log" if stdout == "file" else None
        pane = Pane(tmp_path, prc3cfg("adopt", plant.path, "--module", "booth-a-left"), environment(),
                    stdout=log)
        question = f"Write 1 value into {plant.path}? [y/N]:"
        try:
            asked(pane, question, None if log else f"+++ {plant.path} (adopted)")
            pane.type("y")
            assert pane.exit_status() == 0, pane.screen()
            said = log.read_text() if log else pane.screen()
        finally:
            pane.close()
        assert f"Adopted 1 value into {plant.path}" in said
        assert "position: 2.08\n" in plant.path.read_text()
