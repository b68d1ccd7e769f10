"""Ctrl-C and SIGTERM: stop promptly, but never inside an exchange and never mid-account.

`Cancellation.handling()` installs a handler for SIGINT and SIGTERM for the length of a
command (main thread only). A signal always sets `event`, which every `Link` looks at
before each attempt (`prc3cfg.shell.link.client`), so the threads that talk on the lines stop
after the exchange in flight with `Interrupted`. What else happens depends on the phase:

- inside `deferred()` (line work, and everything from the first write to the end of the
  account of an apply), nothing more: the code running there finishes its step, looks at
  `event`, says what it did, and raises `Interrupted` itself;
- elsewhere (loading, planning, rendering, prompts) the handler raises `Interrupted` at
  once, so a long plan or a question stops on the spot.

`Interrupted` is a `UserError` (exit 130): the CLI prints its one line, `error: interrupted`. Before a command
handles signals, and after, `exit_on_signal` (installed by the entry point before it imports anything else)
ends the process with that line and exit 130 at once: a Ctrl-C while Python imports the command line is not a
`KeyboardInterrupt` traceback, a SIGTERM not a death by signal. Owns the signal handling. Does not own what is
said about the work that stopped (`apply`, the CLI).
"""

from __future__ import annotations

import contextlib
import os
import signal
import threading
from collections.abc import Iterator

from prc3cfg.errors import Interrupted
from prc3cfg.shell import platform

SIGNALS = (signal.SIGINT, signal.SIGTERM)


def exit_on_signal() -> None:
    """From now on, until a command handles them, SIGINT and SIGTERM end the process at once:
    `error: interrupted` on stderr, exit 130 (`Interrupted.exit_code`)."""
    for signum in SIGNALS:
        signal.signal(signum, _exit_interrupted)


def _exit_interrupted(signum: int, frame: object) -> None:
    os.write(2, f"error: {Interrupted()}\n".encode())  # as the CLI says it
    os._exit(Interrupted.exit_code)


def main_thread_only() -> None:
    """A worker thread's first call: SIGINT and SIGTERM are not delivered to it. Python runs a
    handler in the main thread only, once that runs again — a signal the kernel gave a thread that
    reads or writes a line left the main thread asleep in its wait for them, and Ctrl-C did nothing
    until they were done; blocked here, the kernel gives it to the main thread, whose wait it ends."""
    platform.block_signals(SIGNALS)


class Cancellation:
    """The cancel event of one command and the phase that decides what a signal does."""

    def __init__(self) -> None:
        self.event = threading.Event()
        self._deferring = 0

    @contextlib.contextmanager
    def handling(self) -> Iterator[None]:
        """Handle SIGINT and SIGTERM while the block runs (a fresh, unset event)."""
        self.event.clear()
        if threading.current_thread() is not threading.main_thread():
            yield
            return
        previous = {signum: signal.signal(signum, self._on_signal) for signum in SIGNALS}
        try:
            yield
        finally:
            for signum, handler in previous.items():
                signal.signal(signum, handler)

    def _on_signal(self, signum: int, frame: object) -> None:
        self.event.set()
        if not self._deferring:
            raise Interrupted()

    @contextlib.contextmanager
    def deferred(self) -> Iterator[None]:
        """A phase a signal must not cut: it only sets `event`; the block decides when to stop."""
        self._deferring += 1
        try:
            yield
        finally:
            self._deferring -= 1

    @property
    def requested(self) -> bool:
        return self.event.is_set()

    def check(self) -> None:
        """`Interrupted` if a signal came."""
        if self.event.is_set():
            raise Interrupted()
