"""The line's record read once a command and written only where safety needs it (issue 41, item 5):
counted in a real prc3cfg process by Python's audit hooks — every open of a record file, every file
moved into the records' folder, every host name resolved — against the demo plant on emulators.

An apply reads each of a line's record files once, under the line's lock; it writes a line it changes
twice — before the first write (the modules it writes dropped, what was read kept) and after the
verification — and a line it leaves unchanged once, after. A plan or an apply resolves each line's
address twice (issue 43's "one line context"): once for its identity — its lock, its record, its
fault records — and once when pyserial connects; before, an apply resolved it three times and a
plan read the fault records again, unlocked, after the lines were closed."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from collections import Counter
from pathlib import Path

import pytest
from emulated import emulated_plant, run_cli
from terminal import Pane, environment, needs_tmux, prc3cfg

#: Runs prc3cfg with an audit hook that writes, for each open of a file under `lines/` and each file
#: moved there, one JSON line to the file descriptor given: the hook opens nothing itself.
COUNTING = """
import json, os, sys
fd = int(sys.argv[1])
def hook(event, args):
    if event == "open" and "/lines/" in str(args[0]) and not str(args[0]).endswith(".lock"):
        os.write(fd, (json.dumps(["open", str(args[0]), args[2]]) + "\\n").encode())
    elif event == "os.rename" and "/lines/" in str(args[1]):
        os.write(fd, (json.dumps(["write", str(args[1])]) + "\\n").encode())
    elif event == "socket.getaddrinfo":
        os.write(fd, (json.dumps(["resolve", f"{args[0]}:{args[1]}"]) + "\\n").encode())
sys.addaudithook(hook)
from prc3cfg.__main__ import main
sys.argv = ["prc3cfg", *sys.argv[2:]]
main()
"""


def counted(tmp_path: Path, *args: object) -> tuple[subprocess.CompletedProcess, Counter, Counter, Counter]:
    """`prc3cfg ARGS` in a process of its own: its result, the record files it opened for reading (by
    name, each time), those it wrote (by name) and the host names it resolved (by host:port)."""
    log = tmp_path / "record-io.log"
    with log.open("wb") as sink:
        done = subprocess.run([sys.executable, "-c", COUNTING, str(sink.fileno()), *map(str, args)],
                              pass_fds=(sink.fileno(),),
                              capture_output=True, text=True, env=os.environ | {"COLUMNS": "200"},
                              check=False)
    reads, writes, resolved = Counter(), Counter(), Counter()
    for line in log.read_text().splitlines():
        event = json.loads(line)
        if event[0] == "resolve":
            resolved[event[1]] += 1
        elif event[0] == "write":
            writes[Path(event[1]).name] += 1
        elif not event[2] & (os.O_WRONLY | os.O_RDWR):
            reads[Path(event[1]).name] += 1
    log.unlink()
    return done, reads, writes, resolved


def edit(path: Path, old: str, new: str) -> None:
    text = path.read_text()
    assert old in text, old
    path.write_text(text.replace(old, new, 1))


@pytest.mark.skipif(sys.platform == "win32", reason="counts opens by POSIX path")
def test_an_apply_reads_each_record_file_once_and_writes_a_changed_line_twice_an_unchanged_one_once(tmp_path,
                                                                                                    capsys):
    with emulated_plant(tmp_path) as plant:
        assert run_cli(capsys, "apply", plant.path, "--auto-approve", "--allow-axis-release").code == 0
        edit(plant.path, "position: 2.0\n", "position: 1.9\n")  # booth-a-right's program 1: one line changes
        done, reads, writes, resolved = counted(tmp_path, "apply", plant.path, "--auto-approve")
        assert done.returncode == 0, done.stdout + done.stderr
        # each line's address resolved twice: once for its identity (its lock, its record), once to connect
        assert len(resolved) == 2 and set(resolved.values()) == {2}, resolved
        files = sorted((Path(os.environ["PRC3CFG_STATE_DIR"]) / "lines").glob("*.json"))
        assert len(files) == 2  # one per line: booth-a's and booth-b's
        assert reads and max(reads.values()) == 1, reads  # every record file read once
        # booth-b once (after), booth-a twice (before its write, after)
        assert sorted(writes.values()) == [1, 2], writes

        done, reads, writes, resolved = counted(tmp_path, "plan", plant.path)
        assert done.returncode == 0, done.stdout + done.stderr
        assert len(resolved) == 2 and set(resolved.values()) == {2}, resolved
        assert max(reads.values()) == 1 and sorted(writes.values()) == [1, 1], (reads, writes)


@needs_tmux
def test_a_plan_waiting_for_the_line_reads_the_record_an_apply_holding_it_left(tmp_path, capsys):
    """The record is read once the line's lock is held: a plan that waited for the line while another plant
    file's apply wrote a program there (its system block unchanged) sees that apply's record, not the one from
    before it waited — else it takes the program as it was and says "No changes" over a module holding other
    values."""
    with emulated_plant(tmp_path) as plant:
        assert run_cli(capsys, "apply", plant.path, "--auto-approve", "--allow-axis-release").code == 0
        other = tmp_path / "checkout-b" / "plant.yaml"
        other.parent.mkdir()
        other.write_text(plant.path.read_text())
        edit(other, "position: 2.0\n", "position: 1.9\n")  # booth-a-right's program 1
        pane = Pane(tmp_path, prc3cfg("apply", other), environment())
        try:
            # it holds the lines
            pane.wait(lambda screen: "Only 'yes' will be accepted:" in screen, "the apply's question")
            waiting = subprocess.Popen(prc3cfg("plan", plant.path, "--detailed-exitcode", "--lock-timeout",
                                               "600"),
                                       stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                                       env=os.environ | {"COLUMNS": "200"})
            assert waiting.stderr is not None
            told = waiting.stderr.readline()
            assert "waiting for the line lock held by" in told, told
            pane.type("yes")
            assert pane.exit_status() == 0, pane.screen()
        finally:
            pane.close()
        out, err = waiting.communicate()
        assert waiting.returncode == 2, out + err  # changes: program 1 of booth-a-right is put back
        assert "program 1: position 1.900 m → 2.000 m" in out, out
