"""`prc3cfg read` and `prc3cfg plan` against real emulators: outputs, exit codes, warnings, plan file."""

from __future__ import annotations

import html
import json
import os
import re
import subprocess
import sys
from dataclasses import replace

from emulated import emulated_plant, run_cli

from prc3cfg.core import codec, render
from prc3cfg.core.plan_file import image_sha256

WARNING = "travel to reference point required"


def test_read_json_is_exactly_what_the_emulators_hold(plant, capsys):
    result = run_cli(capsys, "read", plant.path, "--json")
    assert result.code == 0, result.err
    entries = json.loads(result.out)
    held = plant.images()
    assert len(entries) == 6
    for entry in entries:
        image = held[(entry["bus"], entry["address"])]
        for number, program in enumerate(entry["programs"], start=1):
            assert program is None or program == image.program(number).to_json()
        assert entry["system"] == image.system.to_json()


def test_read_shows_each_module_as_read_and_says_which_programs_it_did_not_read(plant, capsys):
    """`read` reads what the plant file manages and what its system parameters could clamp: once applied,
    booth-a-left's profile manages programs 1–3 and leaves the others alone, booth-b-pretreat
    (`unmanaged_programs: reset`) manages every one. What was not read is said, not left for the reader to
    take as absent."""
    assert run_cli(capsys, "apply", plant.path, "--auto-approve", "--allow-axis-release").code == 0
    result = run_cli(capsys, "read", plant.path)
    assert result.code == 0, result.err
    modules = re.split(r"^(?=bus )", result.out, flags=re.MULTILINE)[1:]
    shown = {module.splitlines()[0]: module.splitlines()[1:] for module in modules}
    left = shown["bus booth-a, module 1 (booth-a-left)"]
    assert [line.split(":")[0] for line in left] == ["  system", "  program 1", "  program 2", "  program 3",
                                                     "  not read"]
    assert left[-1] == ("  not read: programs 4–64 — the plant file leaves them alone, and its system "
                        "parameters cannot clamp them")
    top = shown["bus booth-a, module 5 (booth-a-top)"]
    assert top[-1] == ("  not read: programs 4–9, 12–64 — the plant file leaves them alone, and its system "
                       "parameters cannot clamp them")
    pretreat = shown["bus booth-b, module 4 (booth-b-pretreat)"]
    assert len(pretreat) == 1 + 64 and not any("not read" in line for line in pretreat)


def test_a_step_s_bytes_are_shown_only_with_frames_and_always_kept_in_the_plan_file(plant, capsys, tmp_path):
    """People read what a step does; its bytes in hex only with --frames (plan, show, markdown) — the plan
    file keeps them, as apply --plan sends them."""
    system_step = re.compile(r"^ +1\. (?:([0-9a-f]{8,}) +)?write system parameters", re.MULTILINE)
    saved = tmp_path / "plan.json"
    plain = run_cli(capsys, "plan", plant.path, "--out", saved)
    framed = run_cli(capsys, "plan", plant.path, "--frames")
    frame = json.loads(saved.read_text())["buses"][0]["modules"][0]["steps"][0]["message"]
    assert [m.group(1) for m in system_step.finditer(plain.out)] == [None] * 6
    assert next(m.group(1) for m in system_step.finditer(framed.out)) == frame
    for args in (("show", saved), ("show", saved, "--markdown"), ("plan", plant.path, "--markdown")):
        assert frame not in run_cli(capsys, *args).out, args
        assert frame in run_cli(capsys, *args, "--frames").out, args


def test_the_command_a_plan_prints_to_apply_it_runs_as_printed_from_a_folder_with_spaces(tmp_path, capsys):
    """"apply it with: prc3cfg apply --plan …" names a path with spaces and non-ASCII letters: pasted into
    the shell as printed, it runs (issue 42: unquoted, it failed with exit 64 under C:\\Users\\First Last)."""
    folder = tmp_path / "Anlage Süd – Linie 3"
    folder.mkdir()
    with emulated_plant(folder) as plant:
        planned = run_cli(capsys, "plan", plant.path, "--out", folder / "plan (reviewed).json")
        printed = planned.out.rsplit("apply it with: ", 1)[1].strip()
        assert printed == f"prc3cfg apply --plan '{folder / 'plan (reviewed).json'}'"
        pasted = subprocess.run(["sh", "-c", f"{printed} --auto-approve --allow-axis-release"],
                                capture_output=True, text=True,
                                cwd=tmp_path, env=os.environ | {"PYTHONPATH": os.pathsep.join(sys.path)},
                                check=False)
        assert pasted.returncode == 0, pasted.stderr
        assert plant.matches_plant()


