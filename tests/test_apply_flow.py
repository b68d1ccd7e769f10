"""The apply flows one way (issue 43, item 2): the lower layers (`prc3cfg.core`, `prc3cfg.shell`) never call
back into the API or the command line while an apply reads, plans, writes and verifies — the API's loop calls
the stages and shows what they give back between them; and the write stage takes the consent to release axes
as a value, refusing a 10h/20h to any module it does not name. The stages — read, plan, gate, write and
verify, record — are functions of values, which a test can drive one at a time.

The calls are counted on a real apply of the demo plant on emulators, every thread traced (`sys.setprofile`).
"""

from __future__ import annotations

import collections
import contextlib
import random
import sys
import threading
from collections.abc import Callable, Iterator
from pathlib import Path

import pytest
from emulated import emulated_plant, run_cli
from hypothesis import given, settings
from hypothesis import strategies as st
from lossy import Loss

import prc3cfg
from prc3cfg import api
from prc3cfg.api._apply import gate
from prc3cfg.api._plan import select, shared_planner, targets
from prc3cfg.core.stages import Consent, LinePlan, ReadBack
from prc3cfg.shell import audit, pending_records
from prc3cfg.shell.cancel import Cancellation
from prc3cfg.shell.engine import Keeping, NotConsented, Writing
from prc3cfg.shell.planning import line_plan, read_lines
from prc3cfg.shell.records import Journal
from prc3cfg.shell.records import header as run_header
from prc3cfg.shell.sessions import LineOptions, bus_line_keys, lines

PACKAGE = Path(prc3cfg.__file__).resolve().parent
LOWER, HIGHER = {"core", "shell"}, {"api", "cli"}
#: Ports the shell declares and a higher layer implements — the progress display
#: (`prc3cfg.shell.phases.Progress`): the one kind of call up that stays (the display is told as the lines'
#: threads work; issue 43 item 2 leaves it)
PORTS = {"start", "advance", "note"}


def _layer(filename: str) -> str | None:
    try:
        parts = Path(filename).resolve().relative_to(PACKAGE).parts
    except ValueError:
        return None
    return parts[0] if len(parts) > 1 else None


def calls_up(*args: str, capsys: pytest.CaptureFixture) -> tuple[int, collections.Counter[str]]:
    """`prc3cfg ARGS` run in this process with every thread traced: its exit code, and each call a function of
    `core/` or `shell/` made into `api/` or `cli/` (but a progress display's), by caller → callee."""
    up: collections.Counter[str] = collections.Counter()
    layers: dict[str, str | None] = {}

    def profile(frame, event, _arg) -> None:
        if event != "call" or frame.f_back is None:
            return
        callee, caller = frame.f_code, frame.f_back.f_code
        for code in (callee, caller):
            if code.co_filename not in layers:
                layers[code.co_filename] = _layer(code.co_filename)
        if (layers[caller.co_filename] in LOWER and layers[callee.co_filename] in HIGHER
            and callee.co_name not in PORTS):
            up[f"{caller.co_qualname} → {callee.co_qualname}"] += 1

    threading.setprofile(profile)
    sys.setprofile(profile)
    try:
        code = run_cli(capsys, *args).code
    finally:
        sys.setprofile(None)
        threading.setprofile(None)
    return code, up


def test_an_auto_approved_apply_never_calls_up_a_layer(tmp_path, capsys):
    """`apply --auto-approve --allow-axis-release` (each line written as soon as its plan is whole, the lines'
    threads at work at once): no call from the shell or the core into the API or the CLI — the planner, the
    line's record, the plan's `reading`, the plans shown (each line's and the plant's) are all the API loop's.
    """
    with emulated_plant(tmp_path) as emulated:
        code, up = calls_up("apply", emulated.path, "--auto-approve", "--allow-axis-release", capsys=capsys)
        assert code == 0 and emulated.matches_plant()
    assert up == {}, "\n".join(f"{n} × {call}" for call, n in up.most_common())


def test_a_reviewed_apply_never_calls_up_a_layer(tmp_path, capsys):
    """With the plant's plan reviewed first (`--json`: the questions answered on the command line, each an
    event)."""
    with emulated_plant(tmp_path) as emulated:
        code, up = calls_up("apply", emulated.path, "--auto-approve", "--json", capsys=capsys)
        # the demo plant releases axes: refused, nothing written
        assert code != 0 and not emulated.matches_plant()
    assert up == {}, "\n".join(f"{n} × {call}" for call, n in up.most_common())


