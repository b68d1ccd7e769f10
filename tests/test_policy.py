"""Policy as code (issue 44, item 1): envelopes and windows of the policy file a plant file names, judged by
`plan` and again by `apply` before the line opens, on emulated buses through the command line; windows' DST
edges as a table.

The moment windows are judged at is `PRC3CFG_POLICY_NOW` in the command tests (the core takes it as a value).
"""

from __future__ import annotations

import functools
import itertools
import json
import re
from datetime import UTC, datetime, timedelta
from pathlib import Path
from zoneinfo import ZoneInfo

import jsonschema
import pytest
from emulated import DEMO, emulated_plant, run_cli
from hypothesis import given, settings
from hypothesis import strategies as st

from prc3cfg.core import policy
from prc3cfg.plant import PlantError
from prc3cfg.plant.policy import parse_policy, policy_schema_text
from prc3cfg.shell import platform

SCHEMAS = Path(__file__).resolve().parents[1] / "schemas"
SPEEDS = """format: prc3cfg-policy/1
envelopes:
  - name: booth speeds
    level: {level}
    buses: [booth-a]
    limits:
      speed: {{max: 0.300}}
"""
#: Berlin's production shift, Monday to Friday 06:00 for 10 hours.
SHIFT = """format: prc3cfg-policy/1
windows:
  - name: production
    kind: deny
    level: soft
    cron: "0 6 * * 1-5"
    duration: 10h
    time_zone: Europe/Berlin
"""
#: The same shift on booth-b alone.
SHIFT_ON_BOOTH_B = SHIFT + "    buses: [booth-b]\n"
MONDAY_MORNING = "2026-11-30T09:00:00+01:00"  # in the shift
SUNDAY = "2026-11-29T09:00:00+01:00"


@pytest.fixture
def source(tmp_path):
    """The demo plant naming its policy file `rules.yaml` (written beside the emulated copy by each test)."""
    path = tmp_path / "source.yaml"
    path.write_text(DEMO.read_text() + "\npolicy: rules.yaml\n")
    return path


@pytest.fixture
def plant(tmp_path, source):
    directory = tmp_path / "plant"
    directory.mkdir()
    with emulated_plant(directory, source=source) as emulated:
        FACTORY[id(emulated)] = emulated.images()
        yield emulated
        del FACTORY[id(emulated)]


def _at(path: Path, line: int, column: int) -> str:
    """The text of `path` from line:column on (1-based)."""
    return path.read_text().splitlines()[line - 1][column - 1:]


def _untouched(plant) -> bool:
    """No module was written: every one still holds the factory's settings (what the fixture started them
    with)."""
    return plant.images() == FACTORY[id(plant)]


FACTORY: dict[int, dict] = {}


def test_an_envelope_violation_is_refused_at_plan_and_at_apply_naming_the_value_and_the_rule(plant, capsys,
                                                                                             monkeypatch):
    rules = plant.path.parent / "rules.yaml"
    rules.write_text(SPEEDS.format(level="hard"))
    monkeypatch.setenv("PRC3CFG_POLICY_NOW", SUNDAY)
    planned = run_cli(capsys, "plan", plant.path)
    assert planned.code == 3, planned.err
    found = re.search(r"plant\.yaml:(\d+):(\d+): hard: module booth-a-left: program 1 speed 0\.350 m/s is "
                      r"above 0\.300 m/s, "
                      r"the limit of envelope 'booth speeds' \(rule at .*rules\.yaml:(\d+):(\d+)\)",
                      planned.out)
    assert found, planned.out
    line, column, rule_line, rule_column = map(int, found.groups())
    assert _at(plant.path, line, column).startswith("0.35")
    assert _at(rules, rule_line, rule_column).startswith("{max: 0.300}")
    # the envelope covers booth-a only
    assert "booth-b" not in "".join(re.findall(r".*hard: module.*", planned.out))
    applied = run_cli(capsys, "apply", plant.path, "--auto-approve", "--allow-axis-release",
                      "--override-envelope", "wanted")
    assert applied.code == 1
    assert f"plant.yaml:{line}:{column}: hard: module booth-a-left: program 1 speed" in applied.err
    assert "a hard rule is never overridden" in applied.err
    assert _untouched(plant)