def test_plan_from_factory_shows_changes_and_axis_warnings_everywhere(plant, capsys, tmp_path):
    human = run_cli(capsys, "plan", plant.path, "--detailed-exitcode", "--out", tmp_path / "plan.json")
    assert human.code == 2
    assert WARNING in human.out and "RELEASES AXES" in human.out
    assert "upper reversing point 0.400 m → 2.200 m" in human.out

    document = json.loads((tmp_path / "plan.json").read_text())
    assert document["format"] == "prc3cfg-plan/1" and document["plant"] == "demo-line"
    module = document["buses"][0]["modules"][0]
    assert module["releases_axes"] is True and WARNING in module["warning"]
    assert module["steps"][0]["releases_axes"] is True
    assert codec.decode_message(bytes.fromhex(module["steps"][0]["message"])).ID == 0x20
    assert sum(len(m["steps"]) for b in document["buses"] for m in b["modules"]) == document["message_count"]

    as_json = run_cli(capsys, "plan", plant.path, "--json")
    assert as_json.code == 0
    assert json.loads(as_json.out)["axis_releases"] == [f"{b}/{n}" for b, n in (
        ("booth-a", "booth-a-left"), ("booth-a", "booth-a-right"), ("booth-a", "booth-a-top"),
        ("booth-b", "booth-b-left"), ("booth-b", "booth-b-right"), ("booth-b", "booth-b-pretreat"))]

    markdown = run_cli(capsys, "plan", plant.path, "--markdown")
    assert markdown.code == 0
    assert "<details>" in markdown.out and "| bus | module |" in markdown.out
    assert WARNING in markdown.out and "⚠ releases axes" in markdown.out


def test_plan_state_hash_is_the_read_back(plant, capsys, tmp_path):
    run_cli(capsys, "plan", plant.path, "--out", tmp_path / "plan.json")
    document = json.loads((tmp_path / "plan.json").read_text())
    read = json.loads(run_cli(capsys, "read", plant.path, "--json").out)
    hashes = {(e["bus"], e["address"]): e for e in read}
    from prc3cfg.core.image import ModuleImage

    for bus in document["buses"]:
        for module in bus["modules"]:
            entry = hashes[(bus["name"], module["address"])]
            assert module["state_sha256"] == image_sha256(ModuleImage.from_json(entry))


def test_no_change_plan_has_no_warning_and_exit_0(plant, capsys):
    assert run_cli(capsys, "apply", plant.path, "--auto-approve", "--allow-axis-release").code == 0
    result = run_cli(capsys, "plan", plant.path, "--detailed-exitcode")
    assert result.code == 0
    assert WARNING not in result.out and "No changes" in result.out


def test_a_speed_tweak_is_one_cheap_step_without_axis_release(plant, capsys, tmp_path):
    assert run_cli(capsys, "apply", plant.path, "--auto-approve", "--allow-axis-release").code == 0
    plant.path.write_text(plant.path.read_text().replace("speed: 0.35", "speed: 0.34", 1))
    result = run_cli(capsys, "plan", plant.path, "--json", "--module", "booth-a-left")
    document = json.loads(result.out)
    steps = document["buses"][0]["modules"][0]["steps"]
    assert [s["message"][:2] for s in steps] in (["41"], ["32"])
    assert not steps[0]["releases_axes"] and document["axis_releases"] == []
    assert document["estimated_bus_time_s"] < document["naive_bus_time_s"] or len(steps) == 1


def test_plan_against_saved_images_needs_no_bus(plant, capsys, tmp_path):
    saved = tmp_path / "actual.json"
    saved.write_text(run_cli(capsys, "read", plant.path, "--json").out)
    for emulator in plant.emulators.values():
        emulator.close()  # the bus is gone
    result = run_cli(capsys, "plan", plant.path, "--actual", saved, "--detailed-exitcode")
    assert result.code == 2 and "Plan: 6 of 6 modules change" in result.out


def test_usage_error_under_detailed_exitcode_is_not_changes(plant, capsys):
    result = run_cli(capsys, "plan", plant.path, "--detailed-exitcode", "--no-such-option")
    assert result.code not in (0, 2)


def test_unknown_module_name_is_one_line(plant, capsys):
    result = run_cli(capsys, "plan", plant.path, "--module", "nope")
    assert result.code == 1
    assert result.err.count("\n") == 1 and "no module named nope" in result.err


def test_a_silent_bus_is_one_line_naming_bus_and_module(plant, capsys):
    plant.emulators["booth-b"].update(3, mode="manual")
    result = run_cli(capsys, "plan", plant.path, "--module", "booth-b-right", "--retries", "1")
    assert result.code == 1
    # the line's 0.053 s, the bus's 0.1 s on top
    assert result.err.startswith("error: bus booth-b, module 3: no reply within 0.153 s")
    assert result.err.count("\n") == 1


def test_a_saved_plan_shows_what_the_live_plan_showed_charts_and_marks_included(plant, capsys, tmp_path):
    """One vocabulary for a change: the human plan ends with what its marks mean; `show PLAN.json
    --markdown` shows the stroke charts `plan --markdown` showed, from the plan file alone."""
    saved = tmp_path / "plan.json"
    live = run_cli(capsys, "plan", plant.path, "--markdown", "--out", saved)
    assert live.code == 0 and live.out.count("```mermaid") >= 1
    shown = run_cli(capsys, "show", saved, "--markdown")
    assert shown.code == 0
    # what show adds: the review text is the one its digests were written for
    said = f"> {render.REVIEW_AS_WRITTEN}\n\n"
    assert said in shown.out and shown.out.replace(said, "", 1) == live.out
    human = run_cli(capsys, "plan", plant.path)
    assert human.out.splitlines()[-1] == render.LEGEND
    assert "No changes" not in human.out and render.LEGEND.startswith("Marks: ~ changed")


