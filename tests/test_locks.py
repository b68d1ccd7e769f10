"""One apply per line: the kernel lock, its holder's details, waiting, and the identities of a line.

Holders are real processes (`python -c` taking the lock and printing "locked"), told to let
go through their stdin; nothing is synchronised by sleeping.
"""

from __future__ import annotations

import contextlib
import json
import os
import pwd
import shutil
import signal
import socket
import stat
import subprocess
import sys
import tempfile
import uuid
from pathlib import Path

import pytest

from prc3cfg.errors import UserError
from prc3cfg.shell import locks, platform
from prc3cfg.shell.locks import LineBusy, line_keys, line_lock, lock_dir, lock_path

HOLDER = """
import json, sys
from prc3cfg.shell.locks import line_lock
with line_lock(json.loads(sys.argv[1]), "bus held"):
    print("locked", flush=True)
    sys.stdin.readline()
"""

# A process between taking the lock and writing its details: the file holds what argv[2] says.
RAW_HOLDER = """
import fcntl, os, sys
fd = os.open(sys.argv[1], os.O_RDWR | os.O_CREAT)
fcntl.flock(fd, fcntl.LOCK_EX)
os.ftruncate(fd, 0)
os.write(fd, sys.argv[2].encode())
print("locked", flush=True)
sys.stdin.readline()
"""

KEY = "tcp/127.0.0.1/7001"


@contextlib.contextmanager
def holding(*argv: str, script: str = HOLDER, env: dict[str, str] | None = None,
            command: list[str] | None = None):
    """A process that holds a lock until its stdin gets a line (or closes); `command` runs it otherwise (as
    another user)."""
    command = command or [sys.executable, "-c", script, *argv]
    process = subprocess.Popen(command, stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True, env=env,
                               cwd=Path(__file__).resolve().parents[1])
    try:
        assert process.stdout.readline() == "locked\n"
        yield process
    finally:
        with contextlib.suppress(BrokenPipeError):
            process.stdin.close()
        process.wait()


def held(*keys: str):
    return holding(json.dumps(keys))


def test_a_held_line_is_refused_naming_the_holder():
    with held(KEY) as holder:
        with pytest.raises(LineBusy) as refused:
            with line_lock((KEY,), "bus a (socket://127.0.0.1:7001)"):
                pass
    assert str(refused.value).startswith("bus a (socket://127.0.0.1:7001): the line is locked by ")
    assert f"@{socket.gethostname()} (pid {holder.pid}, apply since 20" in str(refused.value)
    assert str(refused.value).endswith(") as its lock file says — wait for it to finish, or pass "
                                       "--lock-timeout SECONDS to wait")


def test_the_lock_file_names_the_holder_while_held_and_stays():
    with line_lock((KEY,), "bus a (socket://127.0.0.1:7001)", purpose="restore") as (path,):
        record = json.loads(path.read_text())
    assert record["pid"] == os.getpid() and record["host"] == socket.gethostname()
    assert record["holder"].endswith(f"@{socket.gethostname()}") and record["since"].startswith("20")
    assert record["purpose"] == "restore" and record["line"] == "bus a (socket://127.0.0.1:7001)"
    assert path.exists() and path.read_text() == ""  # never deleted; no details of a holder that is gone


def test_other_lines_are_independent():
    with held("dev/dev/ttyUSB0"):
        with line_lock(("dev/dev/ttyUSB1",), "bus b"):
            pass


def test_the_lock_dies_with_its_process():
    with held(KEY) as holder:
        holder.send_signal(signal.SIGKILL)
        holder.wait()
        with line_lock((KEY,), "bus a") as (path,):  # at once: timeout 0
            assert json.loads(path.read_text())["pid"] == os.getpid()


@pytest.mark.parametrize("content",
                         ["", "{garbage", '{"holder": "alice@floor", "pid": 99999999, "since": "2026"}'])
def test_a_lock_file_left_behind_does_not_block(content):
    lock_path(KEY).parent.mkdir(parents=True)
    lock_path(KEY).write_text(content)
    with line_lock((KEY,), "bus a") as (path,):
        assert json.loads(path.read_text())["pid"] == os.getpid()


