"""Bus time on a real-speed line: measured read-back and apply against their estimates.

    python bench/line_bench.py [--modules 30] [--baud 9600] [--framing crc16] [--changed 2] [--skip-read]
    [--skip-apply] [--full-read] [--gaps]

Starts `prc3cfg emulator serve --line-speed BAUD` (a separate process, so the emulator
and the client do not share an interpreter), then

- **read**: `prc3cfg read --json` of a plant of N fully managed modules (one 50h and
  sixteen 52h each) — prints the wall time, the bus-time estimate (docs/line.md's cost model
  summed over those exchanges) and the ratio; acceptance: at most 1.10;
- **apply**: `prc3cfg apply` of the same plant from factory defaults (commissioning: see below), then
  of a change of `--changed` programs per module (default 2: a position and a speed) —
  each prints the wall time against the read-back, the plan's estimated bus time and the
  *minimal* verification (the floor: the 50h if a system step runs, and the fewest 51h/52h
  that read the programs the steps write), and, from the apply's journal, each phase on the
  line and the verification exchanges against the floor; acceptance: at most 1.10, and
  verification exchanges = the floor. A third apply changes one program alike on every
  module: with a full line (30 modules) that is one broadcast and a verifying read per
  module; it prints the writes' bus time against the same change as addressed writes. A
  fourth changes one system parameter on every module (the acceleration: a change that can
  clamp no program, so no program is read for it).

Commissioning against the naive download (issue 41, item 4: at most 0.70×, evidence included). *The naive
download* is what a tool that knows nothing of the modules does to put the plant file on them, and then check
it: per module, addressed, one 20h and one 21h for every program the plant file sets (with
`unmanaged_programs: reset` every program, the unmanaged ones at the factory's), then read back what it wrote
— a 50h and the fewest 51h/52h over those programs; no read before writing (it writes everything whatever the
modules hold), no broadcast. Its time is the cost model's (docs/line.md), which the line matches within 1.02×
(the ratios below): at 9600 baud on 30 modules of this plant, 76.6 s of writes and 45.2 s of read-back, 121.8
s. Commissioning is the wall time of `prc3cfg apply` on factory-fresh modules, its evidence included: a 50h of
every module, which shows the factory's system parameters — so the programs the plant file manages are planned
as the factory's, not read first (`what_to_read.factory_fresh`), and the verification reads every one of them
back after the writes, written or not (what another tool may have changed is found there and repaired). The
bench's `plan --json` before it is not counted (it reads in full: a plan for review reads what it shows).
Measured (crc16, 2 shared cores): 70.42 s before (a full read before writing, 45.65 s on the line; 0.58× the
naive download), 50.45 s after (1.41 s of 50h, 0.65 s of writes, 46.28 s of verification — 510 exchanges, its
floor now: 0.41×). Open-driver unprotected: 66.04 s against a naive download of 199.69 s, 0.33× (2.36 s of
50h, 0.82 s of writes, 62.16 s of verification; each verifying read is believed at once where it reads as
planned, as a naive tool's read-back of what it wrote would be).

What the link's protections cost (issue 40, acceptance at 9600 baud on 30 modules: the two program changes ≤
10 s, the system change ≤ 5 s, wall): on `--framing open-driver` (the plant's `parity: none`, its risk
accepted) nothing protects a data reply, so a read is believed only when it agrees with another observation —
the line's record or the write being verified, else a second reply (`read` of modules no record knows: counted
twice, `CONFIRMED`); the quiet period before a verification that a late copy could undo
(`late_frames.undone_by_late`) would show as the verification on the line above its estimate. Measured (2
cores, shared): crc16 — 6.71 s, 5.12 s, 3.34 s (8.21 s, 6.23 s, 4.21 s with rolling evidence's eight 52h a
plan, `what_to_read.ROLLED_WINDOWS`: 0.73 s on the line), verification on the line 1.02× its estimate (none of
the three plans waits a quiet period: no 10h–14h, and no addressed step overrides the broadcast), so a checked
line pays nothing. Open-driver unprotected — 10.68 s, 8.91 s, 5.32 s (was 18.17 s, 15.34 s, 9.96 s when every
read was made twice): each read of an apply is as the record or its writes say and is made once, so the
confirmations cost nothing there; what is left over the limits is open-driver's own line time (the estimates:
9.69 s, 8.17 s, 4.68 s, at 1.02× on the line, plus the commands' start-up). `read` of 30 modules nothing
expects: 124.24 s, twice its one-read time. A serial device with `parity: even` on POSIX checks parity at the
port and reads once (docs/line.md); over TCP an open-driver line confirms whatever its parity.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from datetime import datetime
from itertools import pairwise
from pathlib import Path

from prc3cfg.core import codec
from prc3cfg.core.bustime import LineCost
from prc3cfg.core.framing import get_framing
from prc3cfg.core.line import LineSettings
from prc3cfg.core.what_to_read import protects_replies, read_messages
from prc3cfg.plant import parse_plant

#: Reads of each message `read`'s estimate counts: 2 where nothing protects a data reply and no record says
#: what it holds (set in `main`); an apply's reads are as the record or its writes say: once.
CONFIRMED = 1


def changed_programs(changed: set[int] = frozenset(), faster: set[int] = frozenset()) -> str:
    """Programs 1..32 of a module; those in `changed` a little further and faster, those in
    `faster` only faster."""
    return "\n".join(
        f"          {n}: {{position: {0.5 + n / 100 + (0.01 if n in changed else 0):.3f}, "
        f"speed: 0.{200 + n + (10 if n in changed | faster else 0):03d}, dwell: {n % 7}.5}}"
        for n in range(1, 33)
    )


PROGRAMS = changed_programs()
PLANT = """\
plant: line-bench
buses:
  - name: line
    port: {port}
    framing: {framing}
    baud: {baud}
    parity: none{accepted}
    timeout: 1.0
    modules:
{modules}
"""
MODULE = """\
      - address: {address}
        name: m{address}
        unmanaged_programs: reset
        system: {{upper_reversing_point: 2.000, max_speed: 0.500, acceleration: {acceleration}}}
        programs:
{programs}
        chains: [[1, 2, 3, 4], {{programs: [10, 11], loop: true}}]
