"""Test support: a command run in a real terminal — a tmux pane — and what its screen shows.

tmux draws the pane as a terminal would (cursor movements, erased lines, a progress display's
redraws): `capture-pane` gives the screen the operator sees, not the bytes written. Tests using
it skip, with the reason, where tmux is not installed (`.ci/run` installs it).
"""

from __future__ import annotations

import os
import re
import shlex
import subprocess
import time
import uuid
from collections.abc import Callable
from pathlib import Path

from tools import needs, which

TMUX = which("tmux")
needs_tmux = needs("tmux")

#: Captures of the screen a wait makes at most, one every `POLL` seconds: polling, bounded.
POLLS = 1_200
POLL = 0.05
#: A line of rich's progress display: "reading modules ━━━━━━━ 3/6 0:00:01".
PROGRESS_LINE = re.compile(r"━|\d+/\d+ +-?\d+:\d\d:\d\d")
#: What the pane's shell prints once the command ended.
ENDED = re.compile(r"^\[exit (\d+)\]$", re.MULTILINE)


class Pane:
    """One tmux server of its own (its own socket), one window, one command; the pane stays after
    the command ends, so its last screen and exit status can be read."""

    def __init__(self, folder: Path, command: list[str], env: dict[str, str], *, stdout: Path | None = None,
                 width: int = 160,
                 height: int = 100) -> None:
        """Start `command` with `env` (and its stdout into the file `stdout`, if given) in a new pane."""
        assert TMUX is not None
        self._socket = f"prc3cfg-test-{uuid.uuid4().hex[:12]}"
        config = folder / "tmux.conf"
        config.write_text("set -g remain-on-exit on\nset -g status off\nset -g history-limit 10000\n")
        line = shlex.join(["env", *(f"{k}={v}" for k, v in env.items()), *command])
        if stdout is not None:
            line += f" > {shlex.quote(str(stdout))}"
        line += "; printf '\\n[exit %d]\\n' $?"
        self._tmux("-f", str(config), "new-session", "-d", "-x", str(width), "-y", str(height), "-s", "t",
                   line)

    def _tmux(self, *args: str) -> str:
        return subprocess.run([TMUX or "tmux", "-L", self._socket, *args], check=True, capture_output=True,
                              text=True).stdout

    def screen(self) -> str:
        """What the pane shows now, its scrollback included, wrapped lines joined."""
        return self._tmux("capture-pane", "-p", "-J", "-S", "-", "-t", "t")

    def wait(self, until: Callable[[str], bool], what: str) -> str:
        """The screen, once `until` holds for it (a bounded number of polls)."""
        for _ in range(POLLS):
            shown = self.screen()
            if until(shown):
                return shown
            time.sleep(POLL)
        raise AssertionError(f"the screen never showed {what}:\n{shown}")

    def watch(self, polls: int) -> list[str]:
        """The next `polls` screens, `POLL` apart: what stays on screen while the command waits."""
        screens = []
        for _ in range(polls):
            time.sleep(POLL)
            screens.append(self.screen())
        return screens

    def type(self, text: str) -> None:
        """Keys typed at the terminal, then Enter."""
        self._tmux("send-keys", "-t", "t", "-l", text)
        self._tmux("send-keys", "-t", "t", "Enter")

    def exit_status(self) -> int:
        """The command's exit status, once it ended (the pane's shell says it, last)."""
        shown = self.wait(lambda screen: ENDED.search(screen) is not None, "the command's end")
        found = ENDED.search(shown)
        assert found is not None
        return int(found.group(1))

    def close(self) -> None:
        subprocess.run([TMUX or "tmux", "-L", self._socket, "kill-server"], capture_output=True)


def prc3cfg(*args: object) -> list[str]:
    """The command line of `prc3cfg ARGS`, run as the console script runs it (this venv's install)."""
    import sys

    return [sys.executable, "-m", "prc3cfg", *map(str, args)]


def environment() -> dict[str, str]:
    """What a command in the pane needs of this test's environment: its lock and state folders."""
    return {key: os.environ[key] for key in ("PRC3CFG_LOCK_DIR", "PRC3CFG_STATE_DIR", "PATH")
            if key in os.environ}
