"""How plans show diffs, jumps and field names to people."""

from __future__ import annotations

import html
import itertools
import math
import re
from dataclasses import replace
from pathlib import Path

import pytest
from hypothesis import given
from hypothesis import strategies as st

from prc3cfg.core import plan_file, render
from prc3cfg.core.bustime import LineCost
from prc3cfg.core.device import widest_range
from prc3cfg.core.image import PROGRAM_FIELDS, SYSTEM_KEYS, ModuleImage, Program
from prc3cfg.core.line import LineSettings
from prc3cfg.core.planner import Action, plan_module
from prc3cfg.core.plant_plan import ModuleChange, PlantPlan
from prc3cfg.core.render import (
    CLAMPED,
    LEGEND,
    FieldChange,
    changes_json,
    field_changes,
    field_name,
    hanging,
    human,
    jumps,
    markdown,
    module_diff,
    module_lines,
    unchanged_line,
)
from prc3cfg.core.what_to_read import read_messages, verification_time


def image_with(jumps_: dict[int, int]) -> ModuleImage:
    factory = ModuleImage.factory(1)
    return factory.with_programs({n: Program(P=150, V=50, A=a) for n, a in jumps_.items()})


@pytest.mark.parametrize(
    ("jumps_", "within", "expected"),
    [
        ({}, {1, 2}, set()),
        ({1: 2, 2: 3}, {1, 2, 3}, {"chain 1 → 2 → 3 → stop"}),
        ({10: 11, 11: 12, 12: 10}, {10, 11, 12}, {"chain 10 → 11 → 12 → 10"}),
        ({1: 3, 2: 3}, {1, 2, 3}, {"jump 1 → 3", "jump 2 → 3"}),
        ({3: 10}, {3}, {"jump 3 → 10"}),  # 10 is not managed: nothing is claimed about it
        ({1: 2, 2: 1, 5: 6}, {1, 2, 5, 6}, {"chain 1 → 2 → 1", "chain 5 → 6 → stop"}),
    ],
)
def test_jumps(jumps_, within, expected):
    assert jumps(image_with(jumps_), within) == expected


@pytest.mark.parametrize(
    ("symbol", "name"),
    [("S1", "upper reversing point"), ("S12", "sync conveyor sequence"), ("Vr", "relative speed"),
     ("T", "dwell"), ("F2", "F2")],
)
def test_field_name(symbol, name):
    assert field_name(symbol) == name


@pytest.mark.parametrize("symbol", [*SYSTEM_KEYS, *(f for f in PROGRAM_FIELDS if f != "A")])
def test_a_value_is_shown_raw_exactly_outside_the_devices_range(symbol):
    """The rendering's range is the device model's (`device.widest_range`), not a table of its own."""
    low, high = widest_range(symbol)
    assert "raw" not in render.format_value(symbol, low) and "raw" not in render.format_value(symbol, high)
    assert render.format_value(symbol, low - 1) == f"{low - 1} (raw, outside {low}..{high})"
    assert render.format_value(symbol, high + 1) == f"{high + 1} (raw, outside {low}..{high})"


COST = LineCost.of("crc16", LineSettings(), 0.010, 0.020)


def a_change() -> ModuleChange:
    """Program 1 set up, program 2's jump changed, S1 lowered below unmanaged program 5's position."""
    actual = ModuleImage.factory(1).with_programs({2: Program(P=300, V=100, A=3), 3: Program(P=350, V=100),
                                                   5: Program(P=390, V=90)})
    desired = replace(actual, system=replace(actual.system, S1=380)).with_programs(
        {1: Program(P=200, V=60, Vr=5, F1=1010, A=2), 2: Program(P=300, V=100, A=1),
         **{n: None for n in range(3, 65)}})
    return ModuleChange("a", "m", actual, desired, plan_module(actual, desired, COST))


def test_a_module_diff_compares_the_images_field_by_field() -> None:
    change = a_change()
    assert module_lines(changes_json(change)) == [
        "~ system: upper reversing point 0.400 m → 0.380 m",
        (
            "+ program 1: position 0.150 m → 0.200 m, speed 0.050 m/s → 0.060 m/s, relative speed 0.000 m/s →"
            " 0.005 m/s, F1 reset at 0.000 m → set at 0.010 m"
        ),
        "- jump 2 → 3",
        "+ chain 1 → 2 → 1",
        f"~ program 5 (not managed, kept): position 0.390 m → 0.380 m — {CLAMPED}",
    ]
    changes = changes_json(change)
    assert [(f["program"], f["field"], f["before"], f["after"]) for f in changes["fields"]] == [
        (None, "S1", 400, 380), (1, "P", 150, 200), (1, "V", 50, 60), (1, "Vr", 0, 5), (1, "F1", 0, 1010)]
    assert changes["clamped"] == [{"program": 5, "field": "P", "before": 390, "after": 380,
                                   "text": "position 0.390 m → 0.380 m", "reason": CLAMPED}]
    assert (changes["chains_removed"], changes["chains_added"]) == (["jump 2 → 3"], ["chain 1 → 2 → 1"])