def test_an_advisory_envelope_is_shown_and_refuses_nothing(plant, capsys, monkeypatch):
    (plant.path.parent / "rules.yaml").write_text(SPEEDS.format(level="advisory"))
    monkeypatch.setenv("PRC3CFG_POLICY_NOW", SUNDAY)
    planned = run_cli(capsys, "plan", plant.path, "--detailed-exitcode")
    assert planned.code == 2, planned.err  # changes, no refusal
    assert "advisory: module booth-a-left: program 1 speed 0.350 m/s is above 0.300 m/s" in planned.out
    applied = run_cli(capsys, "apply", plant.path, "--auto-approve", "--allow-axis-release")
    assert applied.code == 0, applied.err
    # said on the apply too
    assert "advisory: module booth-a-left: program 1 speed 0.350 m/s is above 0.300 m/s" in applied.err
    assert plant.matches_plant()


def test_a_soft_envelope_is_refused_unless_overridden(plant, capsys, monkeypatch):
    (plant.path.parent / "rules.yaml").write_text(SPEEDS.format(level="soft"))
    monkeypatch.setenv("PRC3CFG_POLICY_NOW", SUNDAY)
    assert run_cli(capsys, "plan", plant.path).code == 0  # only a hard rule fails a plan
    refused = run_cli(capsys, "apply", plant.path, "--auto-approve", "--allow-axis-release")
    assert refused.code == 1 and "--override-envelope REASON" in refused.err and _untouched(plant)
    applied = run_cli(capsys, "apply", plant.path, "--auto-approve", "--allow-axis-release",
                      "--override-envelope", "trial coat")
    assert applied.code == 0, applied.err
    assert plant.matches_plant()


def _journal_header(plant) -> dict:
    journals = sorted((plant.path.parent / ".prc3cfg" / "journal").glob("*.jsonl"))
    return json.loads(journals[-1].read_text().splitlines()[0])


def test_a_deny_window_refuses_an_apply_before_the_line_opens_and_an_override_is_recorded_with_its_reason(
    plant, capsys, monkeypatch
):
    (plant.path.parent / "rules.yaml").write_text(SHIFT)
    monkeypatch.setenv("PRC3CFG_POLICY_NOW", MONDAY_MORNING)
    planned = run_cli(capsys, "plan", plant.path)
    assert planned.code == 0, planned.err  # a plan is read-only: a window judges the moment of an apply
    assert "soft: bus booth-a: deny window 'production' is open until 2026-11-30 16:00 CET" in planned.out
    refused = run_cli(capsys, "apply", plant.path, "--auto-approve", "--allow-axis-release")
    # only a window refuses: try again later (EX_TEMPFAIL), not a mistake (docs/fleet.md)
    assert refused.code == 75
    assert re.search(r"rules\.yaml:3:5: soft: bus booth-a: deny window 'production' is open until "
                     r"2026-11-30 16:00 CET", refused.err)
    assert "--override-window REASON" in refused.err
    assert _untouched(plant)
    assert not (plant.path.parent / ".prc3cfg" / "journal").exists()  # the line was never opened
    applied = run_cli(capsys, "apply", plant.path, "--auto-approve", "--allow-axis-release",
                      "--override-window", "line down: ticket 4711")
    assert applied.code == 0, applied.err
    assert "overridden by" in applied.err and "line down: ticket 4711" in applied.err
    header = _journal_header(plant)
    said = header["policy"]
    assert said["now"] == "2026-11-30T08:00:00+00:00" and said["clock"] == "PRC3CFG_POLICY_NOW"
    assert {(o["kind"], o["rule"], o["reason"], o["user"]) for o in said["overridden"]} == {
        ("window", "production", "line down: ticket 4711", platform.user_name())}
    assert plant.matches_plant()


