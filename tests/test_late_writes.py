"""No write lands unseen (issue 40, item 1): a frame a gateway holds past the reply's time-out, or
delivers twice, reaches the module after frames sent after it. Across the real link client and a
real emulator, a `LossyProxy` between them holding the frame (`Loss.LATE`: the client's retry goes
first) or a copy of it (`Loss.DUPLICATE`) until a later request of the client's or the proxy's
`hold` — shorter than the line's quiet period, as a bound the link states must be — and finally
`flush()`: every frame held is delivered before the result is judged. On every framing the result
is never a silent wrong value: an apply that says "verified" left the module as the plant file
says, and a plan after any apply never says "No changes" while a module differs.
"""

from __future__ import annotations

import contextlib
import random
from collections.abc import Iterator
from pathlib import Path

import pytest
from emulated import run_cli
from lossy import Loss, LossyProxy, Rule, Until

from prc3cfg.core.framing import Frame
from prc3cfg.shell.testing import EmulatedPlant, emulate

#: m1's programs 1–3 as first applied; then the plant file drops their dwell and relative speed: the
#: plan initialises programs 1–3 (14h) and writes their positions and speeds (33h) — the issue's apply.
SOURCE = """plant: late
buses:
  - name: line
    port: emulator://late
    modules:
      - address: 1
        name: m1
        programs:
          1: {position: 0.35, speed: 0.3, dwell: 0.5, relative_speed: 0.03}
          2: {position: 0.15, speed: 0.3, dwell: 0.5, relative_speed: 0.03}
          3: {position: 0.25, speed: 0.3, dwell: 0.5, relative_speed: 0.03}
      - address: 2
        name: m2
        programs:
          1: {position: 0.2, speed: 0.3, dwell: 0.5}
"""
#: framing and bus settings: the checksummed framings, and open-driver with parity
FRAMINGS = {
    "crc16": {"framing": "crc16"},
    "stx": {"framing": "stx"},
    "open-driver": {"framing": "open-driver", "parity": "even", "zvz": 0.008},
}
TIMEOUT = 0.2  # s: the bus's reply time-out
# s: past the time-out (the client retries a LATE frame first), within the quiet period (2 × 0.2 s and more)
HOLD = 0.3
READS = (0x50, 0x51, 0x52)


@contextlib.contextmanager
def proxied(directory: Path, settings: dict, rule: Rule, until: Until,
            hold: float = HOLD) -> Iterator[tuple[EmulatedPlant, LossyProxy]]:
    """`SOURCE` on an emulator reached through a `LossyProxy` with `rule`, `until` and `hold`."""
    source = directory / "source.yaml"
    source.write_text(SOURCE)
    proxies: list[LossyProxy] = []
    with contextlib.ExitStack() as stack:

        def route(bus: str, host: str, port: int) -> str:
            proxy = LossyProxy((host, port), rule, framing=settings["framing"],
                               zvz=settings.get("zvz", 0.020), hold=hold, until=until)
            proxies.append(stack.enter_context(proxy))
            return proxy.listen()

        plant = stack.enter_context(emulate(source, directory, route=route, timeout=TIMEOUT, **settings))
        yield plant, proxies[0]


def simplified(plant: EmulatedPlant) -> None:
    """m1's programs 1–3 lose their dwell and relative speed in the plant file (14h, then 33h), m2's program 1
    its dwell."""
    text = plant.path.read_text()
    edited = text.replace("        dwell: 0.5\n        relative_speed: 0.03\n",
                          "").replace("        dwell: 0.5\n", "")
    assert edited != text
    plant.path.write_text(edited)


def writes_to(address: int, message_id: int | None, loss: Loss, times: int = 1) -> Rule:
    """A rule: `loss` for the first `times` requests with this message ID to `address`, once armed
    (`rule.armed`)."""
    seen = 0

    def rule(frame: Frame, _: int) -> set[Loss]:
        nonlocal seen
        if (getattr(rule, "armed", False) and frame.address == address
            and (message_id is None or frame.message[0] == message_id) and seen < times):
            seen += 1
            return {loss}
        return set()

    return rule


def after_read_of(address: int, rule: Rule) -> Until:
    """Deliver the held frames before the first request after a read of `address` that followed a write to
    it since `rule` was armed: after that module's verification read the values — the latest a late frame
    can do harm unseen."""
    state = {"wrote": False, "read": False}

    def until(frame: Frame, _: int) -> bool:
        if not getattr(rule, "armed", False):
            return False
        due, ours = state["read"], frame.address == address
        state["read"] |= ours and state["wrote"] and frame.message[0] in READS
        state["wrote"] |= ours and frame.message[0] not in READS
        return due

    return until