def test_each_change_carries_the_action_whose_mark_the_plan_shows() -> None:
    """Terraform's vocabulary on each change: the module's, each program's (also in the plan file's
    JSON, as plain marks), and the legend says what every mark means."""
    change = a_change()
    assert change.plan.action is Action.UPDATE and Action.of_module(0) is Action.NO_OP
    diff = module_diff(change)
    assert diff.actions == {1: Action.CREATE}
    assert type(changes_json(change)["symbols"]["1"]) is str
    assert unchanged_line("a", [1]) == f"{Action.NO_OP} bus a: no changes at address 1"
    for action, meaning in ((Action.UPDATE, "changed"), (Action.CREATE, "set up from factory defaults"),
                            (Action.DELETE, "put back to factory defaults")):
        assert f" {action} {meaning}" in LEGEND


def test_a_program_either_image_lacks_has_no_field_changes() -> None:
    factory = ModuleImage.factory(1)
    assert field_changes(factory, factory.with_programs({1: None, 2: Program(P=160, V=50)})) == [
        FieldChange(2, "P", 150, 160, "position 0.150 m → 0.160 m")]


def test_a_live_plan_shows_what_its_plan_file_shows() -> None:
    """The human and markdown outputs of a live plan work each module's diff out as they show it;
    the plan file's document carries them all: both must read the same."""
    plan = PlantPlan("p", "p.yaml", "0" * 64, (a_change(),))
    document = plan_file.write(plan, ["module x left the plant file: it stays on the hardware"], render)
    assert human(plan, notes=document["left_alone"]) == human(document)
    assert module_lines(changes_json(plan.changes[0]))[0] in markdown(plan)
    assert ("```diff\n"
            + "\n".join(module_lines(document["buses"][0]["modules"][0]["changes"])) in markdown(document))


def full_line_plan(tmp_path):
    """30 modules × 64 programs, every program changed, names that are hard on markdown."""
    import yaml

    from prc3cfg import api
    from prc3cfg.core.image import ModuleImage

    modules = []
    for address in range(1, 31):
        programs = {n: {"position": round(0.3 + (n * 7 + address) % 150 / 100, 3),
                        "speed": round(0.05 + (n + address) % 40 / 100, 3)}
                    for n in range(1, 65)}
        name = {1: "left|right", 2: "<b>bold</b>", 3: "a & b"}.get(address, f"m{address}")
        modules.append({"address": address, "name": name, "unmanaged_programs": "reset",
                        "system": {"upper_reversing_point": 2.0, "max_speed": 0.5}, "programs": programs})
    plant_file = tmp_path / "plant.yaml"
    plant_file.write_text(yaml.safe_dump({"plant": "full|line",
                                          "buses": [{"name": "line", "port": "socket://127.0.0.1:9",
                                                     "modules": modules}]}))
    plant = api.load(plant_file)
    return api.plan(plant, images={("line", a): ModuleImage.factory(a) for a in range(1, 31)})