def test_outside_the_window_the_apply_goes_on(plant, capsys, monkeypatch):
    (plant.path.parent / "rules.yaml").write_text(SHIFT)
    monkeypatch.setenv("PRC3CFG_POLICY_NOW", "2026-11-30T16:00:00+01:00")  # the shift's end: shut
    applied = run_cli(capsys, "apply", plant.path, "--auto-approve", "--allow-axis-release")
    assert applied.code == 0, applied.err
    assert _journal_header(plant)["policy"]["overridden"] == []


def test_a_change_to_the_policy_shows_in_the_plan(plant, capsys, monkeypatch):
    rules = plant.path.parent / "rules.yaml"
    rules.write_text("format: prc3cfg-policy/1\n")
    monkeypatch.setenv("PRC3CFG_POLICY_NOW", SUNDAY)
    before = run_cli(capsys, "plan", plant.path, "--json")
    rules.write_text(SPEEDS.format(level="advisory"))
    after = run_cli(capsys, "plan", plant.path, "--json")
    plan_schema = json.loads((SCHEMAS / "plan.schema.json").read_text(encoding="utf-8"))
    for said in (before.out, after.out):
        jsonschema.validate(json.loads(said), plan_schema)
    first, second = json.loads(before.out)["policy"], json.loads(after.out)["policy"]
    assert first["findings"] == [] and first["file"].endswith("rules.yaml")
    assert first["sha256"] != second["sha256"]
    assert {f["rule"] for f in second["findings"]} == {"booth speeds"}
    assert {f["text"].partition(": advisory: module ")[2].partition(":")[0] for f in second["findings"]} == {
        "booth-a-left", "booth-a-right", "booth-a-top"}  # every module of the line it affects, none other
    markdown = run_cli(capsys, "plan", plant.path, "--markdown").out
    assert (markdown.startswith("#### Policy") and second["sha256"][:12] in markdown
            and "booth speeds" in markdown)


@pytest.mark.parametrize(("text", "expected"), [
    ("format: prc3cfg-policy/1\nwindows:\n  - {name: w, kind: deny, cron: '0 6 * *', duration: 1h, "
     "time_zone: Europe/Berlin}\n",
     "rules.yaml:3:33: 'cron': a cron expression has 5 fields"),
    ("format: prc3cfg-policy/1\nwindows:\n  - {name: w, kind: deny, cron: '0 6 * * *', duration: 1h, "
     "time_zone: Europe/Bonn}\n",
     "rules.yaml:3:71: 'time_zone': 'Europe/Bonn' is not an IANA time zone"),
    ("format: prc3cfg-policy/1\nenvelopes:\n  - {name: e, limits: {speed: {max: fast}}}\n",
     "rules.yaml:3:37: 'max': 'fast' is not a number — give one in the plant file's units"),
    ("format: prc3cfg-policy/1\nenvelopes:\n  - {name: e, levle: hard, limits: {speed: {max: 1}}}\n",
     "rules.yaml:3:15: unknown key 'levle'"),
    ("format: prc3cfg-policy/2\n",
     "rules.yaml:1:9: 'format' is 'prc3cfg-policy/2' — it is one of 'prc3cfg-policy/1'"),
    ("format: prc3cfg-policy/1\nwindows: [{name: w, kind: deny, cron: '0 6 * * *', duration: 1h, time_zone: "
     "x, time_zone: y}]\n",
     "rules.yaml:2:"),
])
def test_a_malformed_policy_file_is_one_line_naming_file_line_and_column(text, expected):
    with pytest.raises(PlantError) as refused:
        parse_policy("rules.yaml", text.encode())
    assert str(refused.value).startswith(expected), str(refused.value)
    assert "Traceback" not in str(refused.value) and "Input should" not in str(refused.value)


