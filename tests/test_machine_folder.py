"""The machine's folder of records (`prc3cfg.shell.machine_folder`, `prc3cfg.shell.pending_records`,
`prc3cfg.shell.line_record`): every user of a line sees the axis releases and what the modules hold, once an
administrator made it (`prc3cfg setup-machine`); until then each user's records are their own, and a command
on a real line says so in one line. Another user's file there vouches for nothing, but tells that a module
changed.

Across real processes: root and the user prc3cfg-other (made when absent, as the lock tests do) on
one emulated line, through socket://.
"""

from __future__ import annotations

import contextlib
import grp
import os
import pwd
import re
import shutil
import stat
import subprocess
import sys
import tempfile
from pathlib import Path

import pytest
from emulated import emulated_plant, run_cli
from test_locks import ROOT, other_user

from prc3cfg.shell.sessions import bus_line_keys


@pytest.fixture
def machine(monkeypatch):
    """A machine's folder to be made (PRC3CFG_MACHINE_STATE_DIR) and root's own state folder, in a folder
    every user can reach; PRC3CFG_STATE_DIR unset, as on a real machine."""
    outer = Path(tempfile.mkdtemp(prefix="prc3cfg-test-"))
    try:
        outer.chmod(0o755)
        monkeypatch.delenv("PRC3CFG_STATE_DIR", raising=False)
        monkeypatch.setenv("PRC3CFG_MACHINE_STATE_DIR", str(outer / "machine"))
        monkeypatch.setenv("XDG_STATE_HOME", str(outer / "root-state"))
        monkeypatch.setenv("PRC3CFG_LOCK_DIR", str(outer / "locks"))
        yield outer
    finally:
        shutil.rmtree(outer)


def plant_unreadable(path: Path, kind: str, size: int) -> None:
    """What another user may leave in the records' folders that is no regular file of a bounded size: a FIFO
    (`fifo`), a link to /dev/zero (`zero`), a sparse file of `size` bytes (`sparse`), a folder (`folder`)."""
    if kind == "fifo":
        os.mkfifo(path)
    elif kind == "zero":
        path.symlink_to("/dev/zero")
    elif kind == "sparse":
        with open(path, "wb") as file:
            file.truncate(size)
    else:
        path.mkdir()


def made(folder: Path) -> Path:
    folder.mkdir()
    return folder


def unshared_note(err: str) -> list[str]:
    return [line for line in err.splitlines() if line.startswith("note: ") and "setup-machine" in line]


def test_without_the_machine_s_folder_records_are_the_user_s_and_a_command_on_a_line_says_so_once(
    machine, capsys
):
    with emulated_plant(made(machine / "a")) as plant:
        planned = run_cli(capsys, "plan", plant.path)
        assert planned.code == 0, planned.err
        (note,) = unshared_note(planned.err)
        assert (str(machine / "root-state" / "prc3cfg") in note
                and f"{machine / 'machine'} is not there" in note)
        # the record is kept all the same
        assert list((machine / "root-state" / "prc3cfg" / "lines").glob("*.json"))
        assert not (machine / "machine").exists()  # never made on the way
    shown = run_cli(capsys, "plan", ROOT / "plants" / "demo-line.yaml", "--out", machine / "plan.json")
    assert shown.code == 0 and not unshared_note(shown.err)  # an emulator:// line is nobody else's


@pytest.mark.skipif(not hasattr(os, "geteuid") or os.geteuid() != 0,
                    reason="giving a folder to a group takes root")
def test_setup_machine_makes_the_shared_folder_and_the_records_go_there(machine, capsys):
    setup = run_cli(capsys, "setup-machine", "--group", "dialout")
    assert setup.code == 0, setup.err
    assert setup.out.strip() == (f"{machine / 'machine'}: the records of axis releases and of what the "
                                 "modules hold, shared by the "
                                "group dialout — each user's files their own")
    for folder in (machine / "machine", machine / "machine" / "releases", machine / "machine" / "lines"):
        status = folder.lstat()
        assert (stat.S_IMODE(status.st_mode) == 0o3775 and status.st_uid == 0
                and status.st_gid == grp.getgrnam("dialout").gr_gid)
    with emulated_plant(made(machine / "a")) as plant:
        planned = run_cli(capsys, "plan", plant.path)
        assert planned.code == 0 and not unshared_note(planned.err)
        # root's, per identity
        assert [p.name.split(".")[1] for p in (machine / "machine" / "lines").glob("*.json")] == ["0", "0"]
    assert run_cli(capsys, "setup-machine", "--group", "no-such-group-here").err.startswith(
        "error: there is no group no-such-group-here on this machine — name the group of the lines' users "
        "with --group")