def assert_no_silent_wrong_value(plant: EmulatedPlant, proxy: LossyProxy, applied, capsys) -> None:
    """Every frame held delivered; then an apply that exited 0 left every module as the plant file says,
    and a plan never says "No changes" while a module differs."""
    proxy.flush()
    matches = plant.matches_plant()
    if applied.code == 0:
        assert matches, f"the apply said verified, the modules differ:\n{applied.out}{applied.err}"
    planned = run_cli(capsys, "plan", plant.path)
    if not matches:
        assert "No changes" not in planned.out, planned.out


@pytest.mark.parametrize("loss", [Loss.LATE, Loss.DUPLICATE])
@pytest.mark.parametrize("framing", FRAMINGS)
def test_an_initialisation_delivered_late_is_caught_before_the_verification(tmp_path, capsys, framing, loss):
    """The issue's apply: m1's 14h (programs 1–3 to defaults) is held past the time-out (LATE: the retry is
    acknowledged first) or delivered twice (DUPLICATE); the held frame reaches the module after the
    33h, at the latest once m1's verification read its programs. The verification waits the line's quiet
    period first, so the 14h lands before it: the read-back shows the reset, a repair writes it again."""
    rule = writes_to(1, 0x14, loss)
    with proxied(tmp_path, FRAMINGS[framing], rule, after_read_of(1, rule)) as (plant, proxy):
        assert run_cli(capsys, "apply", plant.path, "--auto-approve", "--allow-axis-release").code == 0
        simplified(plant)
        rule.armed = True  # type: ignore[attr-defined]
        applied = run_cli(capsys, "apply", plant.path, "--auto-approve", "--allow-axis-release")
        assert proxy.lost and proxy.lost[0][0] is loss, "the 14h was not held: the plan no longer initialises"
        assert proxy.holding == 0, ("the held 14h was still on its way after the apply: it was verified "
                                    "before it landed")
        assert applied.code == 0, applied.out + applied.err
        assert_no_silent_wrong_value(plant, proxy, applied, capsys)
        assert "No changes" in run_cli(capsys, "plan", plant.path).out


def test_a_plan_whose_late_copies_change_nothing_is_verified_without_waiting(tmp_path, capsys):
    """m2's change alone (its 32h writes a whole program): a copy of it, delivered whenever, leaves what the
    plan left — the verification follows the writes at once, and a duplicate delivered after it does no harm.
    """
    rule = writes_to(2, None, Loss.DUPLICATE)
    with proxied(tmp_path, FRAMINGS["crc16"], rule, lambda frame, n: False, hold=30.0) as (plant, proxy):
        assert run_cli(capsys, "apply", plant.path, "--auto-approve", "--allow-axis-release").code == 0
        plant.path.write_text(plant.path.read_text().replace("position: 0.2\n", "position: 0.22\n", 1))
        rule.armed = True  # type: ignore[attr-defined]
        applied = run_cli(capsys, "apply", plant.path, "--auto-approve", "--allow-axis-release")
        assert applied.code == 0, applied.out + applied.err
        assert proxy.holding == 1  # no quiet period waited for it: the copy is still held after the apply
        assert_no_silent_wrong_value(plant, proxy, applied, capsys)
        assert plant.matches_plant()


# -- the soak tier: seeded faults on any write of the apply, on every framing ---------------------


@pytest.mark.soak
@pytest.mark.parametrize("seed", range(24))
def test_late_and_duplicated_writes_never_leave_a_silent_wrong_value(tmp_path, capsys, seed):
    """A seeded framing, fault (LATE or DUPLICATE), write (any of the apply's, by its running number among
    the writes) and delivery (before the k-th later request, or at `hold`): never a silent wrong value."""
    draw = random.Random(seed)
    framing = draw.choice(list(FRAMINGS))
    loss = draw.choice([Loss.LATE, Loss.DUPLICATE])
    nth, k = draw.randint(1, 4), draw.randint(1, 8)
    writes, later = 0, {"after": None}

    def rule(frame: Frame, n: int) -> set[Loss]:
        nonlocal writes
        if not armed or frame.message[0] in READS:
            return set()
        writes += 1
        if writes == nth:
            later["after"] = n
            return {loss}
        return set()

    def until(frame: Frame, n: int) -> bool:
        return later["after"] is not None and n >= later["after"] + k

    armed = False
    with proxied(tmp_path, FRAMINGS[framing], rule, until,
                 hold=draw.uniform(TIMEOUT + 0.02, 2 * TIMEOUT)) as (plant, proxy):
        assert run_cli(capsys, "apply", plant.path, "--auto-approve", "--allow-axis-release").code == 0
        simplified(plant)
        armed = True
        applied = run_cli(capsys, "apply", plant.path, "--auto-approve", "--allow-axis-release")
        assert_no_silent_wrong_value(plant, proxy, applied, capsys)