def test_a_plant_naming_a_missing_policy_is_refused_in_one_line(plant, capsys):
    result = run_cli(capsys, "plan", plant.path)
    assert result.code == 1
    assert result.err.strip().endswith("rules.yaml: no such file (the policy file " + str(plant.path)
                                       + " names) — check the path"), result.err
    assert len(result.err.strip().splitlines()) == 1


def _window(cron: str, duration: timedelta, zone: str, kind: str = "deny") -> policy.Window:
    return policy.Window("w", "soft", kind, policy.parse_cron(cron), duration, ZoneInfo(zone), (),
                         ("windows", 0))  # type: ignore[arg-type]


BERLIN, NEW_YORK = "Europe/Berlin", "America/New_York"


@pytest.mark.parametrize(("zone", "cron", "hours", "now", "open_since"), [
    # spring forward, Berlin 2026-03-29 02:00 CET → 03:00 CEST: 02:30 does not exist, the window starts at
    # 01:30 UTC (03:30 CEST)
    (BERLIN, "30 2 * * *", 1, "2026-03-29T01:29:00+00:00", None),
    (BERLIN, "30 2 * * *", 1, "2026-03-29T01:30:00+00:00", "2026-03-29T01:30:00+00:00"),
    (BERLIN, "30 2 * * *", 1, "2026-03-29T02:29:00+00:00", "2026-03-29T01:30:00+00:00"),
    # an hour of real time, not of the wall clock
    (BERLIN, "30 2 * * *", 1, "2026-03-29T02:30:00+00:00", None),
    # the day before: 02:30 CET
    (BERLIN, "30 2 * * *", 1, "2026-03-28T01:30:00+00:00", "2026-03-28T01:30:00+00:00"),
    # fall back, Berlin 2026-10-25 03:00 CEST → 02:00 CET: 02:30 comes twice, the window starts at the first
    # (00:30 UTC)
    (BERLIN, "30 2 * * *", 1, "2026-10-25T00:30:00+00:00", "2026-10-25T00:30:00+00:00"),
    (BERLIN, "30 2 * * *", 1, "2026-10-25T01:30:00+00:00", None),  # the second 02:30 starts nothing
    # a shift across the change: 22:00 CET for 10 hours of real time ends at 09:00 CEST on the wall (not
    # 08:00)
    (BERLIN, "0 22 * * *", 10, "2026-03-29T06:59:00+00:00", "2026-03-28T21:00:00+00:00"),
    (BERLIN, "0 22 * * *", 10, "2026-03-29T07:00:00+00:00", None),
    # and in autumn 22:00 CEST for 10 hours ends at 07:00 CET on the wall
    (BERLIN, "0 22 * * *", 10, "2026-10-25T05:59:00+00:00", "2026-10-24T20:00:00+00:00"),
    (BERLIN, "0 22 * * *", 10, "2026-10-25T06:00:00+00:00", None),
    # New York 2026-03-08 02:00 EST → 03:00 EDT, and 2026-11-01 02:00 EDT → 01:00 EST
    (NEW_YORK, "30 2 * * *", 1, "2026-03-08T07:29:00+00:00", None),
    (NEW_YORK, "30 2 * * *", 1, "2026-03-08T07:30:00+00:00", "2026-03-08T07:30:00+00:00"),  # 03:30 EDT
    # the first 01:30 (EDT)
    (NEW_YORK, "30 1 * * *", 1, "2026-11-01T05:30:00+00:00", "2026-11-01T05:30:00+00:00"),
    (NEW_YORK, "30 1 * * *", 1, "2026-11-01T06:30:00+00:00", None),  # the second (EST) starts nothing
    # Monday 09:00 EST
    (NEW_YORK, "0 9 * * 1-5", 8, "2026-11-02T14:00:00+00:00", "2026-11-02T14:00:00+00:00"),
    (NEW_YORK, "0 9 * * 1-5", 8, "2026-11-01T14:00:00+00:00", None),  # Sunday
])
def test_a_window_opens_at_its_local_time_across_daylight_saving_changes(zone, cron, hours, now, open_since):
    window = _window(cron, timedelta(hours=hours), zone)
    found = policy.open_since(window, datetime.fromisoformat(now).astimezone(UTC))
    assert (None if found is None else found.isoformat()) == open_since


