"""Program chains: the jump addresses A of a module's programs read as the chains a plant file writes.

A path of jumps that ends in A = 0 is a chain `[1, 2, 3]`, a cycle is a loop
`{"programs": [...], "loop": True}`, and every other jump is a `next:` on its program (a
program that two others continue with, a path running into a loop or into another chain).
Used wherever an image is shown as chains: plant files written from modules
(`prc3cfg.plant.importer`), plans (`render`) and the motion (`motion`). Pure.
"""

from __future__ import annotations

from typing import Any

from prc3cfg.core.image import Program


def jumps_as_chains(programs: dict[int, Program]) -> tuple[list[Any], dict[int, int]]:
    """(chains, next) that give exactly the programs' jump addresses A.

    Chains are written as a plant file writes them: `[1, 2, 3]`, `{"programs": [...], "loop": True}`.
    A jump to a program not in `programs` is always a `next`.
    """
    succ = {n: p.A for n, p in programs.items() if p.A}
    preds: dict[int, list[int]] = {}
    for n, a in sorted(succ.items()):
        preds.setdefault(a, []).append(n)
    # A jump can be a chain link only into a given program that no other program jumps to.
    link = {n: a for n, a in succ.items() if len(preds[a]) == 1 and a in programs}
    chains, placed = _plain_chains(programs, link, succ)
    chains += [{"programs": cycle, "loop": True} for cycle in _loops(link, placed)]
    nexts = {n: a for n, a in succ.items() if n not in placed}
    return chains, nexts


def _plain_chains(programs: dict[int, Program], link: dict[int, int],
                  succ: dict[int, int]) -> tuple[list[Any], set[int]]:
    """The paths of links from a program nothing links to that end in A = 0, and the programs on them."""
    linked_to = set(link.values())
    chains: list[Any] = []
    placed: set[int] = set()
    for start in sorted(n for n in programs if n not in linked_to and n in link):
        path = [start]
        while path[-1] in link and link[path[-1]] not in path:
            path.append(link[path[-1]])
        if path[-1] not in succ:  # ends in A = 0: a plain chain
            chains.append(path)
            placed.update(path)
    return chains, placed


def _loops(link: dict[int, int], placed: set[int]) -> list[list[int]]:
    """The cycles among the linked programs not `placed` yet, each from its lowest program, added to
    `placed`."""
    loops = []
    for start in sorted(link):
        if start in placed:
            continue
        cycle = [start]
        while link.get(cycle[-1]) not in (None, start) and link[cycle[-1]] not in cycle:
            cycle.append(link[cycle[-1]])
        if link.get(cycle[-1]) == start and not placed.intersection(cycle):
            loops.append(cycle)
            placed.update(cycle)
    return loops
