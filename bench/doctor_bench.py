"""How close `prc3cfg doctor` measures a module's turnaround: the timing the tests leave out.

    python bench/doctor_bench.py [--exchanges 15] [--seed 3]

An emulator at line speed (9600 baud 8E1) whose modules 1, 2, 3 answer after 80, 120 and 160 ms
(seeded jitter of ±4 ms) is measured by `prc3cfg doctor` in each framing. Prints, per framing and
module, the median and worst doctor measured and the median's error against the turnaround given;
acceptance: within 10 % on an idle machine. A wall-clock figure: a loaded machine's scheduling adds
to it, which is why tests/test_doctor.py only checks that a measurement is never shorter (90 % of the
turnaround or more) and leaves the upper side here.
"""

from __future__ import annotations

import argparse
import io
import sys
from contextlib import redirect_stderr, redirect_stdout

from prc3cfg.cli import main
from prc3cfg.core.device import ModuleState
from prc3cfg.core.line import LineSettings
from prc3cfg.shell.emulator.server import Emulator, FaultInjection

GIVEN = {1: 0.080, 2: 0.120, 3: 0.160}


def doctor(framing: str, exchanges: int, seed: int) -> dict[int, tuple[float, float]]:
    """address → (median, worst) in s, as `prc3cfg doctor` printed them."""
    line = LineSettings(9600, 8, "even", 1)
    with Emulator({a: ModuleState.factory(a) for a in GIVEN}, framing=framing, line=line, line_speed=True,
                  turnarounds=GIVEN,
                  jitter=0.004, faults=FaultInjection(seed=seed)) as emulator:
        host, tcp = emulator.listen(rfc2217=True)
        out = io.StringIO()
        with redirect_stdout(out), redirect_stderr(io.StringIO()):
            try:
                main(["doctor", "--port", f"rfc2217://{host}:{tcp}", "--framing", framing, "--baud", "9600",
                      "--parity", "even",
                      "--modules", "1-3", "--exchanges", str(exchanges), "--allow-unchecked-probes"])
            except SystemExit as exit_:
                if exit_.code:
                    sys.exit(f"doctor failed on {framing}: exit {exit_.code}")
    # doctor's table
    rows = [line.split("│") for line in out.getvalue().splitlines() if line.startswith("│") and "ms" in line]
    return {int(r[1]): (float(r[2].split()[0]) / 1000, float(r[3].split()[0]) / 1000) for r in rows}


def main_() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--exchanges", type=int, default=15)
    parser.add_argument("--seed", type=int, default=3)
    args = parser.parse_args()
    worst_error = 0.0
    print(f"{'framing':<12} {'module':>6} {'given':>8} {'median':>8} {'worst':>8} {'error':>7}")
    for framing in ("crc16", "stx", "open-driver"):
        measured = doctor(framing, args.exchanges, args.seed)
        for address, given in GIVEN.items():
            median, worst = measured[address]
            error = (median - given) / given
            worst_error = max(worst_error, abs(error))
            print(f"{framing:<12} {address:>6} {given * 1000:>6.0f}ms {median * 1000:>6.1f}ms "
                  f"{worst * 1000:>6.1f}ms {error:>+7.1%}")
    print(f"largest error of a median: {worst_error:.1%} (acceptance: within 10 % on an idle machine)")


if __name__ == "__main__":
    main_()