def test_deny_wins_over_allow_and_outside_every_allow_window_refuses():
    allow = _window("0 6 * * *", timedelta(hours=12), BERLIN, "allow")
    deny = policy.Window("freeze", "hard", "deny", policy.parse_cron("0 12 * * *"), timedelta(hours=1),
                         ZoneInfo(BERLIN), ("booth-*",),
                         ("windows", 1))
    rules = policy.Policy((), (allow, deny))
    noon = datetime(2026, 11, 30, 11, 30, tzinfo=UTC)  # 12:30 in Berlin: both open
    assert [(f.rule, f.level) for f in policy.findings([], ["booth-a"], rules, noon)] == [("freeze", "hard")]
    assert policy.findings([], ["cell-1"], rules, noon) == []  # the freeze covers booth-* only
    night = datetime(2026, 11, 30, 22, tzinfo=UTC)
    assert [f.message for f in policy.findings([], ["cell-1"], rules, night)] == ["bus cell-1: outside "
                                                                                  "every allow window ('w')"]


@pytest.mark.parametrize(("text", "why"), [
    ("* * * *", "5 fields"), ("60 * * * *", "0..59"), ("* * * * 8", "0..7"), ("5-1 * * * *", "ranges"),
    ("*/0 * * * *", "steps"), ("a * * * *", "not *"), ("5/2 * * * *", "steps"),
])
def test_a_cron_expression_outside_five_numeric_fields_is_refused(text, why):
    with pytest.raises(ValueError, match=re.escape(why)):
        policy.parse_cron(text)


def test_cron_days_match_either_day_field_when_both_are_given():
    cron = policy.parse_cron("0 0 13 * 5")  # the 13th, and every Friday
    assert cron.day_matches(datetime(2026, 11, 13).date()) and cron.day_matches(datetime(2026, 11, 6).date())
    assert not cron.day_matches(datetime(2026, 11, 7).date())
    assert policy.parse_cron("0 0 * * 7").day_matches(datetime(2026, 11, 29).date())  # 7 is Sunday too


def test_the_policy_schema_in_schemas_is_the_one_the_models_make():
    assert (SCHEMAS / "policy.schema.json").read_text(encoding="utf-8") == policy_schema_text()
    schema = json.loads(policy_schema_text())
    jsonschema.validate({"format": "prc3cfg-policy/1",
                         "windows": [{"name": "w", "kind": "deny", "cron": "0 6 * * *",
                                                                    "duration": "1h",
                                      "time_zone": "Europe/Berlin"}]}, schema)
    with pytest.raises(jsonschema.ValidationError):  # the check can fail
        jsonschema.validate({"format": "prc3cfg-policy/1",
                             "envelopes": [{"name": "e", "limits": {"sped": {"max": 1}}}]}, schema)


# -- windows against a brute force: every UTC minute of the days around, each checked on its own
# ---------------------------

ZONES = ("Europe/Berlin", "America/New_York", "Australia/Sydney", "Australia/Lord_Howe", "Asia/Kathmandu",
         "Pacific/Chatham", "UTC")