@pytest.mark.skipif(not hasattr(os, "geteuid") or os.geteuid() != 0,
                    reason="giving a folder to another user takes root")
@pytest.mark.parametrize("taken", ["another user's", "a link"])
def test_a_machine_folder_another_user_could_subvert_is_not_used(machine, capsys, taken):
    user = other_user()
    assert run_cli(capsys, "setup-machine", "--group", "dialout").code == 0
    lines = machine / "machine" / "lines"
    if taken == "a link":
        shutil.rmtree(lines)
        (machine / "elsewhere").mkdir(mode=0o777)
        lines.symlink_to(machine / "elsewhere")
    else:
        os.chown(lines, user.pw_uid, user.pw_gid)
    with emulated_plant(made(machine / "a")) as plant:
        planned = run_cli(capsys, "plan", plant.path)
        assert planned.code == 0, planned.err
        (note,) = unshared_note(planned.err)
        assert (f"{lines} belongs to {user.pw_name} (uid {user.pw_uid}), not to root"
                if taken != "a link" else f"{lines} is not a folder") in note
    assert not list((machine / "elsewhere").glob("*")) if taken == "a link" else not list(lines.glob("*"))


#: Prints the top folder (or file) in site-packages of every third-party module prc3cfg's modules import, one
#: a line.
THIRD_PARTY = """
import importlib, pkgutil, sys
from pathlib import Path
import prc3cfg.cli, rich.progress  # rich: imported by a command only once it shows progress
prc3cfg.cli._register_commands()  # every command's module
# what the commands import as they run
for package in ("prc3cfg.api", "prc3cfg.core", "prc3cfg.plant", "prc3cfg.shell"):
    for found in pkgutil.walk_packages(importlib.import_module(package).__path__, package + "."):
        importlib.import_module(found.name)
for module in list(sys.modules.values()):
    file = Path(getattr(module, "__file__", None) or "/")
    if "site-packages" in file.parts and "prc3cfg" not in file.parts:
        site = Path(*file.parts[: file.parts.index("site-packages") + 1])
        print(site / file.relative_to(site).parts[0])
"""


#: The tests of another user's interpreter, on one worker: the copy of `packages` is made once a session, not
#: once a worker.
ONE_COPY = pytest.mark.xdist_group("packages")


@pytest.fixture(scope="session")
def packages(tmp_path_factory) -> Path:
    """prc3cfg's dependencies where another user can import them: a world-readable copy of every
    third-party package prc3cfg's modules import — this Python's own may lie in root's home, mode 700
    (CI's pyenv does), where another user's interpreter does not find them. Found by a fresh interpreter:
    a test worker's own modules (hypothesis, matplotlib, numpy, … whatever its earlier tests loaded) made
    the copy 150 MB and 13 s of a worker's time, and different from one worker to the next."""
    listed = subprocess.run([sys.executable, "-c", THIRD_PARTY], capture_output=True, text=True,
                            check=True).stdout.split()
    folder = Path(tempfile.mkdtemp(prefix="prc3cfg-packages-"))
    for top in map(Path, dict.fromkeys(listed)):
        (shutil.copytree if top.is_dir() else shutil.copy2)(top, folder / top.name)
    for path in [folder, *folder.rglob("*")]:
        path.chmod(0o755 if path.is_dir() else 0o644)
    yield folder
    shutil.rmtree(folder)