def test_a_full_line_plan_fits_a_comment_with_every_warning_and_a_row_per_module(tmp_path):
    import re

    import cmarkgfm

    plan = full_line_plan(tmp_path)
    text = render.markdown(plan, full_plan="`plan.json`")
    assert len(text) <= render.COMMENT_BUDGET
    assert text.startswith(render.MARKER)
    assert len(plan.axis_releases) == 30 and all(render.code(f"line/{m.name}") in text
                                                 for m in plan.axis_releases)
    assert "are left out to keep this comment under 65,000 characters: the full plan is `plan.json`." in text
    page = cmarkgfm.github_flavored_markdown_to_html(text)
    body = page.split("<tbody>", 1)[1].split("</tbody>", 1)[0]
    rows = re.findall(r"<tr>(.*?)</tr>", body, re.S)
    assert len(rows) == 30
    cells = [re.findall(r"<td[^>]*>(.*?)</td>", row, re.S) for row in rows]
    assert [c[1] for c in cells[:3]] == ["left|right", "&lt;b&gt;bold&lt;/b&gt;", "a &amp; b"]
    # outside the table, names read as written too: in code spans, and in each module's summary
    assert "<h3>prc3cfg plan — <code>full|line</code></h3>" in page
    warning = page.split("travel to reference point required after apply", 1)[1].split("</blockquote>", 1)[0]
    assert re.findall(r"<code>(.*?)</code>", warning)[:3] == ["line/left|right",
                                                              "line/&lt;b&gt;bold&lt;/b&gt;",
                                                              "line/a &amp; b"]
    # as GitHub: <details> kept
    shown = cmarkgfm.github_flavored_markdown_to_html(text, options=cmarkgfm.cmark.Options.CMARK_OPT_UNSAFE)
    summaries = re.findall(r"<summary>(.*?) \(address", shown)
    assert summaries[:3] == ["line / left|right", "line / &lt;b&gt;bold&lt;/b&gt;", "line / a &amp; b"]


@pytest.mark.parametrize("text", ["plain", "a|b", "<b>", "`tick`", "a``b", "&amp;"])
def test_a_code_span_shows_its_text_as_written(text):
    import cmarkgfm

    page = cmarkgfm.github_flavored_markdown_to_html(f"x {render.code(text)} y")
    assert html.unescape(page.split("<code>", 1)[1].split("</code>", 1)[0]) == text


def test_the_budget_is_kept_for_any_size(tmp_path):
    plan = full_line_plan(tmp_path)
    with pytest.raises(render.BudgetTooSmall) as refused:  # the table and warnings always, or no comment
        render.markdown(plan, max_chars=1)
    for budget in (refused.value.needed, 5_000, 20_000, 200_000):
        if budget >= refused.value.needed:
            assert len(render.markdown(plan, max_chars=budget)) <= budget
    assert "left out" not in render.markdown(plan, max_chars=10_000_000)


def test_an_apply_is_reckoned_as_its_lines_run() -> None:
    """The phases as an apply measures them — until every line is read, until every line has written, the
    rest: with a question (or a plan file) every line's writes begin once all lines are read; without, each
    line is written and verified as soon as it is read, and a line done while another is still read adds
    nothing. Here line a commissions (programs planned as the factory's, not read, verified after the
    writes): it reads less than line b, which writes nothing, and is still verifying when b is read."""
    change = replace(a_change(), cost=COST, assumed=tuple(range(8, 40)))
    held = change.actual
    unchanged = ModuleChange("b", "n", held, held, plan_module(held, held, COST), cost=COST)
    asked = PlantPlan("p", "p.yaml", "0" * 64, (change, unchanged))
    read_a, write_a, verify_a = change.reading_time, change.plan.bus_time, change.verifying_time
    read_b = unchanged.reading_time
    assert read_a < read_b < read_a + write_a + verify_a
    assert asked.phases() == pytest.approx({"reading": read_b, "writing": write_a, "verifying": verify_a})
    by_line = replace(asked, by_line=True)
    assert by_line.phases() == pytest.approx({"reading": read_b, "writing": 0.0,
                                              "verifying": read_a + write_a + verify_a - read_b})
    # the total: the line that ends last
    assert sum(by_line.phases().values()) == pytest.approx(read_a + write_a + verify_a)
    assert sum(asked.phases().values()) == pytest.approx(read_b + write_a + verify_a)


def test_a_plan_states_its_time_by_phase_and_the_total_as_its_headline() -> None:
    """Reading back what the plan was made from, writing, verifying: priced by the bus-time model,
    the longest line's each (lines run at once), their sum the headline of the human plan and the
    markdown, with the writes' bus time beside the naive download."""
    change = replace(a_change(), cost=COST)
    other = replace(change, bus="b", name="n")  # a second line, alike: it runs at the same time
    plan = PlantPlan("p", "p.yaml", "0" * 64, (change, other))
    # its read-back holds every program: 1 + 16 reads
    reading = math.fsum(COST.message_time(1, m) for m in read_messages(range(1, 65)))
    verifying = verification_time(change.actual, change.plan.predicted, change.steps, COST)
    assert plan.phases() == pytest.approx({"reading": reading, "writing": change.plan.bus_time,
                                           "verifying": verifying})
    document = plan_file.write(plan, (), render)
    assert document["estimated_phases_s"] == {phase: round(seconds, 3)
                                              for phase, seconds in plan.phases().items()}
    assert document["estimated_time_s"] == round(reading + change.plan.bus_time + verifying, 3)
    said = (f"estimated time {document['estimated_time_s']:.1f} s: reading back {reading:.1f} s, writing "
            f"{change.plan.bus_time:.1f} s "
            f"(bus time {plan.bus_time:.3f} s, naive download {plan.naive_bus_time:.3f} s), verifying "
            f"{verifying:.1f} s; "
            "⚠ 2 modules release the axes")
    assert human(plan).splitlines()[-2:] == [f"Plan: 2 of 2 modules change, {plan.message_count} "
                                             f"messages, {said}", LEGEND]
    assert f"\n\nPlan: 2 of 2 modules change, {plan.message_count} messages, {said}\n" in markdown(plan)