@contextlib.contextmanager
def _writing(plant) -> Iterator[Writing]:
    """The write stage's `Writing` on the plant's lines, held and journalled as an apply holds them."""
    buses = {bus.name: bus for bus, _ in select(plant, None)}
    keys = {name: bus_line_keys(plant, bus) for name, bus in buses.items()}
    journal = Journal(plant.path, run_header("apply", plant.path, plant.name, plant.sha256, reason=None),
                      audit.follow(plant.path))
    options = LineOptions(cancel=Cancellation())
    assert options.cancel is not None
    keeping = Keeping(plant, buses, keys, journal, pending_records.Releases("apply", journal.path),
                      options.cancel.event)
    try:
        with lines(plant, buses, options, purpose="apply", observer=keeping.observe,
                   announce=keeping.announce, records=keeping,
                   identities=keys) as held:
            yield Writing(plant, keys, buses, held, keeping, api.Verify.FLOOR, options, "apply")
    finally:
        keeping.close()


def _write_stage(emulated, consent: frozenset[tuple[str, int]]) -> str:
    """The write stage run on the demo plant's plan (fresh modules: every one released) with `consent`: what
    it refused, in one line — nothing, when every module it releases is consented."""
    the_plan = api.plan(emulated.plant)
    images = {(c.bus, c.address): c.actual for c in the_plan.modules}
    with _writing(emulated.plant) as writing:
        try:
            writing.write(LinePlan(the_plan.modules, images), Consent(consent))
        except NotConsented as refused:
            return str(refused)
        return ""


def test_the_write_stage_refuses_an_axis_release_without_consent(tmp_path):
    """Consent is per module and a value: a plan that releases a module's axes the consent does not name is
    refused whole — one line naming it, nothing sent to any module; consented, it is written."""
    with emulated_plant(tmp_path) as emulated:
        before = emulated.images()
        releasing = sorted((c.bus, c.address) for c in api.plan(emulated.plant).axis_releases)
        assert len(releasing) > 1
        said = _write_stage(emulated, frozenset(releasing[1:]))
        bus, address = releasing[0]
        assert (said.startswith(f"bus {bus}, module {address} (") and "10h/20h" in said
                and "nothing was sent" in said)
        assert "\n" not in said
        assert emulated.images() == before
        assert _write_stage(emulated, frozenset(releasing)) == ""
        assert emulated.matches_plant()


@pytest.mark.soak
@settings(max_examples=12)
@given(st.data())
def test_any_consent_short_of_every_release_sends_nothing(data):
    """Seeded (the profile's derandomised examples): any subset of the releasing modules short of all of them
    — a module left out anywhere in the plan — is refused before a frame, naming every one left out."""
    import tempfile

    with tempfile.TemporaryDirectory() as directory, emulated_plant(Path(directory)) as emulated:
        before = emulated.images()
        releasing = sorted((c.bus, c.address) for c in api.plan(emulated.plant).axis_releases)
        consent = data.draw(st.sets(st.sampled_from(releasing), max_size=len(releasing) - 1))
        said = _write_stage(emulated, frozenset(consent))
        assert all((f"bus {bus}, module {address} (" in said) == ((bus, address) not in consent)
                   for bus, address in releasing)
        assert emulated.images() == before


def test_each_line_s_plan_is_shown_by_the_caller_s_thread_before_that_line_writes(tmp_path):
    """Without a question (`Gates.asks`), `show_line` and `show` run in the thread that called `api.apply` —
    between the stages, never from a line's thread — and a line's modules hold what they held until its plan
    was shown."""
    with emulated_plant(tmp_path) as emulated:
        before, shown, whole = emulated.images(), [], []

        def show_line(line_plan) -> None:
            assert threading.current_thread() is threading.main_thread()
            shown.extend(line_plan.buses())
            assert all(emulated.images()[key] == before[key] for key in before if key[0] in line_plan.buses())

        def show(the_plan) -> None:
            assert threading.current_thread() is threading.main_thread()
            whole.append(the_plan)

        gates = api.Gates(show=show, show_line=show_line, allow_axis_release=True)
        result = api.apply(emulated.plant, gates=gates)
        assert result.verified and emulated.matches_plant()
        assert sorted(shown) == sorted(bus.name for bus in emulated.plant.buses)
        # nothing to write: no line's plan, the plant's on the lines' records
        again = api.apply(emulated.plant, gates=gates)
    assert (len(whole) == 2 and whole[0].modules == result.plan.modules
            and whole[1].modules == again.plan.modules)
    # what it read, worked out by the API
    assert whole[1].reading is not None and whole[1].reading == again.plan.reading