@pytest.mark.parametrize("content", ["", '{"holder": "alice@fl'])
def test_a_holder_that_has_not_written_its_details_is_another_process(content):
    lock_dir().mkdir(parents=True)
    with holding(str(lock_path(KEY)), content, script=RAW_HOLDER):
        with pytest.raises(LineBusy, match=r"^bus a: the line is locked by another process — wait for it"):
            with line_lock((KEY,), "bus a"):
                pass


def test_waiting_is_told_once_naming_the_holder_and_the_lock_follows_its_release():
    told = []
    with held(KEY) as holder:

        def waiting(text: str) -> None:
            told.append(text)
            holder.stdin.write("release\n")
            holder.stdin.flush()

        with line_lock((KEY,), "bus a (socket://127.0.0.1:7001)", timeout=600, waiting=waiting) as (path,):
            assert json.loads(path.read_text())["pid"] == os.getpid()
    (text,) = told
    assert text.startswith("bus a (socket://127.0.0.1:7001): waiting for the line lock held by ")
    assert (f"(pid {holder.pid}, apply since 20" in text
            and text.endswith(") as its lock file says — up to 600 s"))


def test_a_wait_that_runs_out_is_refused_and_told_once():
    told = []
    with held(KEY):
        refusal = (r"^bus a: the line is locked by .* after waiting 0.3 s — wait for it to finish, or pass "
                   r"a longer --lock-timeout$")
        with pytest.raises(LineBusy, match=refusal):
            with line_lock((KEY,), "bus a", timeout=0.3, waiting=told.append):
                pass
    assert len(told) == 1


def test_all_keys_or_none():
    with held("b"):
        with pytest.raises(LineBusy):
            with line_lock(("c", "a", "b"), "bus a"):
                pass
        with held("a"), held("c"):  # the keys taken before "b" was found busy were let go
            pass
    with line_lock(("c", "a", "b"), "bus a") as paths:
        assert sorted(paths) == list(paths) and len(paths) == 3


def test_the_lock_is_released_on_error():
    with pytest.raises(RuntimeError):
        with line_lock((KEY,), "bus a"):
            raise RuntimeError("boom")
    with held(KEY):
        pass


def test_a_port_is_not_a_key():
    with pytest.raises(TypeError, match=r"line_keys\(port\)"):
        with line_lock("socket://127.0.0.1:7001", "bus a"):
            pass


def test_shared_directory_and_files_whatever_the_umask(tmp_path, monkeypatch):
    monkeypatch.setenv("PRC3CFG_LOCK_DIR", str(tmp_path / "shared" / "locks"))
    previous = os.umask(0o077)
    try:
        with line_lock((KEY,), "bus a") as (path,):
            pass
    finally:
        os.umask(previous)
    assert stat.S_IMODE(path.parent.stat().st_mode) == 0o1777
    # every user reads who holds it; only its owner writes it
    assert stat.S_IMODE(path.stat().st_mode) == 0o644


# A process trying a lock, at once: prints "took" or the refusal.
TRIER = """
import json, sys
from prc3cfg.shell.locks import LineBusy, line_lock
try:
    with line_lock(json.loads(sys.argv[1]), "bus a"):
        print("took")
except LineBusy as busy:
    print(busy)
"""


def without_lock_dir(tmpdir) -> dict[str, str]:
    """This environment without PRC3CFG_LOCK_DIR, with its own TMPDIR (and user and home)."""
    env = {k: v for k, v in os.environ.items() if k != "PRC3CFG_LOCK_DIR"}
    tmpdir.mkdir()
    return {**env, "TMPDIR": str(tmpdir), "TMP": str(tmpdir), "TEMP": str(tmpdir), "HOME": str(tmpdir),
            "USER": tmpdir.name}


def test_the_lock_is_one_place_for_the_machine_whatever_the_environment(tmp_path):
    """Two processes with different TMPDIR, HOME and USER and no PRC3CFG_LOCK_DIR meet at one lock
    (they both took it when it followed TMPDIR); the folder is shared: sticky and open to all."""
    key = f"test/{uuid.uuid4()}"  # machine-wide: a key no other run uses
    first, second = without_lock_dir(tmp_path / "alice"), without_lock_dir(tmp_path / "bob")
    with holding(json.dumps([key]), env=first) as holder:
        tried = subprocess.run([sys.executable, "-c", TRIER, json.dumps([key])], env=second,
                               capture_output=True, text=True)
    assert (tried.stdout.startswith("bus a: the line is locked by ")
            and f"(pid {holder.pid}, " in tried.stdout), tried
    folder = Path(subprocess.run([sys.executable, "-c",
                                  "from prc3cfg.shell.locks import lock_dir; print(lock_dir())"],
                                 env=first, capture_output=True, text=True, check=True).stdout.strip())
    assert folder in (Path("/run/lock/prc3cfg"), Path("/var/lock/prc3cfg"), Path("/tmp/prc3cfg-locks"))
    assert stat.S_IMODE(folder.stat().st_mode) == 0o1777
    assert stat.S_IMODE((folder / lock_path(key).name).stat().st_mode) & 0o444 == 0o444