def test_an_apply_says_its_time_by_phase_against_the_estimate_in_one_line() -> None:
    said = render.timing({"reading": 4.9, "writing": 0.61, "verifying": 0.5},
                         {"reading": 5.04, "writing": 0.66, "verifying": 0.52})
    assert said == ("Time: 6.2 s (estimated 6.0 s) — reading back 5.0 s (4.9 s), writing 0.7 s (0.6 s), "
                    "verifying 0.5 s (0.5 s)")


def test_show_says_each_value_in_both_units_with_its_source_from_plain_values() -> None:
    """`show`'s words come from plain values — no plant file, no terminal."""
    factory = ModuleImage.factory(4)
    program = Program(P=1750, V=350, F1=1020, A=0)
    sources = {"unmanaged_programs": "default", "chains": "module"} | {key: "default" for key in (
        "upper_reversing_point", "reference_point", "increment_pulses", "max_speed", "min_speed",
        "acceleration", "circuit_gain", "alarm", "sync_increment", "sync_circuit_gain",
        "sync_conveyor_sequence")}
    shown = render.shown_module(render.Settings(
        name="left", bus="booth-a", address=4, profiles=(), unmanaged_programs="keep", system=factory.system,
        programs={3: program}, sources=sources | {"upper_reversing_point": "profile fast"},
        program_sources={3: dict.fromkeys(
            ("position", "speed", "relative_speed", "dwell", "f1", "f2", "jump"), "module")},
        chains=(((3, 5), True),),
    ))
    assert shown.heading == ("module ", "left", " — bus booth-a, address 4, profiles: none")
    unmanaged, system, programs, chains = shown.blocks
    assert unmanaged == "unmanaged_programs: keep (default)"
    assert isinstance(system, render.Table) and isinstance(programs, render.Table)
    assert system.sections[0][0] == ("upper_reversing_point (S1)", "0.400 m", "400", "profile fast")
    assert programs.sections[0][0] == ("3", "position (P)", "1.750 m", "1750", "module")
    assert ("", "f1 (F1)", "set at 0.020 m", "1020", "module") in programs.sections[0]
    assert programs.sections[0][-1] == ("", "jump (A)", "stop", "0", "module")
    assert chains == "chains (module): 3 → 5 → 3 (loop)"


def test_an_account_names_the_releases_earlier_applies_left_untold_and_the_broadcasts_proved_heard() -> None:
    from types import SimpleNamespace

    from prc3cfg.core.plant_plan import LineProof

    killed = SimpleNamespace(bus="booth-a", name="left", command="apply", pid=41, time="2024-05-01T10:00:00",
                             journal=None, owner=None)
    claimed = SimpleNamespace(**vars(killed) | {"bus": "booth-a\x1b[1A\x1b[2K", "name": "left\u202e",
                                                "owner": "bob (uid 1002)"})
    told = SimpleNamespace(**vars(killed) | {"journal": "j.jsonl"})
    assert render.earlier_releases([killed, told, claimed]) == [
        "⚠ Travel to reference point required before production on: booth-a/left (possibly: an earlier "
        "prc3cfg apply, pid 41 at 2024-05-01T10:00:00, sent a 10h/20h and ended before its account)",
        "⚠ Travel to reference point required before production on: booth-a/left (possibly: an earlier "
        "prc3cfg apply, pid 41 at 2024-05-01T10:00:00, sent a 10h/20h and ended before its account; "
        "journal j.jsonl)",
        "⚠ Travel to reference point required before production on: booth-a\\x1b[1A\\x1b[2K/left\\u202e "
        "(possibly: bob (uid 1002)'s record says an earlier prc3cfg apply, pid 41 at 2024-05-01T10:00:00, "
        "sent a 10h/20h and ended before its account)"]
    runs = [SimpleNamespace(bus="line", broadcasts=1), SimpleNamespace(bus="other", broadcasts=0)]
    proofs = [LineProof("line", silent=(3, 4, 5)), LineProof("other", silent=(9,)), LineProof("quiet")]
    assert render.broadcasts_heard(proofs, runs) == [
        "Bus line: broadcast after addresses 3–5 answered no probe — only the plan's modules heard it"]