"""


def run(command: list[str]) -> tuple[float, str]:
    start = time.perf_counter()
    done = subprocess.run(command, capture_output=True, text=True)
    elapsed = time.perf_counter() - start
    if done.returncode != 0:
        sys.exit(f"{' '.join(command)} failed:\n{done.stdout}\n{done.stderr}")
    return elapsed, done.stdout


def journal_phases(path: Path) -> tuple[dict[str, float], int]:
    """Seconds on the line per phase of an apply (from the first exchange of a phase to the end of
    its last), and the number of verification exchanges."""
    exchanges = [e for e in map(json.loads, path.read_text().splitlines()) if e["event"] == "exchange"]
    for e in exchanges:
        e["start"] = datetime.fromisoformat(e["time"]).timestamp() - e["duration_s"]
    writes = [i for i, e in enumerate(exchanges) if not e["request"].startswith(("50", "51", "52"))]
    spans = {"read-back": exchanges[: writes[0]], "writes": exchanges[writes[0] : writes[-1] + 1],
             "verify": exchanges[writes[-1] + 1 :]}
    seconds = {name: part[-1]["start"] + part[-1]["duration_s"] - part[0]["start"]
               for name, part in spans.items()}
    return seconds, len(spans["verify"])


GAP_LIMIT = 0.050  # seconds a line may stand idle between two exchanges


def idle_gaps(trace: Path, cost: LineCost) -> dict[str, tuple[float, str, float, float]]:
    """Per bus of an apply's frame trace: the largest idle gap (and between which requests), their
    sum, and the gap before the first write — from the end of an exchange to the next request on the
    line. An exchange ends with its reply heard; a broadcast (no reply) once its frame has gone out at
    the line's speed (the trace stamps it as it is handed over) and the turnaround every module takes
    to execute it (`LineCost.broadcast_time`) has passed — the line is busy, not idle, until then."""
    events: dict[str, list[tuple[float, str, int, float]]] = {}
    for line in trace.read_text().splitlines():
        stamp, bus, direction, frame = line.split("\t")[:4]
        if direction in "<>":
            message = int(frame[6:8], 16) if direction == ">" else -1  # crc16: A5h, address, length, ID
            # the line busy after the stamp
            sending = len(frame) // 2 * cost.line.char_time + cost.turnaround if direction == ">" else 0.0
            events.setdefault(bus, []).append((datetime.fromisoformat(stamp).timestamp(), direction, message,
                                               sending))
    found = {}
    for bus, seen in events.items():
        gaps, asked = [], -1
        for before, after in pairwise(seen):
            asked = before[2] if before[1] == ">" else asked
            if after[1] == ">":
                # a reply's stamp; a broadcast's, its frame and turnaround later
                ended = before[0] + before[3]
                gaps.append((max(0.0, after[0] - ended), f"{asked:02X}h → {after[2]:02X}h", after[2]))
        to_write = next((gap for gap, _, message in gaps if message < 0x50), 0.0)
        largest = max(gaps)
        found[bus] = (largest[0], largest[1], sum(gap for gap, _, _ in gaps), to_write)
    return found


def verification_floor(plan: dict, cost: LineCost, unread: frozenset[int] = frozenset()) -> tuple[int, float]:
    """The fewest exchanges, and their bus time, that read what a plan's steps can change — and `unread`, the
    programs of each changed module planned from the factory's without being read (commissioning)."""
    exchanges, seconds = 0, 0.0
    for bus in plan["buses"]:
        for module in bus["modules"]:
            steps = [codec.decode_message(bytes.fromhex(step["message"])) for step in module["steps"]]
            if not steps:
                continue
            reads = read_messages({n for m in steps for n in m.touched_programs()} | unread)
            if not any(m.RELEASES_AXES for m in steps):
                reads = reads[1:]  # no system step: no 50h
            exchanges += len(reads)  # each as the plan expects it: believed at once, confirmed or not
            seconds += sum(cost.message_time(module["address"], m) for m in reads)
    return exchanges, seconds


