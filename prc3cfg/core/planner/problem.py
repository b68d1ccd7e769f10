"""What one module's plan must achieve, in the terms the search works in.

From the read-back and the desired image this derives, once per module: which programs
are managed, the system step (none, 10h or 20h), the *bases* — what a program holds
once the system step and any initialisation are done, before any write — and, per base,
the fields that still differ from the desired program (a bit mask). Every base is
obtained by running messages on the device model (`prc3cfg.core.device`): clamping and
defaults are predicted there, never re-implemented here.

Init kinds: KEEP (not initialised), INIT_AFTER (initialised after the system step, or
plainly initialised when there is none) and INIT_BEFORE (initialised before the system
step, so the module's clamping acts on the defaults of the old system parameters; offered
only when that gives something different). Programs are indexed 0..63 here.

Owns the validation that a desired image is reachable at all (`UnreachableImage`).
Does not own the search (`prc3cfg.core.planner.init_search`). Pure.
"""

from __future__ import annotations

from dataclasses import dataclass

from prc3cfg.core import codec, device
from prc3cfg.core.bustime import LineCost
from prc3cfg.core.image import (
    DEFAULT_SYSTEM,
    PROGRAM_COUNT,
    PROGRAM_FIELDS,
    ModuleImage,
    Program,
    default_program,
)
from prc3cfg.core.planner.module_plan import UnreachableImage
from prc3cfg.core.planner.pricing import Prices

KEEP, INIT_BEFORE, INIT_AFTER = 0, 1, 2

#: One bit per program field, in message order: P = 1, V = 2, … A = 64.
FIELD_BIT = {name: 1 << k for k, name in enumerate(PROGRAM_FIELDS)}
P_BIT, V_BIT, A_BIT = FIELD_BIT["P"], FIELD_BIT["V"], FIELD_BIT["A"]
PV_BITS = P_BIT | V_BIT
#: Fields that only a 21h or their own 40h..45h message can write.
PLAIN_FIELDS = ("Vr", "T", "F1", "F2")


def diff_mask(have: Program, want: Program) -> int:
    """The fields in which two programs differ, as FIELD_BITs (written out: a plan computes 46,000)."""
    return ((have.P != want.P) | (have.V != want.V) << 1 | (have.Vr != want.Vr) << 2 | (have.T != want.T) << 3
            | (have.F1 != want.F1) << 4 | (have.F2 != want.F2) << 5 | (have.A != want.A) << 6)


def system_step(actual: ModuleImage, desired: ModuleImage) -> codec.Message | None:
    """None when the system parameters agree; 10h when the factory defaults are wanted (cheaper); else 20h."""
    if desired.system == actual.system:
        return None
    if desired.system == DEFAULT_SYSTEM:
        return codec.InitSystem()
    try:
        return codec.WriteSystem(desired.system)
    except codec.MessageError as error:
        raise UnreachableImage(f"module {desired.address}: system parameters: {error}") from None


def _run(state: device.ModuleState, message: codec.Message | None) -> device.ModuleState:
    return state if message is None else device.execute(state, message)


@dataclass(frozen=True, slots=True)
class PlanningProblem:
    """One module: where it starts, where it must go, and the bases the search chooses from."""

    address: int
    actual: ModuleImage
    desired: ModuleImage
    start: device.ModuleState  # the read-back; programs not read are filled in (never touched)
    managed: tuple[bool, ...]
    system_step: codec.Message | None
    kinds: tuple[int, ...]  # the init kinds on offer, KEEP first
    bases: dict[int, tuple[Program, ...]]
    masks: dict[int, tuple[int, ...]]  # 0 for unmanaged programs
    target_a: tuple[int, ...]  # the desired jump addresses, 0 for unmanaged programs
    prices: Prices

    @classmethod
    def build(cls, actual: ModuleImage, desired: ModuleImage, cost: LineCost) -> PlanningProblem:
        if actual.address != desired.address:
            raise ValueError(f"read-back of module {actual.address} planned against module {desired.address}")
        managed = tuple(p is not None for p in desired.programs)
        for number, (have, want) in enumerate(zip(actual.programs, desired.programs), start=1):
            if want is not None and have is None:
                raise ValueError(f"module {desired.address}: program {number} is managed but was not read")
        _check_reachable(desired)
        filler = default_program(actual.system)
        start = device.ModuleState(
            ModuleImage(actual.address, actual.system,
                        tuple(filler if p is None else p for p in actual.programs))
        )
        step = system_step(actual, desired)
        try:
            after_system = _run(start, step)
        except codec.Rejected as rejected:
            raise UnreachableImage(f"module {desired.address}: the module rejects these system parameters "
                                   f"with code {rejected.code}") from None
        init_all = codec.InitAllPrograms()
        bases = {
            KEEP: after_system.image.complete(),
            INIT_AFTER: device.execute(after_system, init_all).image.complete(),
        }
        kinds = [KEEP, INIT_AFTER]
        before = _run(device.execute(start, init_all), step).image.complete()
        if before != bases[INIT_AFTER]:
            bases[INIT_BEFORE] = before
            kinds.insert(1, INIT_BEFORE)
        wanted = desired.programs
        masks = {
            kind: tuple(0 if w is None else diff_mask(b, w) for b, w in zip(base, wanted))
            for kind, base in bases.items()
        }
        return cls(
            address=desired.address,
            actual=actual,
            desired=desired,
            start=start,
            managed=managed,
            system_step=step,
            kinds=tuple(kinds),
            bases=bases,
            masks=masks,
            target_a=tuple(0 if w is None else w.A for w in wanted),
            prices=Prices.measure(cost, desired.address),
        )

    @property
    def system_cost(self) -> float:
        return 0.0 if self.system_step is None else self.prices.message(len(self.system_step.encode()))

    def init_useful(self) -> bool:
        """Whether initialising any program could leave it with fewer differences than keeping it."""
        keep = self.masks[KEEP]
        return any(keep[i] & ~self.masks[k][i] for k in self.kinds[1:] for i in range(PROGRAM_COUNT))


def _check_reachable(desired: ModuleImage) -> None:
    """Every managed desired value must be one the module accepts under the desired system parameters."""
    ranges = [device.value_range(name, desired.system)[:2] for name in PROGRAM_FIELDS]
    for number, program in enumerate(desired.programs, start=1):
        if program is None:
            continue
        for name, (low, high), value in zip(PROGRAM_FIELDS, ranges, program.values()):
            if not low <= value <= high:
                raise UnreachableImage(
                    f"module {desired.address}: program {number}: {name} = {value} is outside "
                    f"{low}..{high}, which the module accepts with these system parameters"
                )