def test_the_travel_list_groups_its_modules_by_bus_on_lines_a_screen_holds() -> None:
    """30 released modules on a line and one possibly released on another: a heading, then each bus's modules
    on lines of their own, each line within TRAVEL_WIDTH, wrapped between modules, every module named once."""
    from types import SimpleNamespace

    from prc3cfg.core.axes import Release

    runs = [SimpleNamespace(bus="booth-a", name=f"reciprocator-{n:02d}", released=Release.YES)
            for n in range(1, 31)]
    runs += [SimpleNamespace(bus="booth-b", name="pretreat", released=Release.POSSIBLY),
             SimpleNamespace(bus="booth-b", name="x", released=Release.NO)]
    heading, *lines = render.travel_list(runs).splitlines()
    assert heading == render.TRAVEL and len(lines) > 2
    assert all(len(line) <= render.LIST_WIDTH and line.startswith("    ") for line in lines), lines
    named = [name.strip() for line in lines for name in line.split(",") if name.strip()]
    assert (named == [f"booth-a/reciprocator-{n:02d}" for n in range(1, 31)]
            + ["booth-b/pretreat (possibly: its 10h/20h went out unacknowledged)"])
    # another bus, another line
    assert lines[-1] == "    booth-b/pretreat (possibly: its 10h/20h went out unacknowledged)"


def test_a_plan_lists_the_modules_it_releases_by_bus_on_lines_a_screen_holds(tmp_path) -> None:
    """30 modules of a line whose axes the plan releases, and the demo's two buses: under the warning's
    heading, each bus's modules on lines of their own within LIST_WIDTH, every module named once, in the
    plan's order — as the account lists them after the apply (30 modules were one line of hundreds of
    characters)."""
    from prc3cfg import api

    def travel(plan: PlantPlan) -> list[str]:
        lines = render.human(plan).splitlines()
        at = lines.index(render.AXIS_HEADING)
        return list(itertools.takewhile(lambda line: line.startswith("    "), lines[at + 1:]))

    full = full_line_plan(tmp_path)
    lines = travel(full)
    assert len(lines) > 2 and all(len(line) <= render.LIST_WIDTH for line in lines), lines
    named = [name.strip() for line in lines for name in line.split(",") if name.strip()]
    assert named == [f"line/{m.name}" for m in full.axis_releases] and len(named) == 30
    demo = api.load(Path(__file__).resolve().parent.parent / "plants" / "demo-line.yaml")
    factory = {(b.name, m.address): ModuleImage.factory(m.address) for b, m in demo.modules()}
    assert travel(api.plan(demo, images=factory)) == [
        "    booth-a/booth-a-left, booth-a/booth-a-right, booth-a/booth-a-top",
        "    booth-b/booth-b-left, booth-b/booth-b-right, booth-b/booth-b-pretreat"]


#: Lines as plans have them: an indent, a mark, a heading before ": ", fields after it joined by ", " (a field
#: has spaces of its own, and may be longer than a terminal is wide).
_FIELD = st.text(st.sampled_from("abc →.²0 "), min_size=1, max_size=60).map(str.strip).filter(bool)
PLAN_LINES = st.builds(lambda indent, head, fields: " " * indent + head + ": " + ", ".join(fields),
                       st.integers(0, 12), st.sampled_from(["~ system", "+ program 3", "Read now", "x" * 70]),
                       st.lists(_FIELD, min_size=1, max_size=12))


@given(PLAN_LINES, st.integers(20, 200))
def test_a_long_line_is_broken_between_fields_under_where_its_text_began(line, width) -> None:
    """`hanging`: a line that fits is left whole; one that does not keeps its words in order, its first part
    starts as it did, every later part under the text after its first ": " (or two columns in, where that is
    past half the width), and no part is wider than `width` but for a word that alone is."""
    parts = hanging(line, width)
    if len(line) <= width:
        assert parts == [line]
        return
    assert " ".join(" ".join(parts).split()) == " ".join(line.split())
    assert parts[0].startswith(line[:len(line) - len(line.lstrip())] + line.lstrip().split()[0])
    indent = len(line) - len(line.lstrip())
    colon = line.index(": ")
    hang = colon + 2 if colon + 2 <= width // 2 else min(indent + 2, width // 2)
    for part in parts[1:]:
        assert part[:hang].strip() == "" and part[hang] != " ", (parts, hang)
    assert all(len(part) <= width or len(part.split()) == 1 for part in parts), parts