def naive_download(plant: Path, cost: LineCost) -> tuple[float, float]:
    """The naive download of `plant` (see the docstring), by the cost model: its writes' and its read-back's
    seconds."""
    writes = reading = 0.0
    for _, module in parse_plant(plant, plant.read_bytes()).modules():
        desired, address = module.desired_image(), module.address
        messages = [codec.WriteSystem(desired.system),
                    *(codec.WriteProgram(n, p) for n, p in enumerate(desired.programs, 1) if p is not None)]
        writes += sum(cost.message_time(address, m) for m in messages)
        reading += sum(cost.message_time(address, m)
                       for m in read_messages(module.managed_programs() if module.unmanaged_programs == "keep"
                                                                              else range(1, 65)))
    return writes, reading


def measure_apply(title: str, prc3cfg: list[str], plant: Path, work: Path, cost: LineCost,
                  read_estimate: float, read: list[str],
                  gaps: bool = False, fresh: bool = False) -> float:
    """Measure one apply and print it; its wall time. `fresh`: factory-fresh modules — what the apply reads
    before writing is one 50h each, and its verification reads every managed program too."""
    _, plan_json = run([*prc3cfg, "plan", str(plant), "--json", *read])
    plan = json.loads(plan_json)
    fresh = fresh and not read  # --full-read plans nothing from the factory's
    floor, floor_time = verification_floor(plan, cost, frozenset(range(1, 65)) if fresh else frozenset())
    if fresh:
        # one 50h a module, as the record the plan above left expects it: believed at once, on open-driver too
        read_estimate = sum(cost.message_time(m["address"], codec.ReadSystem()) for bus in plan["buses"]
                            for m in bus["modules"])
    journals = work / ".prc3cfg" / "journal"
    before = set(journals.iterdir()) if journals.exists() else set()
    trace = work / "apply.trace"
    trace.unlink(missing_ok=True)  # --trace appends
    wall, _ = run([*prc3cfg, "apply", str(plant), "--auto-approve", "--allow-axis-release", *read,
                   *(["--trace", str(trace)] if gaps else [])])
    if "read" in plan:  # a targeted read-back: what the plan says it reads
        read_estimate = plan["estimated_phases_s"]["reading"]  # as the line's record says: believed at once
        exchanges = sum(len(read_messages(m["read"]["programs"])) for bus in plan["buses"]
                        for m in bus["modules"])
        print(f"  targeted read-back: {exchanges} exchanges for "
              f"{sum(len(b['modules']) for b in plan['buses'])} modules read")
    estimate = read_estimate + plan["estimated_bus_time_s"] + floor_time
    print(f"  apply, {title}: wall {wall:7.2f} s   estimate {estimate:7.2f} s   ratio {wall / estimate:.3f}"
          f"   (read-back {read_estimate:.2f} s, writes {plan['estimated_bus_time_s']:.2f} s, minimal "
          f"verification {floor_time:.2f} s)")
    (journal,) = set(journals.iterdir()) - before
    phases, verifying = journal_phases(journal)
    for name, part in (("read-back", read_estimate), ("writes", plan["estimated_bus_time_s"]),
                       ("verify", floor_time)):
        print(f"    {name:<10} on the line {phases[name]:7.2f} s   estimate {part:7.2f} s   ratio "
              f"{phases[name] / part:.3f}")
    print(f"    verification exchanges {verifying}, floor "
          f"{floor}{'' if verifying == floor else '   ✗ above the floor'}")
    if gaps:
        for bus, (largest, where, total, to_write) in idle_gaps(trace, cost).items():
            print(f"    idle gaps on {bus}: largest {largest * 1000:6.1f} ms ({where})   sum {total:6.2f} s "
                  "  reading → writing "
                  f"{to_write * 1000:6.1f} ms{'' if largest < GAP_LIMIT else '   ✗ over 50 ms'}")
    broadcasts = [b for bus in plan["buses"] for b in bus.get("broadcasts", [])]
    if broadcasts:
        print(f"    {len(broadcasts)} broadcast{'s' if len(broadcasts) != 1 else ''} to "
              f"{len(broadcasts[0]['modules'])} modules: "
              f"writes {plan['estimated_bus_time_s']:.3f} s, as addressed writes "
              f"{plan['without_broadcasts_bus_time_s']:.3f} s")
    return wall


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--modules", type=int, default=30)
    parser.add_argument("--baud", type=int, default=9600)
    parser.add_argument("--framing", default="crc16")
    parser.add_argument("--skip-read", action="store_true")
    parser.add_argument("--skip-apply", action="store_true")
    parser.add_argument("--changed", type=int, default=2,
                        help="programs changed per module in the second apply")
    parser.add_argument("--full-read", action="store_true",
                        help="plan and apply with --full-read (every module read in full)")
    parser.add_argument("--gaps", action="store_true",
                        help="each apply's idle gaps on the line, from its frame trace")
    args = parser.parse_args()
    global CONFIRMED
    CONFIRMED = 1 if protects_replies(get_framing(args.framing).checked, "none", False) else 2
    accepted = "" if CONFIRMED == 1 else "\n    accept_undetected_damage: true"
    read = ["--full-read"] if args.full_read else []
    prc3cfg = [sys.executable, "-m", "prc3cfg"]
    startup, _ = run([*prc3cfg, "--help"])
    cost = LineCost.of(args.framing, LineSettings(baud=args.baud, parity="none"), 0.010, 0.020)

    with tempfile.TemporaryDirectory() as work:
        # the lines' records: this run's, not the machine's
        os.environ["PRC3CFG_STATE_DIR"] = str(Path(work) / "state")
        emulator = subprocess.Popen(
            [*prc3cfg, "emulator", "serve", "--listen", "127.0.0.1:0", "--modules", f"1-{args.modules}",
             "--framing", args.framing, "--line-speed", str(args.baud), "--parity", "none"],
            stdout=subprocess.PIPE, text=True,
        )
        try:
            port = emulator.stdout.readline().split()[2]
            plant = Path(work) / "plant.yaml"
            modules = "".join(MODULE.format(address=a, programs=PROGRAMS, acceleration="1.500")
                              for a in range(1, args.modules + 1))
            plant.write_text(PLANT.format(port=f"socket://{port}", framing=args.framing, baud=args.baud,
                                          modules=modules, accepted=accepted))
            read_estimate = (args.modules * sum(cost.message_time(1, m)
                                                for m in read_messages(range(1, 65))) * CONFIRMED)
            print(f"{args.modules} modules, {args.framing}, {args.baud} baud 8N1, turnaround 10 ms; "
                  f"command start-up {startup:.2f} s (included below)"
                  + ("" if CONFIRMED == 1
                     else "; no check protects a reply: a read nothing expects is confirmed, "
                          "counted twice"))
            if not args.skip_read:
                wall, _ = run([*prc3cfg, "read", str(plant), "--json"])
                print(f"  read:  wall {wall:7.2f} s   estimate {read_estimate:7.2f} s   ratio "
                      f"{wall / read_estimate:.3f}")
            if not args.skip_apply:
                writes, reading = naive_download(plant, cost)
                wall = measure_apply("commissioning from factory defaults", prc3cfg, plant, Path(work), cost,
                                     read_estimate, read, args.gaps,
                                     fresh=True)
                # it reads back what it wrote: each reply believed at once, as the apply's verification
                naive = writes + reading
                print(f"    naive download {naive:7.2f} s (writes {writes:.2f} s, read-back "
                      f"{reading:.2f} s): "
                      f"commissioning {wall / naive:.2f}× the naive "
                      f"download{'' if wall <= 0.7 * naive else '   ✗ over 0.70×'}")
                for title, programs, acceleration in (
                    (f"{args.changed} changed programs per module, other ones on each",
                     lambda a: changed_programs({(a + k) % 32 + 1 for k in range(args.changed)}), "1.500"),
                    ("the same speed of program 32 on every module",
                     lambda a: changed_programs({(a + k) % 32 + 1 for k in range(args.changed)}, {32}),
                     "1.500"),
                    ("one system change on every module (acceleration)",
                     lambda a: changed_programs({(a + k) % 32 + 1 for k in range(args.changed)}, {32}),
                     "1.200"),
                ):
                    changed = "".join(MODULE.format(address=a, programs=programs(a),
                                                    acceleration=acceleration)
                                      for a in range(1, args.modules + 1))
                    plant.write_text(PLANT.format(port=f"socket://{port}", framing=args.framing,
                                                  baud=args.baud, modules=changed, accepted=accepted))
                    measure_apply(title, prc3cfg, plant, Path(work), cost, read_estimate, read, args.gaps)
        finally:
            emulator.terminate()
            emulator.wait()


if __name__ == "__main__":
    main()