@st.composite
def windows_and_instants(draw):
    """A window (its cron's sets kept apart, for the oracle), and an instant: anywhere in 2026, or within two
    days of one of its zone's changes of offset."""
    zone = draw(st.sampled_from(ZONES))
    minutes = draw(st.sets(st.integers(0, 59), min_size=1, max_size=3))
    hours = draw(st.sets(st.integers(0, 23), min_size=1, max_size=3))
    days = draw(st.one_of(st.none(), st.sets(st.integers(1, 31), min_size=1, max_size=3)))
    weekdays = draw(st.one_of(st.none(), st.sets(st.integers(0, 6), min_size=1, max_size=3)))
    text = " ".join([",".join(map(str, sorted(minutes))), ",".join(map(str, sorted(hours))),
                     "*" if days is None else ",".join(map(str, sorted(days))), "*",
                     "*" if weekdays is None else ",".join(map(str, sorted(weekdays)))])
    duration = timedelta(minutes=draw(st.integers(1, 12 * 60)))
    changes = _changes(ZoneInfo(zone))
    base = draw(st.sampled_from(changes)) if changes and draw(st.booleans()) else datetime(2026, 1, 1,
                                                                                           tzinfo=UTC)
    now = base + timedelta(seconds=draw(st.integers(-2 * 86400,
                                                    2 * 86400 if base.month > 1 else 365 * 86400)))
    return _window(text, duration, zone), (minutes, hours, days, weekdays), now


@functools.cache
def _changes(zone: ZoneInfo) -> list[datetime]:
    """The instants in 2026 at which `zone` changes its offset, to the hour."""
    hours = [datetime(2026, 1, 1, tzinfo=UTC) + timedelta(hours=h) for h in range(365 * 24)]
    return [b for a, b in itertools.pairwise(hours)
            if a.astimezone(zone).utcoffset() != b.astimezone(zone).utcoffset()]


def _brute_force(window: policy.Window, sets, now: datetime) -> datetime | None:
    """The latest start in (now − duration, now]: every UTC minute u there, and every wall time W that some
    offset of the zone around it gives, W a start at u when the cron's sets take W and W read in the zone
    (first of two) is u."""
    minutes, hours, days, weekdays = sets
    zone = window.time_zone
    offsets = {(now + timedelta(hours=h)).astimezone(zone).utcoffset() for h in range(-72, 73)}
    minute = now.replace(second=0, microsecond=0)
    found = None
    while minute > now - window.duration:
        for offset in offsets:
            wall = (minute + offset).replace(tzinfo=None)  # type: ignore[operator]
            in_days = days is not None and wall.day in days
            in_weekdays = weekdays is not None and wall.isoweekday() % 7 in weekdays
            day = ((in_days or in_weekdays) if days is not None and weekdays is not None
                   else (days is None or in_days) and (weekdays is None or in_weekdays))
            if (wall.minute in minutes and wall.hour in hours and day
                and wall.replace(tzinfo=zone, fold=0).astimezone(UTC) == minute):
                found = max(found or minute, minute)
        minute -= timedelta(minutes=1)
    return found


@settings(max_examples=15)
@given(windows_and_instants())
def test_a_window_is_open_exactly_when_a_brute_force_over_utc_minutes_says(case):
    window, sets, now = case
    assert policy.open_since(window, now) == _brute_force(window, sets, now)


@pytest.mark.soak
@given(windows_and_instants())
def test_a_window_is_open_exactly_when_a_brute_force_over_utc_minutes_says_soak(case):
    window, sets, now = case
    assert policy.open_since(window, now) == _brute_force(window, sets, now)


def test_a_value_the_plant_file_leaves_to_the_factory_is_said_at_its_module(tmp_path, source):
    from prc3cfg import api

    (tmp_path / "rules.yaml").write_text("format: prc3cfg-policy/1\nenvelopes:\n"
                                         "  - {name: sync, level: advisory, modules: [booth-b-left], "
                                         "limits: {sync_conveyor_sequence: {min: 1}}}\n")
    report = api.policy(api.load(source), now=datetime(2026, 11, 29, tzinfo=UTC))
    assert report is not None and report.clock == "given"
    ((finding, line),) = report.findings
    assert (finding.kind, finding.level) == ("envelope", "advisory")
    at = int(re.match(r".*source\.yaml:(\d+):\d+: ", line).group(1))  # type: ignore[union-attr]
    assert ("name: booth-b-left" in source.read_text().splitlines()[at]
            and "sync_conveyor_sequence 0.010 m is below 1.000 m" in line)