def test_a_plan_s_lines_break_after_their_commas() -> None:
    """The demo's longest diff line (program 3 set up from factory defaults) and its headline on an 80-column
    terminal: each field whole, each line after the first under the first field."""
    line = ("    + program 3: position 0.150 m → 1.200 m, speed 0.050 m/s → 0.250 m/s, relative speed "
            "0.000 m/s → 0.030 m/s, F1 reset at 0.000 m → set at 0.020 m, "
            "F2 reset at 0.000 m → reset at 0.050 m")
    assert hanging(line, 79) == [
        "    + program 3: position 0.150 m → 1.200 m, speed 0.050 m/s → 0.250 m/s,",
        "                 relative speed 0.000 m/s → 0.030 m/s,",
        "                 F1 reset at 0.000 m → set at 0.020 m,",
        "                 F2 reset at 0.000 m → reset at 0.050 m"]
    # a line ends with the comma of its last field: the field was not put on it without room for that comma
    summary = ("Plan: 6 of 6 modules change, 26 messages, estimated time 6.0 s: reading back 4.9 s, "
               "writing 0.6 s (bus time 1.099 s, naive download 1.149 s), verifying 0.5 s; "
               "⚠ 6 modules release the axes")
    assert hanging(summary, 79) == [
        "Plan: 6 of 6 modules change, 26 messages,",
        "      estimated time 6.0 s: reading back 4.9 s,",
        "      writing 0.6 s (bus time 1.099 s, naive download 1.149 s),",
        "      verifying 0.5 s; ⚠ 6 modules release the axes"]


def test_a_plan_shown_line_by_line_as_the_writes_began_lists_each_line_s_releases_once() -> None:
    """`apply --auto-approve --allow-axis-release` shows each line's plan as its writes begin (`line_part`),
    its releases with it; the whole plan after it leaves those lines out — it listed all 60 modules again."""
    from prc3cfg import api

    demo = api.load(Path(__file__).resolve().parent.parent / "plants" / "demo-line.yaml")
    factory = {(b.name, m.address): ModuleImage.factory(m.address) for b, m in demo.modules()}
    plan = api.plan(demo, images=factory)
    booth_a = render.line_part(replace(plan, modules=tuple(m for m in plan.modules if m.bus == "booth-a")))
    assert booth_a.splitlines()[-2:] == [
        render.AXIS_HEADING, "    booth-a/booth-a-left, booth-a/booth-a-right, booth-a/booth-a-top"]
    after = render.human(plan, shown={"booth-a"}).splitlines()
    at = after.index(render.AXIS_HEADING)
    assert after[at + 1] == "    booth-b/booth-b-left, booth-b/booth-b-right, booth-b/booth-b-pretreat"
    assert not after[at + 2].startswith("    ")
    assert render.AXIS_HEADING not in render.human(plan, shown={"booth-a", "booth-b"})


def test_a_plan_says_which_modules_of_a_bus_it_leaves_as_they_are_in_one_line(tmp_path) -> None:
    """One module of 30 changed was one section among 29 lines of "no changes": after a bus's changed modules,
    one line names by address those the plan leaves as they are."""
    from prc3cfg import api

    def unchanged(plan: PlantPlan) -> list[str]:
        return [line for line in render.human(plan).splitlines() if "no changes" in line]

    demo = api.load(Path(__file__).resolve().parent.parent / "plants" / "demo-line.yaml")
    held = {(b.name, m.address): m.desired_image() for b, m in demo.modules()}
    text = render.human(api.plan(demo, images=held | {("booth-a", 2): ModuleImage.factory(2)}))
    lines = text.splitlines()
    at = lines.index(f"{Action.NO_OP} bus booth-a: no changes at addresses 1, 5")
    assert lines[at - 2].startswith("      ") and lines[at - 1] == ""  # after the changed module's steps
    assert lines[at + 1] == f"{Action.NO_OP} bus booth-b: no changes at addresses 1, 3, 4"
    assert "booth-a-right" in text and "booth-a-left" not in text
    full_line_plan(tmp_path)
    line = api.load(tmp_path / "plant.yaml")
    held = {(b.name, m.address): m.desired_image() for b, m in line.modules()}
    assert unchanged(api.plan(line, images=held | {("line", 13): ModuleImage.factory(13)})) == [
        f"{Action.NO_OP} bus line: no changes at addresses 1–12, 14–30"]