@pytest.mark.parametrize(
    ("shared", "chosen"),
    [
        ({"run/lock": 0o1777, "var/lock": 0o1777, "tmp": 0o1777}, "run/lock/prc3cfg"),
        # a lock folder only root writes
        ({"run/lock": 0o755, "var/lock": 0o1777, "tmp": 0o1777}, "var/lock/prc3cfg"),
        ({"run/lock": 0o755, "tmp": 0o1777}, "tmp/prc3cfg-locks"),
        # made by an administrator
        ({"run/lock": 0o755, "run/lock/prc3cfg": 0o1777, "tmp": 0o1777}, "run/lock/prc3cfg"),
        ({"tmp": 0o1777, "tmp/prc3cfg-locks": 0o1777}, "tmp/prc3cfg-locks"),
        ({}, "tmp/prc3cfg-locks"),
    ],
)
def test_the_lock_folder_is_chosen_by_the_machine_not_by_who_asks(tmp_path, monkeypatch, shared, chosen):
    for folder, mode in shared.items():
        (tmp_path / folder).mkdir(parents=True, exist_ok=True)
        (tmp_path / folder).chmod(mode)
    monkeypatch.delenv("PRC3CFG_LOCK_DIR")
    monkeypatch.setattr(locks, "LOCK_FOLDERS",
                        tuple((tmp_path / base.relative_to("/"), name) for base, name in locks.LOCK_FOLDERS))
    assert lock_dir() == tmp_path / chosen


def test_a_symlink_in_place_of_a_lock_file_is_not_followed(tmp_path):
    lock_dir().mkdir(parents=True)
    lock_path(KEY).symlink_to(tmp_path / "elsewhere")
    with pytest.raises(UserError, match=r"^bus a: cannot open the line lock .* — check the lock directory"):
        with line_lock((KEY,), "bus a"):
            pass
    assert not (tmp_path / "elsewhere").exists()


@pytest.mark.skipif(os.geteuid() == 0, reason="root writes any file")
def test_a_read_only_lock_file_is_still_locked():
    lock_dir().mkdir(parents=True)
    lock_path(KEY).write_text("")
    lock_path(KEY).chmod(0o444)
    with line_lock((KEY,), "bus a"):
        with pytest.raises(LineBusy, match="locked by another process"):
            with line_lock((KEY,), "bus a"):
                pass


# -- a lock folder no other user can take over ------------------------------------------------

ROOT = Path(__file__).resolve().parents[1]
OTHER = "prc3cfg-other"


def other_user() -> pwd.struct_passwd:
    """The user prc3cfg-other, made when absent (and left for the next run); skip where that cannot be."""
    if os.geteuid() != 0:
        pytest.skip("needs root: to run a process as another user")
    try:
        return pwd.getpwnam(OTHER)
    except KeyError:
        pass
    if shutil.which("useradd") is None:
        pytest.skip(f"no useradd to make the user {OTHER}")
    made = subprocess.run(["useradd", "--no-create-home", "--shell", "/usr/sbin/nologin", OTHER],
                          capture_output=True, text=True)
    try:
        return pwd.getpwnam(OTHER)
    except KeyError:
        pytest.skip(f"cannot make the user {OTHER}: {made.stderr.strip()}")


@pytest.fixture
def shared_locks(monkeypatch):
    """A lock folder as the machine's: root's, sticky and writable by all, in a folder every user can
    reach (the test's own tmp_path is root's alone); removed after the test."""
    outer = Path(tempfile.mkdtemp(prefix="prc3cfg-test-"))
    try:
        outer.chmod(0o755)
        monkeypatch.setenv("PRC3CFG_LOCK_DIR", str(outer / "locks"))
        yield outer / "locks"
    finally:
        shutil.rmtree(outer)


