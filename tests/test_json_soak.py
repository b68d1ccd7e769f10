"""apply --json under faults (issue 42, item 4), seeded and bounded: a random part of the demo plant applied
through a line that loses a random one of the plan's messages (or its reply) a few times or every time, so
that some runs verify and some fail (of the 20 seeds, 3 fail). Every event must validate against
schemas/event.schema.json, and the stream must tell the same story as the exit code and stderr:

- the last event is the account, its `exit` the process's exit code, its `errors` the `error:` lines on
  stderr;
- `verified` exactly when every module event verified and the exit code is 0;
- a module called verified reads back as the plant file says, on the emulator too;
- each module has one event, and every module whose axes were (or may have been) released is on the travel
  list.

The first seeds run in the fast tier; all under `-m soak`.
"""

from __future__ import annotations

import json
import random

import pytest
from emulated import emulated_plant, run_cli
from lossy import Loss, lose_replies_to
from test_cli_json import events

from prc3cfg.shell.plant_files import load_plant

FAST = 2  # seeds in the fast tier
BUSES = ("booth-a", "booth-b")


def seeds(count: int = 20) -> list:
    return [seed if seed < FAST else pytest.param(seed, marks=pytest.mark.soak) for seed in range(count)]


def planned_messages(tmp_path, capsys, modules: list[str]) -> list[tuple[str, int, int]]:
    """(bus, address, message ID) of every step the plan of `modules` has, on a line without faults."""
    (tmp_path / "planned").mkdir()
    with emulated_plant(tmp_path / "planned") as plant:
        picked = [arg for name in modules for arg in ("--module", name)]
        document = json.loads(run_cli(capsys, "plan", plant.path, "--json", *picked).out)
    return [(bus["name"], module["address"], int(step["message"][:2], 16))
            for bus in document["buses"] for module in bus["modules"] for step in module["steps"]]


@pytest.mark.parametrize("seed", seeds())
def test_the_event_stream_tells_what_the_exit_code_and_the_modules_tell(tmp_path, capsys, seed):
    chooser = random.Random(seed)
    names = [module.name for _, module in load_plant_modules()]
    modules = sorted(chooser.sample(names, chooser.randint(1, len(names)))) if chooser.random() < 0.5 else []
    bus, address, message = chooser.choice(planned_messages(tmp_path, capsys, modules))
    rule = lose_replies_to(message, address=address, times=chooser.choice([1, 3, 8, None]),
                           loss=chooser.choice([Loss.REQUEST, Loss.REPLY]))
    (tmp_path / "run").mkdir()
    with emulated_plant(tmp_path / "run", lossy={bus: rule}) as plant:
        picked = [arg for name in modules for arg in ("--module", name)]
        result = run_cli(capsys, "apply", plant.path, "--json", "--auto-approve", "--allow-axis-release",
                         "--retries", "3", *picked)
        held = plant.images()
    found = events(result.out)
    assert "Traceback" not in result.err
    account = found[-1]
    assert account["event"] == "account" and [e["event"] for e in found].count("account") == 1
    assert account["exit"] == result.code
    assert [f"error: {line}" for line in account["errors"]] == [line for line in result.problems
                                                                if line.startswith("error: ")]
    ran = [e for e in found if e["event"] == "module"]
    assert len({(e["bus"], e["address"]) for e in ran}) == len(ran)
    succeeded = result.code == 0 and all(e["result"] != "failed" for e in ran)
    assert (account["status"] == "verified") == succeeded, (account, ran)
    assert account["status"] in ("verified", "failed", "refused"), account
    if account["status"] == "failed":
        assert any(e["result"] == "failed" for e in ran) or account["errors"]
    plant_file = load_plant(plant.path)
    for e in ran:
        if e["result"] == "verified":
            (said,) = [m for b, m in plant_file.modules() if b.name == e["bus"] and m.address == e["address"]]
            assert (e["read_back"] == "matches"
                    and held[(e["bus"], e["address"])].system == said.desired_system())
    travel = {(t["bus"], t["name"]) for e in found if e["event"] == "travel" for t in e["modules"]}
    assert {(e["bus"], e["name"]) for e in ran if e["released"] != "no"} <= travel
    phases = [e["phase"] for e in found if e["event"] == "progress" and e["done"] == 0]
    assert (phases == [p for p in ("reading modules", "writing", "verifying") if p in phases]
            and phases[:1] == ["reading modules"])
    over = [e for e in found if e["event"] == "progress" and e["done"] > e["total"]]
    assert not over, over  # a repair's write counts among the writes, never among the modules verified


def load_plant_modules():
    from emulated import DEMO

    return load_plant(DEMO).modules()