def as_user(user: pwd.struct_passwd, machine: Path, packages: Path,
            *argv: str) -> subprocess.CompletedProcess[str]:
    """`prc3cfg ARGV` run as `user`, on this machine's folders, with this worktree's prc3cfg."""
    setpriv = shutil.which("setpriv")
    if setpriv is None:
        pytest.skip("no setpriv to run a process as another user")
    env = {**os.environ, "HOME": str(machine / "home"), "XDG_STATE_HOME": str(machine / "home" / "state"),
           "PYTHONPATH": os.pathsep.join([str(ROOT), str(packages)])}
    return subprocess.run([setpriv, f"--reuid={user.pw_uid}", f"--regid={user.pw_gid}", "--init-groups",
                           sys.executable, *argv],
                          capture_output=True, text=True, env=env, cwd=machine, timeout=120)


@ONE_COPY
@pytest.mark.skipif(not hasattr(os, "geteuid") or os.geteuid() != 0,
                    reason="running a process as another user takes root")
def test_what_another_user_wrote_on_the_line_is_seen_and_their_record_vouches_for_nothing(machine, packages,
                                                                                          capsys):
    """Root applied plant file A; the user prc3cfg-other applies plant file B, which sets module 2's program 2
    otherwise. Root's next plan of A must not take its own older record for the truth: it reads the modules
    B's run read or wrote in full, says whose claim made it, and plans A's value back. An axis release
    prc3cfg-other's run left untold is told to root."""
    user = other_user()
    assert run_cli(capsys, "setup-machine", "--group", grp.getgrgid(user.pw_gid).gr_name).code == 0
    home = machine / "home"
    home.mkdir()
    os.chown(home, user.pw_uid, user.pw_gid)
    with emulated_plant(made(machine / "a")) as plant:
        assert run_cli(capsys, "apply", plant.path, "--auto-approve", "--allow-axis-release").code == 0
        assert run_cli(capsys, "plan", plant.path, "--detailed-exitcode").code == 0
        b = home / "b.yaml"
        # booth-a-right's program 1
        b.write_text(plant.path.read_text().replace("position: 2.0\n", "position: 1.9\n", 1))
        os.chown(b, user.pw_uid, user.pw_gid)
        theirs = as_user(user, machine, packages, "-m", "prc3cfg", "apply", str(b), "--auto-approve",
                         "--allow-axis-release")
        assert theirs.returncode == 0, theirs.stderr
        assert not unshared_note(theirs.stderr)
        assert {p.stat().st_uid for p in (machine / "machine" / "lines").glob("*.json")} == {0, user.pw_uid}
        again = run_cli(capsys, "plan", plant.path, "--detailed-exitcode")
        assert again.code == 2, again.out + again.err
        # whose apply its values rest on ...
        assert "another user's record is newer (it claims: apply of " in again.out
        assert f"written by {user.pw_name} (uid {user.pw_uid})" in again.out  # ... and whose file says so
        assert "program 1: position 1.900 m → 2.000 m" in again.out
        # a release their run recorded and never told (killed after its 20h) is told to root's plan
        keys = bus_line_keys(plant.plant, plant.plant.buses[0])
        script = ("import sys; from prc3cfg.shell.pending_records import Releases; "
                  "Releases('apply').record(tuple(sys.argv[1:]), 'booth-a', 2, 'booth-a-right')")
        recorded = as_user(user, machine, packages, "-c", script, *keys)
        assert recorded.returncode == 0, recorded.stderr
        told = run_cli(capsys, "plan", plant.path)
        assert any("bus booth-a, module 2 (booth-a-right): prc3cfg apply" in line
                   and "its axes may be released" in line
                   for line in told.err.splitlines())


# -- other users' records are claims: shared for reading, never trusted, never a reason to write ----------

#: A user besides prc3cfg-other, in its group: two users of one line, neither of them root.
THIRD = "prc3cfg-third"
needs_root = pytest.mark.skipif(not hasattr(os, "geteuid") or os.geteuid() != 0,
                                reason="running a process as another user takes root")


def third_user(group: int) -> pwd.struct_passwd:
    """The user prc3cfg-third in the group `group`, made when absent (and left for the next run, as
    prc3cfg-other is)."""
    with contextlib.suppress(KeyError):
        return pwd.getpwnam(THIRD)
    if shutil.which("useradd") is None:
        pytest.skip(f"no useradd to make the user {THIRD}")
    made = subprocess.run(["useradd", "--no-create-home", "--shell", "/usr/sbin/nologin", "--gid", str(group),
                           THIRD],
                          capture_output=True, text=True)
    try:
        return pwd.getpwnam(THIRD)
    except KeyError:
        pytest.skip(f"cannot make the user {THIRD}: {made.stderr.strip()}")