def as_other(user: pwd.struct_passwd, script: str, *argv: str) -> list[str]:
    """The command that runs `script` as `user`, with this worktree's prc3cfg."""
    setpriv = shutil.which("setpriv")
    if setpriv is None:
        pytest.skip("no setpriv to run a process as another user")
    return [setpriv, f"--reuid={user.pw_uid}", f"--regid={user.pw_gid}", "--init-groups", sys.executable,
            "-c", script, *argv]


@pytest.mark.parametrize("owner", [OTHER, "uid 54321"])
def test_a_lock_folder_another_user_owns_is_refused(owner):
    """The first user to make /run/lock/prc3cfg after a boot owns it and could remove root's locks in it
    (a second plan ran while an apply held the line): such a folder is never used."""
    if os.geteuid() != 0:
        pytest.skip("needs root: to give a folder to another user")
    uid = other_user().pw_uid if owner == OTHER else 54321
    folder = lock_dir()
    folder.mkdir(mode=0o1777)
    os.chown(folder, uid, uid)
    name = f"{OTHER} (uid {uid})" if owner == OTHER else "uid 54321"
    with pytest.raises(UserError) as refused:
        with line_lock((KEY,), "bus a"):
            pass
    assert str(refused.value) == (f"bus a: the lock directory {folder} belongs to {name}, who could remove "
                                  "the locks in it, "
                                  "so it is not used — an administrator removes it, or set "
                                  "PRC3CFG_LOCK_DIR")
    assert list(folder.iterdir()) == []


@pytest.mark.parametrize("target", ["a folder", "nothing"])
def test_a_symlink_in_place_of_the_lock_folder_is_not_followed(tmp_path, target):
    """A symlink someone put where the lock folder goes made root make world-writable files where it
    points."""
    elsewhere = tmp_path / "elsewhere"
    if target == "a folder":
        elsewhere.mkdir()
    lock_dir().symlink_to(elsewhere)
    refusal = (r"^bus a: the lock directory .*/locks is a symbolic link, not used — an administrator "
               r"removes it, or set PRC3CFG_LOCK_DIR$")
    with pytest.raises(UserError, match=refusal):
        with line_lock((KEY,), "bus a"):
            pass
    assert (list(elsewhere.iterdir()) == []) if target == "a folder" else not elsewhere.exists()


def test_a_second_name_of_another_file_is_not_a_lock_file(tmp_path):
    """A hard link planted as a lock file's name: prc3cfg wrote its details into the file it names,
    then emptied it."""
    precious = tmp_path / "shadow"
    precious.write_text("root:secret\n")
    lock_dir().mkdir()
    os.link(precious, lock_path(KEY))
    with pytest.raises(UserError,
                       match=r"^bus a: the line lock .* is a second name of another file, not used — an "
                             r"administrator"):
        with line_lock((KEY,), "bus a"):
            pass
    assert precious.read_text() == "root:secret\n"


def test_a_fifo_in_place_of_a_lock_file_is_refused_not_waited_on():
    lock_dir().mkdir()
    os.mkfifo(lock_path(KEY))
    with pytest.raises(UserError,
                       match=r"^bus a: the line lock .* is no plain file, not used — an administrator"):
        with line_lock((KEY,), "bus a"):
            pass


@pytest.mark.parametrize("holder", ["this user", OTHER])
def test_a_lock_file_replaced_between_its_open_and_its_lock_is_not_taken(shared_locks, monkeypatch, holder):
    """Between this process's open of the lock file and its lock, the file is removed and another
    process — another user's where it can run — makes a new one and holds it: this process must not
    hold the line too (it locked the removed file, and both held the line)."""
    user = other_user() if holder == OTHER else None
    shared_locks.mkdir(mode=0o1777)
    shared_locks.chmod(0o1777)
    lock_path(KEY).write_text("")
    lock_path(KEY).chmod(0o666)
    try_lock = platform.try_lock
    holders: list[subprocess.Popen] = []
    with contextlib.ExitStack() as stack:

        def replaced_first(fd: int) -> bool:
            if not holders:  # the first lock: the file is replaced before it
                lock_path(KEY).unlink()
                command = as_other(user, HOLDER, json.dumps([KEY])) if user is not None else None
                claims_root = {**os.environ, "USER": "root", "LOGNAME": "root"}  # getpass believes them
                holders.append(stack.enter_context(holding(json.dumps([KEY]), command=command,
                                                           env=claims_root)))
            return try_lock(fd)

        monkeypatch.setattr(platform, "try_lock", replaced_first)
        with pytest.raises(LineBusy) as refused:
            with line_lock((KEY,), "bus a"):
                pass
    (holder_process,) = holders
    assert str(refused.value).startswith("bus a: the line is locked by ")
    assert f"(pid {holder_process.pid}, apply since 20" in str(refused.value)
    if user is not None:  # it claims to be root, as $USER says; whose file it is, the kernel says
        assert str(refused.value).startswith("bus a: the line is locked by root@")
        assert f") as its lock file says, a file of {OTHER} (uid {user.pw_uid}) — " in str(refused.value)


