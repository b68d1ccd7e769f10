"""Frames over TCP on a loaded machine: good frames must never be discarded for their timing.

    python bench/tcp_frames_bench.py [--exchanges 20000] [--hogs 4] [--framing crc16] [--no-pauses]

Starts `prc3cfg emulator serve --verbose` (a separate process) and a client process that
makes `--exchanges` exchanges through the link client (`socket://`, reads and writes over
30 modules), while `--hogs` busy processes load every CPU and — unless `--no-pauses` — the
client and the emulator are stopped and continued (SIGSTOP/SIGCONT) for 1..20 ms at
random, every 5..50 ms. No fault is injected, so every frame on the line is good. Prints
the exchanges made, the frames the client's decoder discarded (its trace), the link's
retries and the frames the emulator discarded (its log); acceptance: all three zero.
`--uart-timeouts` makes the client decode as from a UART (`uart=True`, as before TCP
was told apart), for comparison.
"""

from __future__ import annotations

import argparse
import io
import json
import os
import random
import signal
import subprocess
import sys
import threading
import time

HOG = "while True: pass"


class CountingTrace(io.StringIO):
    """A `Trace` stream that keeps only the count of each kind of line (`x`: discarded)."""

    def __init__(self) -> None:
        super().__init__()
        self.kinds: dict[str, int] = {}

    def write(self, text: str) -> int:
        kind = text.split("\t")[2]
        self.kinds[kind] = self.kinds.get(kind, 0) + 1
        return len(text)


def client(url: str, framing: str, exchanges: int, uart: bool) -> None:
    """The client process: `exchanges` exchanges; prints its counts as JSON."""
    from prc3cfg.core import codec
    from prc3cfg.core.framing import get_framing
    from prc3cfg.core.image import Program
    from prc3cfg.core.line import LineSettings
    from prc3cfg.shell.link.client import Link
    from prc3cfg.shell.link.ports import open_port
    from prc3cfg.shell.link.trace import Trace

    line = LineSettings()
    stream = CountingTrace()
    link = Link(open_port(url, line, bus="bench"), get_framing(framing), bus="bench", line=line, retries=5,
                trace=Trace(stream))
    link.uart = uart
    messages = [codec.ReadSystem(), codec.ReadPrograms(1, 4), codec.ReadProgram(9)]
    start = time.perf_counter()
    for n in range(exchanges):
        message = codec.WriteProgram(1 + n % 64, Program(P=n % 400, V=100)) if n % 4 == 3 else messages[n % 4]
        link.request(1 + n % 30, message)
    seconds = time.perf_counter() - start
    link.port.close()
    print(json.dumps({"exchanges": exchanges, "attempts": link.exchanges, "retries": link.repeated,
                      "discarded": stream.kinds.get("x", 0), "seconds": seconds}))


def pause_at_random(pids: list[int], running: threading.Event, rng: random.Random) -> int:
    """Stop and continue one of `pids` for 1..20 ms every 5..50 ms while `running`; the pauses made."""
    pauses = 0
    while running.is_set():
        time.sleep(rng.uniform(0.005, 0.050))
        pid = rng.choice(pids)
        try:
            os.kill(pid, signal.SIGSTOP)
            time.sleep(rng.uniform(0.001, 0.020))
            os.kill(pid, signal.SIGCONT)
        except ProcessLookupError:
            break
        pauses += 1
    return pauses


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--exchanges", type=int, default=20_000)
    parser.add_argument("--hogs", type=int, default=os.cpu_count() or 2)
    parser.add_argument("--framing", default="crc16")
    parser.add_argument("--no-pauses", action="store_true")
    parser.add_argument("--seed", type=int, default=1)
    parser.add_argument("--uart-timeouts", action="store_true")
    parser.add_argument("--client", metavar="URL", help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.client:
        client(args.client, args.framing, args.exchanges, args.uart_timeouts)
        return

    emulator = subprocess.Popen(
        [sys.executable, "-m", "prc3cfg", "emulator", "serve", "--listen", "127.0.0.1:0", "--modules", "1-30",
         "--framing", args.framing, "--verbose"],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
    )
    hogs = [subprocess.Popen([sys.executable, "-c", HOG]) for _ in range(args.hogs)]
    server_log: list[str] = []
    reader = threading.Thread(target=lambda: server_log.extend(emulator.stderr), daemon=True)
    reader.start()
    try:
        url = "socket://" + emulator.stdout.readline().split()[2]
        worker = subprocess.Popen(
            [sys.executable, __file__, "--client", url, "--framing", args.framing, "--exchanges",
             str(args.exchanges),
             *(["--uart-timeouts"] if args.uart_timeouts else [])],
            stdout=subprocess.PIPE, text=True,
        )
        running = threading.Event()
        running.set()
        pauses: list[int] = []
        if not args.no_pauses:
            pauser = threading.Thread(
                target=lambda: pauses.append(pause_at_random([worker.pid, emulator.pid], running,
                                                             random.Random(args.seed)))
            )
            pauser.start()
        output, _ = worker.communicate()
        running.clear()
        if not args.no_pauses:
            pauser.join()
        if worker.returncode != 0:
            sys.exit(f"the client failed (exit {worker.returncode})")
    finally:
        for hog in hogs:
            hog.kill()
            hog.wait()
        emulator.send_signal(signal.SIGCONT)
        emulator.terminate()
        emulator.wait()
        reader.join()
    counts = json.loads(output)
    emulator_discards = sum("discarded" in line for line in server_log)
    print(f"{args.framing}{' (client decoding as from a UART)' if args.uart_timeouts else ''}: "
          f"{counts['exchanges']} exchanges in {counts['seconds']:.1f} s over socket:// with {args.hogs} "
          "busy processes and "
          f"{pauses[0] if pauses else 0} SIGSTOP/SIGCONT pauses of the client or the emulator")
    print(f"  good frames discarded by the client {counts['discarded']}, link retries {counts['retries']}, "
          f"discarded by the emulator {emulator_discards}   (acceptance: all 0)")


if __name__ == "__main__":
    main()