def home_of(user: pwd.struct_passwd, machine: Path) -> Path:
    """The user's own folder on this machine (their HOME and state folder), made on first use."""
    home = machine / f"home-{user.pw_name}"
    if not home.exists():
        home.mkdir()
        os.chown(home, user.pw_uid, user.pw_gid)
    return home


def run_as(user: pwd.struct_passwd, machine: Path, packages: Path, *argv: object,
           timeout: float = 120) -> subprocess.CompletedProcess[str]:
    """`python ARGV` run as `user` with their own HOME and state folder, on this machine's shared folders."""
    setpriv = shutil.which("setpriv")
    if setpriv is None:
        pytest.skip("no setpriv to run a process as another user")
    home = home_of(user, machine)
    env = {**os.environ, "HOME": str(home), "XDG_STATE_HOME": str(home / "state"),
           "PYTHONPATH": os.pathsep.join([str(ROOT), str(packages)])}
    return subprocess.run([setpriv, f"--reuid={user.pw_uid}", f"--regid={user.pw_gid}", "--init-groups",
                           sys.executable, *map(str, argv)],
                          capture_output=True, text=True, env=env, cwd=home, timeout=timeout)


def plant_of(user: pwd.struct_passwd, machine: Path, text: str, name: str = "plant.yaml") -> Path:
    """A plant file of `user`'s, in their folder (its records go beside it)."""
    path = home_of(user, machine) / name
    path.write_text(text)
    os.chown(path, user.pw_uid, user.pw_gid)
    return path


def record(user: pwd.struct_passwd, machine: Path, packages: Path, keys: tuple[str, ...], bus: str,
           address: int, name: str,
           kind: str = "release") -> None:
    """A record of `kind` (an axis release, an E12) that `user` writes through prc3cfg into the machine's
    folder."""
    script = ("import sys; from prc3cfg.shell.pending_records import Releases; "
              "Releases('apply').record(tuple(sys.argv[5:]), sys.argv[1], int(sys.argv[2]), sys.argv[3], "
              "sys.argv[4])")
    recorded = run_as(user, machine, packages, "-c", script, bus, address, name, kind, *keys)
    assert recorded.returncode == 0, recorded.stderr


#: What a terminal would take for a command: C0/C1 controls, bidi overrides, line separators.
RAW = re.compile("[\x00-\x08\x0b-\x1f\x7f-\x9f\u2028\u2029\u202a-\u202e\u2066-\u2069\u200e\u200f\u061c]")


