"""What a plan read now and what it took as known from the line's record, as every output of a plan says it:
the headline of a plan without changes (`no_changes`), the line of what was read and taken (`reading_line`,
the modules read in full by reason), the oldest value taken (`oldest_taken`), said once (in the headline where
it names it: `headline_names_oldest`, else in the line of what was read) and the programs planned from the
factory's without reading them (`factory_line`). Every text a plan file brings is `shown` as the medium
needs; a plan file's words of what was read in full and why stay its claim. Pure: returns strings.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any

from prc3cfg.core import text as escape
from prc3cfg.core.render.words import modules_in, plural
from prc3cfg.core.text import address_ranges
from prc3cfg.core.what_to_read import to_the_minute

#: The headline of a plan without changes that read every value it covers in that run.
EVERY_MODULE = "No changes: every module matches the plant file."


def no_changes(evidence: dict[str, Any] | None, shown: Callable[[str], str] = escape.shown) -> str:
    """The headline of a plan without changes, naming its evidence (`plan_file.evidence`): "every module
    matches the plant file" only when every value it covers was read in that run; else "No changes to what was
    read now (the system blocks of 6 modules) or to what prc3cfg last read or verified (82 programs of 4
    modules; oldest value taken from the record: line/m4's programs, as apply of /p/a.yaml by ana@pc read or
    verified them since 2026-11-26 03:27 UTC)"."""
    if evidence is None:  # a plan file written before plans said what they rest on
        return "No changes (the plan file does not say what was read, or taken from the line's record)."
    if evidence["complete"]:
        return EVERY_MODULE
    now, record, oldest = evidence["read_now"], evidence["from_record"], evidence["oldest"]
    read = f"the system blocks of {plural(now['system_blocks'], 'module')}"
    read += f" and {plural(now['programs'], 'program')}" if now["programs"] else ""
    rests = f"{plural(record['programs'], 'program')} of {plural(record['modules'], 'module')}"
    rests += f"; {oldest_taken(oldest, shown)}" if oldest is not None else ""
    return f"No changes to what was read now ({read}) or to what prc3cfg last read or verified ({rests})."


def factory_line(document: dict[str, Any]) -> str | None:
    """What an apply planned from the factory's programs without reading them, in one line (None: nothing):
    on a factory-fresh module (`what_to_read.factory_fresh`) the programs the plant file manages are
    written over, not read first — and every one of them is read back after the writes."""
    said = (document.get("evidence") or {}).get("from_factory")
    if not isinstance(said, dict) or not said.get("programs"):
        return None
    return (f"Not read before writing: {plural(said['programs'], 'program')} of "
            f"{plural(said['modules'], 'module')} whose system "
            "parameters read as the factory's — planned as the factory's, not read before writing; the "
            "verification reads every "
            "one of them back after the writes, and repairs what another tool changed there")


def oldest_taken(oldest: dict[str, Any], shown: Callable[[str], str] = escape.shown, *,
                 whose: bool = True) -> str:
    """The oldest evidence a plan relied on (`evidence.oldest`), in words: "oldest value taken from the
    record: line/m4's programs, as apply of /p/a.yaml by ana@pc read or verified them since 2026-11-26 03:27
    UTC" (without `whose`: "…: line/m4's programs, since 2026-11-26 03:27 UTC")."""
    since = to_the_minute(oldest["since"]) or shown(oldest["since"])
    by = f" as {shown(oldest['by'])} read or verified them" if whose else ""
    return f"oldest value taken from the record: {shown(oldest['module'])}'s programs,{by} since {since}"


def headline_names_oldest(document: dict[str, Any], faults: Sequence[str]) -> bool:
    """Whether a plan's headline names the oldest value it took from the record (`no_changes`): a plan
    without changes, whose headline is not its faults' (`faulted_summary`). Its `reading_line` does not."""
    return not faults and not any(m["steps"] for _, m in modules_in(document))