def test_another_user_can_neither_remove_a_held_lock_nor_take_the_line(shared_locks):
    """The folder is sticky: another user's prc3cfg sees root's lock and waits, and cannot remove it."""
    user = other_user()
    with line_lock((KEY,), "bus a") as (path,):
        remover = ("import os, sys\ntry:\n    os.unlink(sys.argv[2])\nexcept OSError as e:\n    "
                   "print(e.strerror)\n") + TRIER
        tried = subprocess.run(as_other(user, remover, json.dumps([KEY]), str(path)), capture_output=True,
                               text=True, cwd=ROOT, timeout=60)
        assert path.exists()
    assert tried.stdout.splitlines()[0] == "Operation not permitted", tried
    assert (tried.stdout.splitlines()[1].startswith("bus a: the line is locked by ")
            and f"(pid {os.getpid()}, apply since " in tried.stdout)


# Another user's prc3cfg: takes and lets go of the line once, then removes every file of its own in
# the lock folder — as its owner may, sticky folder or not — and tries the line.
REMOVER_THEN_TRIER = """
import json, os, sys
from prc3cfg.shell.locks import line_lock, lock_dir
with line_lock(json.loads(sys.argv[1]), "bus a"):
    pass
print("made", flush=True)
sys.stdin.readline()
for name in os.listdir(lock_dir()):
    try:
        os.unlink(lock_dir() / name)
        print("removed", name, flush=True)
    except OSError:
        pass
""" + TRIER


def test_a_lock_file_another_user_made_is_never_the_one_held(shared_locks):
    """Another user made the line's lock file the first time it took the line. This process took the
    line after — on that file, which its owner may remove whoever holds it: then the owner's next prc3cfg
    made a new file of that name and held the line too. Each user now holds a file of its own and sees
    every other user's."""
    user = other_user()
    shared_locks.mkdir(mode=0o1777)
    shared_locks.chmod(0o1777)
    other = subprocess.Popen(as_other(user, REMOVER_THEN_TRIER, json.dumps([KEY])), stdin=subprocess.PIPE,
                             stdout=subprocess.PIPE,
                             text=True, cwd=ROOT)
    try:
        assert other.stdout.readline() == "made\n"  # its lock file, made and let go of
        with line_lock((KEY,), "bus a"):
            out, _ = other.communicate("go\n", timeout=60)  # it removes what it may, and tries the line
    finally:
        other.kill()
        other.wait()
    *removed, tried = out.splitlines()
    assert (removed and tried.startswith("bus a: the line is locked by ")
            and f"(pid {os.getpid()}, apply since 20" in tried), out


def test_a_lock_file_in_this_users_name_that_another_user_owns_is_refused():
    """Another user could make this user's lock file first, then remove it while this user holds it."""
    if os.geteuid() != 0:
        pytest.skip("needs root: to give a file to another user")
    lock_dir().mkdir()
    lock_path(KEY).write_text("")
    os.chown(lock_path(KEY), 54321, 54321)
    with pytest.raises(UserError) as refused:
        with line_lock((KEY,), "bus a"):
            pass
    assert str(refused.value) == (f"bus a: the line lock {lock_path(KEY)} belongs to uid 54321, who could "
                                  "remove it while this process "
                                  "holds it, so it is not used — an administrator removes it, or set "
                                  "PRC3CFG_LOCK_DIR")