def test_a_reason_said_once_places_each_module_by_the_longest_name_it_begins_with() -> None:
    """"b/m (spare) (why)" begins with "b/m (" too: read as module m's, the spare's address was lost from the
    group (or, grouped, module m's said in its place)."""
    why = "its system parameters are not those on record"
    modules = [{"address": address, "name": name, "read": {"programs": [], "programs_not_read": []}}
               for address, name in ((1, "m"), (2, "m (spare)"), (3, "x"), (4, "y"))]
    document = {"buses": [{"name": "b", "modules": modules}],
                "read": {"not_as_verified": [f"b/{m['name']} ({why})" for m in modules], "base": "",
                         "modules_not_read": [], "taken": {}}}
    assert render.reading_line(document) == (
        f"Read now: the system parameters of 4 modules and 0 programs; read in full: {why} at bus b "
        "addresses 1–4")

#: Texts a plant or plan file could bring into a pull-request comment, meant to do more than be read.
HOSTILE = {
    "a mention": "@octocat",
    "a team": "@org/plant-floor",
    "an e-mail": "ops@evil.example",
    "a link": "[release notes](https://evil.example)",
    "an image": "![x](https://evil.example/a.png)",
    "a reference link": "[x][1]",
    "an autolink": "<https://evil.example>",
    "a bare URL": "see https://evil.example/a",
    "a www link": "www.evil.example",
    "HTML": "<img src=x onerror=alert(1)>",
    "a closing summary": "</summary></details><script>x</script>",
    "emphasis": "**bold** _it_ ~~gone~~",
    "a table cell": "a|b",
    "a code span": "`x`",
    "a fence": "```",
    "an entity": "&lt;b&gt;",
    "a backslash": "\\[x\\](y)",
    "a new line and a heading": "m\n# heading",
    "a terminal escape": "m\x1b[2J\x07",
}
#: Not printable text, and how a terminal is shown it: as Python's repr escapes it, without the quotes.
CONTROL = re.compile("[\x00-\x1f\x7f-\x9f\u2028\u2029\ud800-\udfff]")


def escaped(text: str) -> str:
    return CONTROL.sub(lambda m: repr(m.group())[1:-1], text)


#: What a comment may hold as HTML: what prc3cfg writes itself.
OUR_TAGS = {"h3", "p", "blockquote", "table", "thead", "tbody", "tr", "th", "td", "details", "summary", "pre",
            "code", "em", "strong"}


@pytest.mark.parametrize("case", HOSTILE, ids=list(HOSTILE))
def test_text_from_a_plan_file_is_never_live_in_a_comment(case):
    """A name, a bus, a note, the base: each shown as written — no mention, link, image, HTML, cell or line of
    its own."""
    import cmarkgfm

    hostile = HOSTILE[case]
    document = plan_file.write(PlantPlan("p", "p.yaml", "0" * 64,
                                         (replace(a_change(), bus=hostile, name=hostile),)), [hostile],
                               render)
    document["plant"] = hostile
    document["read"] = {"base": hostile, "modules_not_read": [hostile], "not_as_verified": [hostile]}
    document["buses"][0]["modules"][0]["read"] = {"programs": [1, 2], "programs_not_read": []}
    text = markdown(document)
    # as GitHub: HTML kept
    page = cmarkgfm.github_flavored_markdown_to_html(text, options=cmarkgfm.cmark.Options.CMARK_OPT_UNSAFE)
    assert set(re.findall(r"<([a-z0-9]+)", page)) <= OUR_TAGS, page
    outside_code = re.sub(r"<(code|pre)>.*?</\1>", "", page, flags=re.S)
    # GitHub makes a mention of any text but code
    assert re.search(r"@[A-Za-z0-9]", html.unescape(outside_code)) is None
    assert not any(c in text for c in "\x1b\x07")
    cells = re.findall(r"<td[^>]*>(.*?)</td>", page, re.S)
    assert "\u200d" not in text  # a mention is broken by an empty comment, which a paste does not carry
    assert html.unescape(cells[0]).replace("<!-- -->", "") == escaped(hostile)  # the bus, as written
    assert len(cells) == 6  # one row: bus, module, address, steps, bus time, axes