@ONE_COPY
@needs_root
@pytest.mark.parametrize("writer", ["root", THIRD])
def test_a_user_sees_the_newer_apply_another_user_of_the_line_made(machine, packages, capsys, writer):
    """User A (prc3cfg-other) applied plant file A; then root, or another user of A's group, applies plant
    file B to module 2 of the same line. A's next plan must see it — their line record is readable by every
    user of the line — and plan A's value back; their apply must write it."""
    a = other_user()
    assert run_cli(capsys, "setup-machine", "--group", grp.getgrgid(a.pw_gid).gr_name).code == 0
    (machine / "locks").mkdir()
    (machine / "locks").chmod(0o1777)  # the lock folder as a boot leaves it, for whoever runs first
    with emulated_plant(made(machine / "plant")) as plant:
        text = plant.path.read_text()
        mine = plant_of(a, machine, text)
        applied = run_as(a, machine, packages, "-m", "prc3cfg", "apply", mine, "--auto-approve",
                         "--allow-axis-release")
        assert applied.returncode == 0, applied.stderr
        assert run_as(a, machine, packages, "-m", "prc3cfg", "plan", mine,
                      "--detailed-exitcode").returncode == 0
        theirs_text = text.replace("position: 2.0\n", "position: 1.9\n", 1)  # booth-a-right's program 1
        if writer == "root":
            (machine / "b").mkdir()
            (machine / "b" / "plant.yaml").write_text(theirs_text)
            assert run_cli(capsys, "apply", machine / "b" / "plant.yaml", "--auto-approve",
                           "--allow-axis-release").code == 0
        else:
            b = third_user(a.pw_gid)
            theirs = run_as(b, machine, packages, "-m", "prc3cfg", "apply", plant_of(b, machine, theirs_text),
                            "--auto-approve",
                            "--allow-axis-release")
            assert theirs.returncode == 0, theirs.stderr
        again = run_as(a, machine, packages, "-m", "prc3cfg", "plan", mine, "--detailed-exitcode")
        assert again.returncode == 2, again.stdout + again.stderr
        # readable by the group, written by their maker alone
        for path in (machine / "machine" / "lines").glob("*.json"):
            assert stat.S_IMODE(path.stat().st_mode) == 0o640 and path.stat().st_gid == a.pw_gid, path
        assert "program 1: position 1.900 m → 2.000 m" in again.stdout
        if writer != "root":  # a claim: it makes A read, and the plan says whose
            assert ("another user's record is newer (it claims: apply of " in again.stdout
                    and f"written by {THIRD} (uid" in again.stdout)
        back = run_as(a, machine, packages, "-m", "prc3cfg", "apply", mine, "--auto-approve",
                      "--allow-axis-release")
        assert back.returncode == 0 and "Nothing to do" not in back.stdout, back.stdout + back.stderr
        assert plant.matches_plant()


@ONE_COPY
@needs_root
def test_another_user_s_release_record_is_told_as_their_claim_escaped(machine, packages, capsys):
    """prc3cfg-other's release record for module 2 whose fields hold terminal commands (erase the line
    above) must not erase root's own warning of its real release: it is told escaped, as their claim."""
    user = other_user()
    assert run_cli(capsys, "setup-machine", "--group", grp.getgrgid(user.pw_gid).gr_name).code == 0
    with emulated_plant(made(machine / "a")) as plant:
        assert run_cli(capsys, "apply", plant.path, "--auto-approve", "--allow-axis-release").code == 0
        keys = bus_line_keys(plant.plant, plant.plant.buses[0])
        from prc3cfg.shell.pending_records import Releases

        # root's own, real: a run killed after its 20h
        Releases("apply").record(keys, "booth-a", 2, "booth-a-right")
        record(user, machine, packages, keys, "\x1b[1A\x1b[2K\x1b[1A\x1b[2Kbooth-a\u202e", 1,
               "all good\u2028\x9b2J")
        told = run_cli(capsys, "plan", plant.path)
        assert told.code == 0, told.err
        assert not RAW.search(told.err + told.out)
        warnings = [line for line in told.err.splitlines() if "its axes may be released" in line]
        assert any(line.startswith("⚠ warning: bus booth-a, module 2 (booth-a-right): prc3cfg apply")
                   for line in warnings), told.err
        (claim,) = [line for line in warnings if "\\x1b[1A" in line]
        assert (f"{user.pw_name} (uid {user.pw_uid})'s record says: " in claim and "\\u202e" in claim
                and "\\u2028\\x9b2J" in claim)


@ONE_COPY
@needs_root
def test_another_user_s_e12_record_makes_prc3cfg_read_never_write(machine, packages, capsys):
    """A forged E12 record for module 2 from prc3cfg-other: root's plan reads the module in full, saying
    whose claim made it, and plans no 10h/20h for it — nor does any apply release its axes."""
    user = other_user()
    assert run_cli(capsys, "setup-machine", "--group", grp.getgrgid(user.pw_gid).gr_name).code == 0
    with emulated_plant(made(machine / "a")) as plant:
        assert run_cli(capsys, "apply", plant.path, "--auto-approve", "--allow-axis-release").code == 0
        plant.emulators["booth-a"].update(2, referenced=True)  # travelled to the reference point since
        record(user, machine, packages, bus_line_keys(plant.plant, plant.plant.buses[0]), "booth-a", 2,
               "booth-a-right", "e12")
        for _ in range(2):  # on every run
            planned = run_cli(capsys, "plan", plant.path, "--detailed-exitcode")
            assert planned.code == 0, planned.out + planned.err
            assert (f"booth-a/booth-a-right ({user.pw_name} (uid {user.pw_uid})'s record says it "
                    "reported E12") in planned.out
            applied = run_cli(capsys, "apply", plant.path, "--auto-approve", "--allow-axis-release")
            assert applied.code == 0 and "Nothing to do" in applied.out, applied.out + applied.err
            assert plant.emulators["booth-a"].module(2).referenced


