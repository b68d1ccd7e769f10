"""The entry point of `prc3cfg` and `python -m prc3cfg`: signals are handled first of all
(`prc3cfg.shell.cancel.exit_on_signal`), then the command line is imported and run — a Ctrl-C
while Python imports it is one line and exit 130 like any other.

A command keeps what it builds until it ends (a plant's documents, the images, the plans:
hundreds of thousands of objects) and makes few reference cycles, so the cyclic collector runs
after `YOUNG` new objects, not Python's 700: at 700 its passes over them took 0.13 s of the 2 s
CPU of `plan` of 8 × 30 modules (bench/plan_time_bench.py), at the same peak memory.
"""

import gc

from prc3cfg.shell.cancel import exit_on_signal

#: New objects between two passes of the cyclic garbage collector over the young ones.
YOUNG = 50_000


def main() -> None:
    exit_on_signal()
    gc.set_threshold(YOUNG, *gc.get_threshold()[1:])
    from prc3cfg.cli import main as run

    run()


if __name__ == "__main__":
    main()