def test_an_older_prc3cfgs_lock_file_is_seen():
    """prc3cfg before lock files of their own per user locked HASH.lock, every user's: still a holder."""
    lock_dir().mkdir()
    shared = lock_dir() / f"{locks._stem(KEY)}.lock"
    with holding(str(shared), "", script=RAW_HOLDER):
        with pytest.raises(LineBusy, match=r"^bus a: the line is locked by another process — wait for it"):
            with line_lock((KEY,), "bus a"):
                pass
    with line_lock((KEY,), "bus a") as (path,):
        assert path != shared


def test_a_lock_file_another_user_cannot_read_counts_as_held(shared_locks):
    user = other_user()
    with line_lock((KEY,), "bus a") as (path,):
        pass
    path.chmod(0)
    tried = subprocess.run(as_other(user, TRIER, json.dumps([KEY])), capture_output=True, text=True, cwd=ROOT,
                           timeout=60)
    assert (tried.stdout == f"bus a: the line is locked by a process of root (uid 0) (its lock file {path} "
                            "cannot be read) — wait for it to finish, or pass --lock-timeout SECONDS "
                            "to wait\n"), tried


# A racer: at every line on stdin it tries the line at once; holding it, it makes the file argv[2]
# (O_EXCL: it fails while the other racer holds the line too), keeps it 20 ms and removes it.
RACER = """
import json, os, sys, time
from prc3cfg.shell.locks import LineBusy, line_lock
for _ in sys.stdin:
    try:
        with line_lock(json.loads(sys.argv[1]), "bus a"):
            try:
                fd = os.open(sys.argv[2], os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o644)
            except FileExistsError:
                print("both", flush=True)
                continue
            time.sleep(0.02)
            os.close(fd)
            os.unlink(sys.argv[2])
            print("took", flush=True)
    except LineBusy:
        print("busy", flush=True)
"""


def test_two_users_racing_for_a_line_never_both_hold_it(shared_locks):
    """Root and prc3cfg-other try one line at the same instant, 40 times: each holds a file of its own
    and looks at the other's; the higher uid lets go, the lower waits for it a moment. Never both hold
    the line, and one of them takes it (both were refused in 73 of 200 races before the wait; after,
    in none: 169 one, 31 both one after the other). Half of the races is the bound: the wait is 50 ms,
    and CI's cores are shared."""
    user = other_user()
    shared_locks.mkdir(mode=0o1777)
    shared_locks.chmod(0o1777)
    (shared_locks.parent / "marks").mkdir(mode=0o1777)
    (shared_locks.parent / "marks").chmod(0o1777)
    inside = shared_locks.parent / "marks" / "inside"
    racers = [subprocess.Popen(command, stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True, cwd=ROOT)
              for command in ([sys.executable, "-c", RACER, json.dumps([KEY]), str(inside)],
                              as_other(user, RACER, json.dumps([KEY]), str(inside)))]
    rounds = []
    try:
        for _ in range(40):
            for racer in racers:
                racer.stdin.write("go\n")
            for racer in racers:
                racer.stdin.flush()
            rounds.append(tuple(racer.stdout.readline().strip() for racer in racers))
    finally:
        for racer in racers:
            racer.stdin.close()
            racer.wait(timeout=60)
    # "both": one made its file while the other held the line
    assert all(set(r) <= {"took", "busy"} for r in rounds), rounds
    assert sum("took" in r for r in rounds) >= len(rounds) // 2, rounds


def test_holder_details_are_shown_as_claims_with_the_file_owner():
    """Anyone who may write a lock file may write any holder into it: the message says whose claim it
    is, and whose file it is where that is not the user it claims."""
    lock_dir().mkdir()
    forged = json.dumps({"holder": "alice@floor", "pid": 1, "purpose": "apply",
                         "since": "2026-01-01T00:00:00+00:00"})
    with holding(str(lock_path(KEY)), forged, script=RAW_HOLDER):
        with pytest.raises(LineBusy) as refused:
            with line_lock((KEY,), "bus a"):
                pass
    owner = platform.uid_name(os.getuid())
    assert str(refused.value) == ("bus a: the line is locked by alice@floor (pid 1, apply since "
                                  "2026-01-01T00:00:00+00:00) as its lock "
                                  f"file says, a file of {owner} — wait for it to finish, or pass "
                                  "--lock-timeout SECONDS to wait")


# -- the identities of a line --------------------------------------------------------------