def test_a_moment_that_is_not_an_instant_with_its_offset_is_refused_in_one_line(plant, capsys, monkeypatch):
    (plant.path.parent / "rules.yaml").write_text(SHIFT)
    monkeypatch.setenv("PRC3CFG_POLICY_NOW", "2026-11-30 09:00")
    result = run_cli(capsys, "apply", plant.path, "--auto-approve")
    assert result.code == 1 and _untouched(plant)
    assert result.err.strip().splitlines() == ["error: PRC3CFG_POLICY_NOW='2026-11-30 09:00' is not an ISO "
                                               "8601 instant with its offset (2026-03-30T09:00:00+02:00) — "
                                               "set it so, or unset it to use the clock"]


def test_a_restore_in_a_deny_window_is_refused_and_goes_on_with_an_override(plant, capsys, monkeypatch):
    (plant.path.parent / "rules.yaml").write_text(SHIFT)
    monkeypatch.setenv("PRC3CFG_POLICY_NOW", SUNDAY)
    assert run_cli(capsys, "apply", plant.path, "--auto-approve", "--allow-axis-release").code == 0
    applied = plant.images()
    (snapshot,) = (plant.path.parent / ".prc3cfg" / "snapshots").iterdir()
    monkeypatch.setenv("PRC3CFG_POLICY_NOW", MONDAY_MORNING)
    refused = run_cli(capsys, "restore", snapshot, "--auto-approve", "--allow-axis-release")
    assert (refused.code == 75 and "deny window 'production' is open" in refused.err
            and "--override-window REASON" in refused.err)
    assert plant.images() == applied
    restored = run_cli(capsys, "restore", snapshot, "--auto-approve", "--allow-axis-release",
                       "--override-window", "roll back the trial")
    assert restored.code == 0, restored.err
    assert plant.images() == FACTORY[id(plant)]
    assert _journal_header(plant)["policy"]["overridden"][0]["reason"] == "roll back the trial"


def test_validate_annotates_envelope_findings_and_policy_file_problems_for_a_pull_request(tmp_path, source,
                                                                                          capsys):
    rules = tmp_path / "rules.yaml"
    rules.write_text(SPEEDS.format(level="hard")
                     + "  - {name: dwell, level: advisory, limits: {dwell: {max: 0.2}}}\n"
                     + SHIFT.split("\n", 1)[1]
                     .replace('"0 6 * * 1-5"', '"* * * * *"'))  # open whenever: validate judges no moment
    annotated = run_cli(capsys, "validate", source, "--format", "github")
    assert annotated.code == 1
    kinds = {(line.split(" ", 1)[0], "hard" in line) for line in annotated.out.splitlines()}
    assert kinds == {("::error", True), ("::warning", False)} and "window" not in annotated.out
    at = rf"::error file={re.escape(str(source))},line=\d+,col=\d+,title=prc3cfg::"
    assert re.search(at + "hard: module booth-a-left: program 1 speed", annotated.out)
    problems = json.loads(run_cli(capsys, "validate", source, "--json").out)
    assert problems and all(p["message"].startswith("hard: ") for p in problems)
    rules.write_text("format: prc3cfg-policy/1\nenvelopes: 3\n")
    broken = run_cli(capsys, "validate", source, "--format", "github")
    assert (broken.code == 1
            and broken.out.startswith(f"::error file={rules},line=2,col=12,title=prc3cfg::'envelopes' is "
                                      "not valid"))