@pytest.mark.parametrize("case", HOSTILE, ids=list(HOSTILE))
def test_text_from_a_plan_file_is_plain_text_on_a_terminal(case):
    """The human plan shows every text of a plan file with its control characters escaped: one line stays one
    line."""
    hostile = HOSTILE[case] + "\u2028\x85\ud800"
    plan = PlantPlan("p", "p.yaml", "0" * 64, (replace(a_change(), bus=hostile, name=hostile),))
    live = human(plan, notes=[hostile])  # names a script gave the API, and notes, as a plan file's
    assert (CONTROL.search(live.replace("\n", "")) is None
            and f"Left as it is: {escaped(hostile)}" in live.splitlines())
    document = plan_file.write(plan, [hostile], render)
    document["read"] = {"base": hostile, "modules_not_read": [hostile], "not_as_verified": []}
    document["buses"][0]["modules"][0]["read"] = {"programs": [1, 2], "programs_not_read": []}
    shown = human(document)
    assert CONTROL.search(shown.replace("\n", "")) is None
    shown.encode()  # no lone surrogate: a terminal can be written this
    assert "\\u2028\\x85\\ud800" in shown
    assert f"Left as it is: {escaped(hostile)}" in shown.splitlines()


def test_a_comment_with_no_room_for_details_still_says_what_was_clamped_released_and_not_read():
    """The head is never cut: the releases, the programs clamped, the modules taken as last verified."""
    document = plan_file.write(PlantPlan("p", "p.yaml", "0" * 64, (a_change(), replace(a_change(), bus="b"))),
                               (), render)
    document["read"] = {"base": "the plant file last applied in full here",
                        "modules_not_read": ["a/x", "a/y"], "not_as_verified": []}
    for module in [m for bus in document["buses"] for m in bus["modules"]]:
        module["read"] = {"programs": [1, 2], "programs_not_read": []}
    with pytest.raises(render.BudgetTooSmall) as refused:
        markdown(document, max_chars=1)
    text = markdown(document, max_chars=refused.value.needed)
    assert "left out" in text and "<details>" not in text
    assert "⚠ 2 modules release the axes" in text and "2 modules (a/x, a/y)" in text
    assert ("> ⚠ 2 programs the plant does not manage are clamped by 2 modules as their system "
            "parameters change") in text


def test_a_plan_files_charts_are_shown_only_as_prc3cfg_draws_them():
    """A stroke chart is markdown of prc3cfg's own making, and the plan file keeps it: one of another
    shape — a fence closed early, HTML after it — is left out, never shown."""
    plan = PlantPlan("p", "p.yaml", "0" * 64, (a_change(),))
    document = plan_file.write(plan, (), render)
    charts = document["buses"][0]["modules"][0]["changes"]["charts"]
    assert len(charts) == 3 and charts[1].startswith("```mermaid\n")  # ours: shown
    hostile = [charts[1].replace("xychart-beta", "```\n<img src=x onerror=alert(1)>\n```mermaid"),
               "<script>alert(1)</script>",
               "\n_1 more chain changed: [see](https://evil.example) draws them all._"]
    document["buses"][0]["modules"][0]["changes"]["charts"] = [*charts, *hostile]
    text = markdown(document)
    assert charts[1] in text and not any(chart in text for chart in hostile)
    assert "<img" not in text and "<script" not in text and "evil.example" not in text


THIRTY = [f"booth-{bus}/booth-{bus}-reciprocator-{n:02d}" for bus in "ab" for n in range(1, 16)]


@pytest.mark.parametrize(
    ("names", "said"),
    [
        (["booth-a/left"], "booth-a/left"),
        (["booth-a/left", "booth-a/right"], "booth-a/left, booth-a/right"),
        (THIRTY, ", ".join(THIRTY[:4]) + " and 26 more"),
        (["x" * 400, "y"], "x" * 400 + " and 1 more"),  # the first name is always shown
    ],
)
def test_the_axis_question_names_what_fits_and_counts_the_rest(names, said):
    assert render.some_of(names) == said


def test_the_axis_summary_stays_two_lines_for_a_full_line():
    """Thirty modules: the count, the first names and 'and N more', then what a release means — two
    lines of at most two terminal rows each, so the question stays on the screen with the plan's end."""
    summary = render.release_summary(THIRTY)
    assert summary[0].startswith("⚠ 30 modules will release their axes (10h/20h): "
                                 "booth-a/booth-a-reciprocator-01, ")
    assert summary[1] == "  Each loses its reference point and must travel to it before production."
    assert len(summary) == 2 and all(len(line) <= 2 * 100 for line in summary)