def _loopback_name() -> str:
    """This machine's name if it resolves to 127.0.0.1 only (a hosts file entry), else skip."""
    name = socket.gethostname()
    try:
        addresses = {a[4][0] for a in socket.getaddrinfo(name, 1, type=socket.SOCK_STREAM)}
    except OSError:
        addresses = set()
    if addresses != {"127.0.0.1"}:
        pytest.skip(f"{name} does not resolve to 127.0.0.1 only")
    return name


@pytest.mark.parametrize("spelling", ["localhost", "LOCALHOST", "127.1", "hostname"])
def test_spellings_of_one_address_share_a_key(spelling):
    host = _loopback_name() if spelling == "hostname" else spelling
    assert "tcp/127.0.0.1/7001" in line_keys(f"socket://{host}:7001")
    assert set(line_keys(f"socket://{host}:7001")) & set(line_keys("socket://127.0.0.1:7001"))
    assert set(line_keys(f"rfc2217://{host}:7001?logging=debug")) & set(line_keys("socket://127.0.0.1:7001"))
    assert not set(line_keys(f"socket://{host}:7002")) & set(line_keys("socket://127.0.0.1:7001"))


@pytest.mark.parametrize("spelling", ["0.0.0.0", "[::ffff:127.0.0.1]", "[::ffff:7f00:1]"])
def test_addresses_that_reach_the_loopback_share_its_key(spelling):
    assert line_keys(f"socket://{spelling}:7001") == ("tcp/127.0.0.1/7001",)
    assert line_keys("socket://[::]:7001") == ("tcp/::1/7001",)


def test_a_pyserial_wrapper_of_a_device_shares_the_device_key(tmp_path):
    device = tmp_path / "ttyUSB0"
    device.touch()
    assert line_keys(f"spy://{device}?file=/tmp/spy.txt")[1] == line_keys(str(device))[0]
    assert line_keys(f"alt://{device}?class=PosixPollSerial")[1] == line_keys(str(device))[0]


def test_a_nul_in_a_path_is_a_key_not_an_error():
    assert line_keys("/dev/ttyS0\x00x") == ("dev/'/dev/ttyS0\\x00x'",)


def test_tcp_keys():
    assert line_keys("socket://127.0.0.1:7001") == ("tcp/127.0.0.1/7001",)
    assert line_keys("socket://[::1]:7001") == ("tcp/::1/7001",)
    assert line_keys("socket://No-Such-Host.invalid:7001") == ("tcp/no-such-host.invalid/7001",)
    assert line_keys("socket://127.0.0.1:seven") == ("socket://127.0.0.1:seven",)


def test_a_device_and_a_link_to_it_share_a_key(tmp_path):
    device = tmp_path / "ttyUSB0"
    device.touch()
    (tmp_path / "by-id").mkdir()
    link = tmp_path / "by-id" / "usb-FTDI_FT232R_A50285BI-if00-port0"
    link.symlink_to(device)
    assert line_keys(str(link)) == line_keys(str(device)) == (f"dev/{os.path.realpath(device)}",)
    assert line_keys(str(tmp_path / "ttyUSB1")) != line_keys(str(device))
    with held(*line_keys(str(link))):
        with pytest.raises(LineBusy):
            with line_lock(line_keys(str(device)), "bus a"):
                pass


def test_an_emulator_is_known_by_its_state_file(tmp_path):
    (tmp_path / "plant" / ".prc3cfg" / "emulators").mkdir(parents=True)
    (tmp_path / "checkout").symlink_to(tmp_path / "plant")
    state = tmp_path / "plant" / ".prc3cfg" / "emulators" / "demo-a.json"
    via_link = tmp_path / "checkout" / ".prc3cfg" / "emulators" / "demo-a.json"
    assert line_keys("emulator://demo-a", emulator_state=via_link) == (f"emulator/{os.path.realpath(state)}",)
    assert (line_keys("emulator://demo-a", emulator_state=state)
            != line_keys("emulator://demo-b", emulator_state=state.with_name("demo-b.json")))
    with pytest.raises(ValueError, match="emulator_state"):
        line_keys("emulator://demo-a")


def test_any_other_url_is_its_own_key():
    assert line_keys("loop://") == ("loop://",)
    assert line_keys("spy:///dev/ttyUSB0")[0] == "spy:///dev/ttyUSB0"