def test_the_stages_driven_one_at_a_time(tmp_path):
    """Read, plan, gate, write and verify, record — each a function of values, driven here one after another
    on the emulated demo plant: the gate refusing the release (an answer, a value) writes nothing; the consent
    it gives then writes and verifies the line, and records what its modules now hold."""
    with emulated_plant(tmp_path) as emulated, _writing(emulated.plant) as writing:
        plant, before = emulated.plant, emulated.images()
        pairs = select(plant, None)
        planner = shared_planner(plant, pairs, writing.held.on_record)
        read_backs: list[ReadBack] = []
        # read
        images = read_lines(targets(pairs), writing.links, writing.held.on_record, "test", planner,
                            then=read_backs.append)
        bus = plant.buses[0].name
        read_back = next(read for read in read_backs if read.bus == bus)
        assert read_back.images == {key: image for key, image in images.items() if key[0] == bus}
        line = line_plan(planner, read_back, writing.links[bus])  # plan: the line's changes, frozen
        assert {c.bus for c in line.changes} == {bus} and line.releasing
        with pytest.raises(api.AxisReleaseRefused, match="nothing was written"):
            gate(planner.plan(images, (bus,)), api.Gates(allow_axis_release=lambda _: False), "apply")
        assert emulated.images() == before
        consent = gate(planner.plan(images, (bus,)), api.Gates(allow_axis_release=lambda _: True), "apply")
        assert consent.releases == line.releasing
        writing.write(line, consent)  # write and verify, then record
        outcomes = writing.account(planner.plan(images, (bus,))).runs
        assert outcomes and all(run.verified for run in outcomes)
        assert all(emulated.images()[key] != before[key] for key in line.releasing)
        assert all(image == before[key] for key, image in emulated.images().items() if key[0] != bus)
        known = writing.records[bus].known()
        assert all(run.address in known for run in outcomes)


#: The answers a gate may be given about an axis release: up front, or asked with the modules named.
ANSWERS: dict[str, bool | Callable[[list[str]], bool]] = {
    "allowed": True, "refused": False, "asked, yes": lambda _: True, "asked, no": lambda _: False,
}
READS = (0x50, 0x51, 0x52)  # the read-backs' messages
FAST = (1, 2)  # seeds of the fast tier — a refusal, a write line by line; the others are soak


@pytest.mark.parametrize("seed", [seed if seed in FAST else pytest.param(seed, marks=pytest.mark.soak)
                                  for seed in range(16)])
def test_either_path_gates_before_it_writes_and_records_what_verified(tmp_path, seed):
    """Seeded: the gate answered any way — the release allowed up front (each line gated and written as soon
    as its plan is whole) or refused or asked (the whole plan gated first), the plan approved, refused or not
    asked — on the emulated demo plant, replies on booth-a lost now and then, and a module taught in by the
    floor between its writes and its verification (a repair round writes it again). Either path: a refusal
    writes nothing; a consent writes, verifies and repairs every module, and records it (the next plan is
    empty)."""
    chooser = random.Random(seed)
    allow, approve = chooser.choice(sorted(ANSWERS)), chooser.choice([None, True, False])
    armed, written = False, set()

    def lossy(frame, _number) -> set[Loss]:
        """A reply lost now and then; and once, the floor teaches a module in between its writes and its
        verification."""
        if not armed or not frame.address:
            return set()
        if frame.message[0] not in READS:
            written.add(frame.address)
        elif frame.address in written and not taught and chooser.random() < 0.5:
            taught.append(frame.address)
            emulated.emulators["booth-a"].teach_in(frame.address, 1, chooser.randint(100, 1800))
        return {Loss.REPLY} if chooser.random() < 0.05 else set()

    with emulated_plant(tmp_path, lossy={"booth-a": lossy}) as emulated:
        before, lines_shown, taught = emulated.images(), [], []
        gates = api.Gates(allow_axis_release=ANSWERS[allow], approve=None if approve is None
                          else lambda _: approve,
                          show_line=lambda line: lines_shown.extend(line.buses()))
        consented = allow in ("allowed", "asked, yes") and approve is not False
        armed = True
        try:
            result = api.apply(emulated.plant, gates=gates)
        except (api.AxisReleaseRefused, api.NotApproved) as refused:
            armed = False
            assert not consented and "nothing was written" in str(refused)
            assert emulated.images() == before and not lines_shown
            return
        armed = False
        assert consented and result.verified and emulated.matches_plant()
        # the path taken
        assert sorted(lines_shown) == ([] if gates.asks else sorted(bus.name for bus in emulated.plant.buses))
        # what verified is on the lines' records: nothing left to write
        assert not api.plan(emulated.plant).changes
        # write and verify: one stage, a repair in it
        assert sum(run.course.repairs for run in result.runs) == len(taught) == 1