CHAINS = """format: prc3cfg-policy/1
envelopes:
  - {name: hood, level: hard, buses: [booth-a], limits: {stroke_length: {max: 1.800}}}
  - {name: takt, level: advisory, modules: [booth-b-pretreat], limits: {pass_time: {max: 13.0}}}
  - {name: guns, level: soft, modules: [booth-a-top], limits: {function_distance: {max: 0.050}}}
"""


def test_a_chains_stroke_length_and_pass_time_and_the_function_outputs_distances_are_bounded(tmp_path,
                                                                                             source):
    """What a chain's motion reaches is judged as the plan's stroke charts draw it: the left and top stroke
    1.950 m and 1.600 m; the pretreatment loop turns in 13.53 s; F1/F2 distances are every managed program's.
    """
    from prc3cfg import api

    (tmp_path / "rules.yaml").write_text(CHAINS)
    source.write_text(source.read_text().replace("1: {position: 1.750}",
                                                 "1: {position: 1.750, f1: {action: set, distance: 0.080}}"))
    report = api.policy(api.load(source), now=datetime(2026, 11, 29, tzinfo=UTC))
    assert report is not None
    rules = tmp_path / "rules.yaml"

    def rule(line: int) -> str:
        return f"(rule at {rules}:{line}:{rules.read_text().splitlines()[line - 1].index('{max') + 1})"

    said = sorted(line.split(": ", 1)[1] for _, line in report.findings)
    assert said == [
        (
            "advisory: module booth-b-pretreat: chain 1 → 2 → 1 pass_time 13.53 s is above 13.00 s, the"
            f" limit of envelope 'takt' {rule(4)}"
        ),
        (
            "hard: module booth-a-left: chain 1 → 2 → 1 stroke_length 1.950 m is above 1.800 m, the limit of "
            f"envelope 'hood' {rule(3)}"
        ),
        (
            "hard: module booth-a-right: chain 1 → 2 → 1 stroke_length 1.850 m is above 1.800 m, the limit"
            f" of envelope 'hood' {rule(3)}"
        ),
        (
            "soft: module booth-a-top: program 1 function_distance 0.080 m is above 0.050 m, the limit of "
            f"envelope 'guns' {rule(5)}"
        ),
    ]


def test_a_chain_outside_its_envelope_is_placed_at_its_first_program(tmp_path, source):
    from prc3cfg import api

    (tmp_path / "rules.yaml").write_text(CHAINS.replace("max: 1.800", "max: 0.500"))
    report = api.policy(api.load(source), now=datetime(2026, 11, 29, tzinfo=UTC))
    assert report is not None
    lines = source.read_text().splitlines()
    touch_up = next(line for _, line in report.findings
                    if "chain 3 → 10 → 11 → stop stroke_length 0.600 m" in line)
    at = int(re.match(r".*source\.yaml:(\d+):\d+: ", touch_up).group(1))  # type: ignore[union-attr]
    assert lines[at - 1].strip().startswith("3: {position: 1.100, next: 10}")


def test_an_apply_of_a_plan_file_is_judged_by_the_windows_of_the_lines_it_writes_only(plant, capsys,
                                                                                      monkeypatch):
    """A plan file for one line is not refused by another line's window: the apply writes that line only."""
    (plant.path.parent / "rules.yaml").write_text(SHIFT_ON_BOOTH_B)
    monkeypatch.setenv("PRC3CFG_POLICY_NOW", MONDAY_MORNING)
    saved = plant.path.parent / "booth-a.plan.json"
    planned = run_cli(capsys, "plan", plant.path, "--module", "booth-a-left", "--out", saved)
    assert planned.code == 0, planned.err
    applied = run_cli(capsys, "apply", "--plan", saved, "--auto-approve", "--allow-axis-release")
    assert applied.code == 0, applied.err
    assert "deny window" not in applied.err
    whole = run_cli(capsys, "apply", plant.path, "--auto-approve", "--allow-axis-release")
    # the other line's apply waits
    assert whole.code == 75 and "bus booth-b: deny window 'production' is open" in whole.err
