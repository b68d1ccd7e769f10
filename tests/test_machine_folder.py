"""The machine's folder of records (`prc3cfg.shell.releases`, `prc3cfg.shell.bases`): every user of a
line sees the axis releases and what the modules hold, once an administrator made it
(`prc3cfg setup-machine`); until then each user's records are their own, and a command on a real line
says so in one line. Another user's file there vouches for nothing, but tells that a module changed.

Across real processes: root and the user prc3cfg-other (made when absent, as the lock tests do) on
one emulated line, through socket://.
"""

from __future__ import annotations

import grp
import os
import pwd
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


def made(folder: Path) -> Path:
    folder.mkdir()
    return folder


def unshared_note(err: str) -> list[str]:
    return [line for line in err.splitlines() if line.startswith("note: ") and "setup-machine" in line]


def test_without_the_machine_s_folder_records_are_the_user_s_and_a_command_on_a_line_says_so_once(machine, capsys):
    with emulated_plant(made(machine / "a")) as plant:
        planned = run_cli(capsys, "plan", plant.path)
        assert planned.code == 0, planned.err
        (note,) = unshared_note(planned.err)
        assert str(machine / "root-state" / "prc3cfg") in note and f"{machine / 'machine'} is not there" in note
        assert list((machine / "root-state" / "prc3cfg" / "lines").glob("*.json"))  # the record is kept all the same
        assert not (machine / "machine").exists()  # never made on the way
    shown = run_cli(capsys, "plan", ROOT / "plants" / "demo-line.yaml", "--out", machine / "plan.json")
    assert shown.code == 0 and not unshared_note(shown.err)  # an emulator:// line is nobody else's


@pytest.mark.skipif(not hasattr(os, "geteuid") or os.geteuid() != 0, reason="giving a folder to a group takes root")
def test_setup_machine_makes_the_shared_folder_and_the_records_go_there(machine, capsys):
    setup = run_cli(capsys, "setup-machine", "--group", "dialout")
    assert setup.code == 0, setup.err
    assert setup.out.strip() == (f"{machine / 'machine'}: the records of axis releases and of what the modules hold, shared by the "
                                "group dialout — each user's files their own")  # fmt: skip
    for folder in (machine / "machine", machine / "machine" / "releases", machine / "machine" / "lines"):
        status = folder.lstat()
        assert stat.S_IMODE(status.st_mode) == 0o3775 and status.st_uid == 0 and status.st_gid == grp.getgrnam("dialout").gr_gid
    with emulated_plant(made(machine / "a")) as plant:
        planned = run_cli(capsys, "plan", plant.path)
        assert planned.code == 0 and not unshared_note(planned.err)
        assert [p.name.split(".")[1] for p in (machine / "machine" / "lines").glob("*.json")] == ["0", "0"]  # root's, per identity
    assert run_cli(capsys, "setup-machine", "--group", "no-such-group-here").err.startswith(
        "error: there is no group no-such-group-here on this machine — name the group of the lines' users with --group")


@pytest.mark.skipif(not hasattr(os, "geteuid") or os.geteuid() != 0, reason="giving a folder to another user takes root")
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
        assert (f"{lines} belongs to {user.pw_name} (uid {user.pw_uid}), not to root" if taken != "a link" else f"{lines} is not a folder") in note
    assert not list((machine / "elsewhere").glob("*")) if taken == "a link" else not list(lines.glob("*"))


@pytest.fixture(scope="session")
def packages(tmp_path_factory) -> Path:
    """prc3cfg's dependencies where another user can import them: a world-readable copy of every
    third-party package the command line loads — this Python's own may lie in root's home, mode 700
    (CI's pyenv does), where another user's interpreter does not find them."""
    import prc3cfg.cli  # noqa: F401  (everything a command imports)

    folder = Path(tempfile.mkdtemp(prefix="prc3cfg-packages-"))
    for module in list(sys.modules.values()):
        file = Path(getattr(module, "__file__", None) or "/")
        if "site-packages" not in file.parts or ROOT in file.parents:
            continue
        site = Path(*file.parts[: file.parts.index("site-packages") + 1])
        top = site / file.relative_to(site).parts[0]
        if not (folder / top.name).exists():
            (shutil.copytree if top.is_dir() else shutil.copy2)(top, folder / top.name)
    for path in [folder, *folder.rglob("*")]:
        path.chmod(0o755 if path.is_dir() else 0o644)
    yield folder
    shutil.rmtree(folder)


def as_user(user: pwd.struct_passwd, machine: Path, packages: Path, *argv: str) -> subprocess.CompletedProcess[str]:
    """`prc3cfg ARGV` run as `user`, on this machine's folders, with this worktree's prc3cfg."""
    setpriv = shutil.which("setpriv")
    if setpriv is None:
        pytest.skip("no setpriv to run a process as another user")
    env = {**os.environ, "HOME": str(machine / "home"), "XDG_STATE_HOME": str(machine / "home" / "state"),
           "PYTHONPATH": os.pathsep.join([str(ROOT), str(packages)])}  # fmt: skip
    return subprocess.run([setpriv, f"--reuid={user.pw_uid}", f"--regid={user.pw_gid}", "--init-groups", sys.executable, *argv],
                          capture_output=True, text=True, env=env, cwd=machine, timeout=120)  # fmt: skip


@pytest.mark.skipif(not hasattr(os, "geteuid") or os.geteuid() != 0, reason="running a process as another user takes root")
def test_what_another_user_wrote_on_the_line_is_seen_and_their_record_vouches_for_nothing(machine, packages, capsys):
    """Root applied plant file A; the user prc3cfg-other applies plant file B, which sets module 2's
    program 2 otherwise. Root's next plan of A must not take its own older record for the truth: it
    reads the modules B's run read or wrote in full, says whose claim made it, and plans A's value back. An axis release
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
        b.write_text(plant.path.read_text().replace("position: 2.0\n", "position: 1.9\n", 1))  # booth-a-right's program 1
        os.chown(b, user.pw_uid, user.pw_gid)
        theirs = as_user(user, machine, packages, "-m", "prc3cfg", "apply", str(b), "--auto-approve", "--allow-axis-release")
        assert theirs.returncode == 0, theirs.stderr
        assert not unshared_note(theirs.stderr)
        assert {p.stat().st_uid for p in (machine / "machine" / "lines").glob("*.json")} == {0, user.pw_uid}
        again = run_cli(capsys, "plan", plant.path, "--detailed-exitcode")
        assert again.code == 2, again.out + again.err
        assert "another user's record is newer (it claims: apply of " in again.out and f"by {user.pw_name}@" in again.out
        assert "program 1: position 1.900 m → 2.000 m" in again.out
        # a release their run recorded and never told (killed after its 20h) is told to root's plan
        keys = bus_line_keys(plant.plant, plant.plant.buses[0])
        script = ("import sys; from prc3cfg.shell.releases import Releases; "
                  "Releases('apply').record(tuple(sys.argv[1:]), 'booth-a', 2, 'booth-a-right')")  # fmt: skip
        recorded = as_user(user, machine, packages, "-c", script, *keys)
        assert recorded.returncode == 0, recorded.stderr
        told = run_cli(capsys, "plan", plant.path)
        assert any("bus booth-a, module 2 (booth-a-right): prc3cfg apply" in line and "its axes may be released" in line
                   for line in told.err.splitlines())  # fmt: skip
