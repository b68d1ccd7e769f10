"""The entry point of `prc3cfg` and `python -m prc3cfg`: signals are handled first of all
(`prc3cfg.shell.cancel.exit_on_signal`), then the command line is imported and run — a Ctrl-C
while Python imports it is one line and exit 130 like any other.

A command keeps what it builds until it ends (a plant's documents, the images, the plans:
hundreds of thousands of objects) and makes few reference cycles, so the cyclic collector runs
after `YOUNG` new objects, not Python's 700: at 700 its passes over them took 0.13 s of the 2 s
CPU of `plan` of 8 × 30 modules (bench/plan_time_bench.py), at the same peak memory. What a
command imports alone is some 60,000 of them (64,000 by the end of the demo's plan), nearly all
kept until the process ends: at 50,000 every command made one pass over those — 14 to 17 ms of
a 0.3 s plan or apply, to free some 480 (2-core machine, 29 November 2026); at 100,000 the demo's
plan and apply make none, and the large plan's time and peak memory are as they were. For the
same reason the process ends without freeing them one by one (0.1 s more; mypy does the same):
once the command line has returned and flushed its output, and only when nothing else runs —
no other thread (a line's worker would be cut off), no profiler, tracer or debugger (which
write what they found as Python shuts down).

stdout and stderr write UTF-8 whatever the console's code page says (`utf8_output`): the output
says ✓, ⚠, → and —, which a Windows console redirected to a file or a pipe (cp1252), or
PYTHONIOENCODING, could not encode — that was a UnicodeEncodeError half-way through the output.
"""

import codecs
import gc
import io
import os
import sys
import threading

from prc3cfg.shell.cancel import exit_on_signal

#: New objects between two passes of the cyclic garbage collector over the young ones.
YOUNG = 100_000


def main() -> None:
    exit_on_signal()
    utf8_output()
    gc.set_threshold(YOUNG, *gc.get_threshold()[1:])
    from prc3cfg.cli import main as run

    try:
        run()
    except SystemExit as ended:
        _leave(ended.code)
    _leave(0)


def utf8_output() -> None:
    """Make stdout and stderr write UTF-8 where they write another encoding; a character that
    UTF-8 cannot hold either (a lone surrogate of an undecodable file name) is written as its
    escape. A stream already writing UTF-8 (a terminal on Linux, the Windows console) is left as it is."""
    for stream in (sys.stdout, sys.stderr):
        if isinstance(stream, io.TextIOWrapper) and codecs.lookup(stream.encoding).name != "utf-8":
            stream.reconfigure(encoding="utf-8", errors="backslashreplace")


def _leave(code: str | int | None) -> None:
    """End the process with `code`: at once where nothing is left to do (module docstring), else as Python
    does."""
    code = 0 if code is None else code
    alone = all(thread is threading.main_thread() or thread.daemon for thread in threading.enumerate())
    if not isinstance(code, int) or not alone or sys.gettrace() is not None or sys.getprofile() is not None:
        sys.exit(code)
    try:
        sys.stdout.flush()
        sys.stderr.flush()
    except OSError:  # said as Python says it, at its own exit
        sys.exit(code)
    os._exit(code)


if __name__ == "__main__":
    main()
