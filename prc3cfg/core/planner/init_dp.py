"""The init DP: which programs to initialise first (11h..14h, before or after the system step), over
program numbers, each program charged what its remaining differences would cost (`charges`).

Runs of initialised programs cost one message each and never cover an unmanaged program.

Owns the DP and what init messages cost. Does not own the charges (`charges`) or which init choices
are searched (`init_search`).
"""

from __future__ import annotations

from collections.abc import Sequence

from prc3cfg.core.image import PROGRAM_COUNT
from prc3cfg.core.planner.layout import init_runs
from prc3cfg.core.planner.problem import KEEP, PlanningProblem
from prc3cfg.core.planner.terms import INF, Kinds, Table

#: A bias far below any price (seconds): ties between keeping and initialising go to initialising.
TIE = 1e-9


def init_cost(problem: PlanningProblem, kinds: Kinds) -> float:
    """What the init messages of `kinds` cost: one 14h per run, a 12h/13h/11h for one program or a run to
    64."""
    prices = problem.prices
    total = 0.0
    for kind in problem.kinds[1:]:
        for first, last in init_runs(kinds, kind):
            total += prices.init if first == last or last == PROGRAM_COUNT - 1 else prices.init_range
    return total


def choose_inits(problem: PlanningProblem, charges: Table) -> Kinds:
    """The init kind of every program minimising init messages + `charges[i][n]` (n: the kind's
    place in `problem.kinds`, KEEP first).

    A run of programs of one kind costs one 14h, or a 12h/13h/11h when it is one program
    or ends at 64. Unmanaged programs are always KEEP, so no run covers them. States: 0, kept;
    for the n-th init kind, 2n - 1 after the first program of its run and 2n further on. A run
    begins from the cheapest state of another kind once closed (a run of one refunded: a 12h,
    not a 14h); on a tie the lowest state. With one init kind (the system step leaves the
    defaults as they were), the DP is `_one_kind`'s.
    """
    prices = problem.prices
    refund, init_range = prices.init_range - prices.init, prices.init_range
    inits = problem.kinds[1:]
    count = len(inits)
    if all(_best_run(problem.managed, charges, n) < prices.init - TIE for n in range(1, count + 1)):
        return (KEEP,) * PROGRAM_COUNT  # no run of any kind saves what its message costs
    if count == 1:
        back, cost = _one_kind(problem.managed, charges, refund, init_range)
    else:
        back, cost = _kinds(problem.managed, charges, count, refund, init_range)
    state = min(range(len(cost)), key=lambda s: cost[s] - (refund if s else 0.0))
    kinds = [KEEP] * PROGRAM_COUNT
    for i in range(PROGRAM_COUNT - 1, -1, -1):
        kinds[i] = inits[(state - 1) // 2] if state else KEEP
        state = back[i][state]
    return tuple(kinds)


def _kinds(managed: tuple[bool, ...], charges: Table, count: int, refund: float,
           init_range: float) -> tuple[list[Sequence[int]], list[float]]:
    """`choose_inits`' DP: per program the state each state came from, and the cost of each state after the
    last."""
    # per init kind: its run's first state, further on
    ends = [(2 * n - 1, 2 * n) for n in range(1, count + 1)]
    no_cost, no_step = [INF] * (2 * count), [0] * (2 * count)
    cost = [0.0, *no_cost]
    back: list[Sequence[int]] = []
    for i, row in enumerate(charges):
        # per kind (KEEP: state 0), its cheapest state closed here; the cheapest of all, and the next
        closed = [(cost[0], 0)]
        for first, further in ends:
            one, more = cost[first] - refund, cost[further]
            closed.append((one, first) if one <= more else (more, further))
        best, *others = sorted(closed)
        new, step = [best[0] + row[0], *no_cost], [best[1], *no_step]
        if managed[i]:
            for n, (first, further) in enumerate(ends, start=1):
                value = row[n]
                c, state = best if best is not closed[n] else others[0]
                new[first], step[first] = c + init_range + value, state
                one, more = cost[first], cost[further]
                new[further], step[further] = (one + value, first) if one <= more else (more + value, further)
        cost = new
        back.append(step)
    return back, cost


def _one_kind(managed: tuple[bool, ...], charges: Table, refund: float,
              init_range: float) -> tuple[list[Sequence[int]], list[float]]:
    """`_kinds` with one init kind, the same sums in the same order: a run of it can only begin from a kept
    program (state 0), and the cheapest closed state is kept or the kind's. Earns 5 % of planning CPU (the 352
    plans of plan_bench's scenarios and plants: 3.19 s, 3.36 s by `_kinds`)."""
    keep, first, further = 0.0, INF, INF
    back: list[Sequence[int]] = []
    for i, (kept, initialised) in enumerate(charges):
        one = first - refund
        closed, came = (one, 1) if one <= further else (further, 2)
        if keep <= closed:
            closed, came = keep, 0
        if managed[i]:
            step = (came, 0, 1) if first <= further else (came, 0, 2)
            keep, first, further = (closed + kept, keep + init_range + initialised,
                                    (first if first <= further else further) + initialised)
        else:
            step = (came, 0, 0)
            keep, first, further = closed + kept, INF, INF
        back.append(step)
    return back, [keep, first, further]


def _best_run(managed: tuple[bool, ...], charges: Table, n: int) -> float:
    """The most a run of the n-th kind could save on `charges` (the maximum subarray, over managed
    programs)."""
    best = run = 0.0
    for i, row in enumerate(charges):
        run = run + row[0] - row[n] if managed[i] else 0.0
        if run < 0.0:
            run = 0.0
        elif run > best:
            best = run
    return best