def test_a_saved_plan_without_its_total_time_is_shown_with_the_sum_of_its_phases(plant, capsys, tmp_path):
    saved = tmp_path / "plan.json"
    assert run_cli(capsys, "plan", plant.path, "--out", saved).code == 0
    document = json.loads(saved.read_text())
    phases = document["estimated_phases_s"]
    # an older or a hand-trimmed file: show shows it all the same (apply --plan refuses it)
    del document["estimated_time_s"]
    saved.write_text(json.dumps(document))
    shown = run_cli(capsys, "show", saved)
    assert shown.code == 0, shown.err
    assert f"estimated time {sum(phases.values()):.1f} s" in shown.out


#: Not printable text (C0, DEL, C1, the line and paragraph separators, lone surrogates).
# a new line (\x0a) apart: outputs have lines
CONTROL = re.compile("[\x00-\x09\x0b-\x1f\x7f-\x9f\u2028\u2029\ud800-\udfff]")
HOSTILE = "\x1b]0;owned\x07\x1b[2J\u2028\ud800"


def test_the_texts_of_a_plan_file_are_shown_escaped_by_show_and_apply(plant, capsys, tmp_path):
    """A plan file is data anyone may have edited: whose verification it says it took as known and its
    notes — with a terminal's title and clear-screen escapes, a bell, a line separator and a lone
    surrogate — are shown by `show` (text and markdown) escaped, each on its line, and never as a
    traceback; `apply --plan`, which works `taken` out again, refuses the edit in one escaped line."""
    assert run_cli(capsys, "apply", plant.path, "--auto-approve", "--allow-axis-release").code == 0
    plant.path.write_text(plant.path.read_text().replace("position: 2.1", "position: 2.0", 1))
    made = tmp_path / "plan.json"
    assert run_cli(capsys, "plan", plant.path, "--out", made).code == 0
    document = json.loads(made.read_text())
    # a targeted plan: it says its base
    assert document["read"]["base"] == "the line's record of what prc3cfg last read or verified"
    first = next(iter(document["read"]["taken"]))
    document["read"]["taken"][first] += HOSTILE
    document["left_alone"] = [f"a note{HOSTILE}"]
    edited = tmp_path / "edited.json"
    edited.write_text(json.dumps(document))
    said = "\\x1b]0;owned\\x07\\x1b[2J\\u2028\\ud800"
    for options in ([], ["--markdown"]):
        shown = run_cli(capsys, "show", edited, *options)
        assert (shown.code, shown.err) == (0, ""), shown.err
        assert CONTROL.search(shown.out) is None
        text = html.unescape(shown.out)  # markdown: as GitHub shows it
        assert f"UTC){said} read or verified them" in text and f"a note{said}" in text
    applied = run_cli(capsys, "apply", plant.path, "--plan", edited, "--auto-approve")
    assert applied.code == 1 and f"read.taken.{first} is not what this apply read" in applied.err
    assert CONTROL.search(applied.out + applied.err) is None


def test_a_comment_cut_to_its_budget_still_counts_the_clamped_programs_and_the_releases(tmp_path, capsys):
    """4 modules lower S1 under 60 programs the plant does not manage each: 240 programs clamped. A comment of
    3,000 characters has no room for the details; its head still says how many are clamped, and on how many
    modules."""
    import yaml

    from prc3cfg.core.image import ModuleImage, Program

    plant = tmp_path / "plant.yaml"
    modules = [{"address": a, "name": f"m{a}", "system": {"upper_reversing_point": 1.0}} for a in range(1, 5)]
    plant.write_text(yaml.safe_dump({"plant": "p",
                                     "buses": [{"name": "b", "port": "socket://127.0.0.1:9",
                                                "modules": modules}]}))
    held = [ModuleImage.factory(a) for a in range(1, 5)]
    held = [replace(image, system=replace(image.system, S1=2500)).with_programs({n: Program(P=2000, V=50)
                                                                                 for n in range(1, 61)})
            for image in held]
    saved = tmp_path / "actual.json"
    saved.write_text(json.dumps([{"bus": "b", **image.to_json()} for image in held]))
    for made in ("plan", "show"):
        args = (["plan", plant, "--actual", saved, "--out", tmp_path / "plan.json"] if made == "plan"
                else ["show", tmp_path / "plan.json"])
        cut = run_cli(capsys, *args, "--markdown", "--max-chars", "3000")
        assert cut.code == 0, cut.err
        assert ("are left out to keep this comment under 3,000 characters" in cut.out
                and "<details>" not in cut.out)
        assert ("> ⚠ 240 programs the plant does not manage are clamped by 4 modules as their system "
                "parameters change") in cut.out
        assert "⚠ 4 modules release the axes" in cut.out
    human = run_cli(capsys, "show", tmp_path / "plan.json")
    assert "⚠ 240 programs the plant does not manage are clamped by 4 modules" in human.out