def reading_line(document: dict[str, Any], shown: Callable[[str], str] = escape.shown, *,
                 claimed: bool = False, oldest: bool = True) -> str | None:
    """What a targeted plan read now and what it took as known from the line's record, in one line,
    its texts `shown` as the medium needs; None for a full read. "Read now: the system parameters of
    30 modules and 60 programs; taken as known from the line's record …, not read: 900 programs of 30
    modules, as apply of /p/a.yaml by ana@pc (since …) read or verified them; read in full: line/m2
    (program 3 is not as on record) — what no read sees: …". `claimed`: the document is a plan file's,
    whose words of whose verification was taken and of what was read in full and why are its own claim
    (`prc3cfg.core.plan_file`): said after "the plan file says", never as prc3cfg's. `oldest`: the oldest
    value taken named too (not where the headline named it: `headline_names_oldest`)."""
    said = document.get("read")
    if not isinstance(said, dict):
        return None
    modules = modules_in(document)
    programs = sum(len(m["read"]["programs"]) for _, m in modules)
    read = (f"the system parameters of {plural(len(modules), 'module')} and "
            f"{plural(programs, 'program')}") if modules else "nothing"
    whose, not_read = _not_read(said, modules, shown)
    in_full = _in_full(said["not_as_verified"], document)
    other = f"read in full: {', '.join(shown(words) for words in in_full)}" if in_full else ""
    claims = "; ".join(words for words in (whose, other) if words) if claimed else ""
    if whose and not claimed:
        not_read[0] += f", as {whose}"
    if oldest and not_read and isinstance(taken := (document.get("evidence") or {}).get("oldest"), dict):
        not_read[0] += f" ({oldest_taken(taken, shown, whose=False)})"
    parts = [f"Read now: {read}"]
    parts += ([f"taken as known from {shown(said['base'])}, not read: {' and '.join(not_read)}"]
              if not_read else [])
    parts += [other] if other and not claimed else []
    parts += [f"the plan file says: {claims} (apply --plan proves whose, not why)"] if claims else []
    return ("; ".join(parts)
            + (" — a program not read that another tool changed on a module whose system parameters did not "
                               "change is not seen: plan --refresh-only (or --full-read) reads everything"
               if not_read else ""))


#: How many modules read in full for one reason are named, each with it; more are said by address.
NAMED_IN_FULL = 3


def _in_full(entries: Sequence[str], document: dict[str, Any]) -> list[str]:
    """The modules read in full, each "bus/name (why)" (`ReadPlan.not_as_verified`); a reason given for more
    than `NAMED_IN_FULL` of the document's modules said once, with their addresses by bus: "its system
    parameters are not those on record at bus a addresses 1–30 and bus b address 4" — 30 modules were 30
    times one reason."""
    places = {f"{bus['name']}/{m['name']} (": (bus["name"], m["address"])
              for bus in document["buses"] for m in bus["modules"]}
    by_why: dict[str, list[tuple[str, tuple[str, int] | None]]] = {}
    for entry in entries:
        # the longest: "b/m (spare) (why)" begins with module m's "b/m (" too
        prefix = max((p for p in places if entry.startswith(p) and entry.endswith(")")), key=len,
                     default=None)
        why = entry if prefix is None else entry[len(prefix):-1]
        by_why.setdefault(why, []).append((entry, None if prefix is None else places[prefix]))
    said = []
    for why, modules in by_why.items():
        located = [place for _, place in modules if place is not None]
        if len(located) <= NAMED_IN_FULL or len(located) < len(modules):  # or words no module of it says
            said += [entry for entry, _ in modules]
            continue
        buses = {bus: [a for b, a in located if b == bus] for bus in dict.fromkeys(b for b, _ in located)}
        said.append(f"{why} at " + " and ".join(f"bus {bus} {address_ranges(addresses)}"
                                                for bus, addresses in buses.items()))
    return said


def _not_read(said: dict[str, Any], modules: list[tuple[str, dict[str, Any]]],
              shown: Callable[[str], str]) -> tuple[str, list[str]]:
    """Whose reads or verifications the programs not read rest on ("" when none was taken), and what was not
    read: "79 programs of 6 modules", "2 modules (line/a, line/b)"."""
    skipped = sum(len(m["read"]["programs_not_read"]) for _, m in modules)
    if not skipped:
        whose, parts = "", []
    else:
        sources = sorted({shown(source) for source in said.get("taken", {}).values()})
        whose = (f"{'; '.join(sources[:3])}{' and others' if len(sources) > 3 else ''} read or "
                 "verified them") if sources else ""
        parts = [f"{plural(skipped, 'program')} of "
                 f"{plural(sum(1 for _, m in modules if m['read']['programs_not_read']), 'module')}"]
    unread = [shown(name) for name in said["modules_not_read"]]
    parts += [f"{plural(len(unread), 'module')} "
              f"({', '.join(unread[:5])}{', …' if len(unread) > 5 else ''})"] if unread else []
    return whose, parts