@pytest.mark.parametrize("kind", ["fifo", "zero", "sparse", "folder"])
def test_a_planted_file_in_the_records_folders_neither_hangs_nor_breaks_a_command(machine, kind):
    """A FIFO, a link to /dev/zero, a 3 GB sparse file or a folder among the axis-release records and
    line records: every command on every line still runs to its end, with no traceback — the file is
    passed over, and said so."""
    state = machine / "root-state" / "prc3cfg"
    with emulated_plant(made(machine / "a")) as plant:
        def cli(*argv: str) -> subprocess.CompletedProcess[str]:
            done = subprocess.run([sys.executable, "-m", "prc3cfg", *argv], capture_output=True, text=True,
                                  timeout=120, cwd=machine,
                                  env={**os.environ, "PYTHONPATH": str(ROOT)})
            assert "Traceback" not in done.stderr, done.stderr
            return done

        assert cli("apply", str(plant.path), "--auto-approve", "--allow-axis-release").returncode == 0
        stem = sorted(path.name.split(".")[0] for path in (state / "lines").glob("*.json"))[0]
        planted = [state / "releases" / "20990101T000000.000000Z-1.jsonl",
                   state / "lines" / f"{stem}.4242.json"]
        for path in planted:
            # sparse: 256 MiB of nothing — read whole, a 3 GB one ended in MemoryError
            plant_unreadable(path, kind, 2**28)
        planned = cli("plan", str(plant.path), "--detailed-exitcode")
        assert planned.returncode == 0, planned.stdout + planned.stderr
        assert "taken as known" in planned.stdout  # this user's own record still counts
        # passed over, and said so
        assert any(str(planted[0]) in line for line in planned.stderr.splitlines())


@ONE_COPY
@needs_root
def test_a_file_planted_at_a_user_s_record_name_in_the_shared_folder_does_not_lock_them_out(machine, packages,
                                                                                            capsys):
    """In the sticky machine's folder user A cannot move another user's file away: where one stands at A's
    record name, A's record goes to the next free name — said in one line — and A's plans go on using it."""
    a = other_user()
    assert run_cli(capsys, "setup-machine", "--group", grp.getgrgid(a.pw_gid).gr_name).code == 0
    (machine / "locks").mkdir()
    (machine / "locks").chmod(0o1777)
    with emulated_plant(made(machine / "plant")) as plant:
        mine = plant_of(a, machine, plant.path.read_text())
        assert run_as(a, machine, packages, "-m", "prc3cfg", "apply", mine, "--auto-approve",
                      "--allow-axis-release").returncode == 0
        names = sorted((machine / "machine" / "lines").glob(f"*.{a.pw_uid}.json"))
        # the names stand empty a moment (a record not kept yet): another user's FIFO takes them
        for path in names:
            path.unlink()
            os.mkfifo(path)
            os.lchown(path, 4242, 4242)
        planned = run_as(a, machine, packages, "-m", "prc3cfg", "plan", mine, "--detailed-exitcode",
                         timeout=60)
        assert planned.returncode == 0, planned.stdout + planned.stderr
        notes = [line for line in planned.stderr.splitlines() if "cannot be moved aside" in line]
        assert len(notes) == len(names) and all(".tmp" not in line and "instead" in line
                                                for line in notes), planned.stderr
        for path in names:
            fresh = path.with_name(path.name.replace(".json", ".1.json"))
            assert fresh.is_file() and fresh.stat().st_uid == a.pw_uid and stat.S_ISFIFO(path.lstat().st_mode)
        again = run_as(a, machine, packages, "-m", "prc3cfg", "plan", mine, "--detailed-exitcode", timeout=60)
        assert again.returncode == 0 and "taken as known" in again.stdout, again.stdout + again.stderr
