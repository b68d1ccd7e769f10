"""The JSON files prc3cfg writes are read back as they were written, and written again byte for
byte: a plan file made by the code before its contracts were pydantic models
(`contracts/plan.json`, from `contracts/plant.yaml` at factory defaults, its version and plant path
left as VERSION and PLANT_PATH) is read and shown, as is `plan-evidence.json`, its one addition (the
evidence), made before the review had a digest; `plan-review.json`, that file with each module's
`review_sha256` added, is the file written now and is proved; module
images, snapshots and emulator state files read and written again are the same bytes."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from emulated import run_cli

from prc3cfg import __version__, api
from prc3cfg.api._apply import prove, read_plan
from prc3cfg.api._plan import as_it_stands
from prc3cfg.core.device import ModuleState
from prc3cfg.core.image import ModuleImage, images_from_json
from prc3cfg.errors import UserError
from prc3cfg.shell.emulator.state import load_state, save_state
from prc3cfg.shell.plant_files import load_plant
from prc3cfg.shell.records import LineTaken, Snapshot

CONTRACTS = Path(__file__).resolve().parent / "contracts"


def plant_here(tmp_path: Path) -> Path:
    plant = tmp_path / "plant.yaml"
    plant.write_bytes((CONTRACTS / "plant.yaml").read_bytes())
    return plant


def factory_images(plant: Path, out: Path) -> Path:
    """A `read --json` file of the plant's modules at factory defaults, as `read --json` writes it."""
    entries = [{"bus": bus.name, **ModuleState.factory(m.address).image.to_json()}
               for bus, m in load_plant(plant).modules()]
    out.write_text(json.dumps(entries, indent=1))
    return out


def made_before(plant: Path, name: str = "plan.json") -> str:
    """The plan file the code before wrote for `plant` at factory defaults, as if made there by this version:
    `plan.json` before plans named their evidence (issue 41), `plan-evidence.json` since — its one addition —
    and `plan-review.json` since the review had its digest (issue 43)."""
    text = (CONTRACTS / name).read_text()
    return text.replace('"VERSION"', json.dumps(__version__)).replace('"PLANT_PATH"',
                                                                      json.dumps(str(plant.resolve())))


def test_a_plan_file_is_written_byte_for_byte_as_before(tmp_path, capsys):
    plant = plant_here(tmp_path)
    out = tmp_path / "plan.json"
    assert run_cli(capsys, "plan", plant, "--actual", factory_images(plant, tmp_path / "images.json"),
                   "--out", out).code == 0
    assert out.read_text() == made_before(plant, "plan-review.json")


def test_a_plan_file_written_before_is_read_and_shown_and_apply_asks_for_a_plan_that_names_its_evidence(
    tmp_path, capsys
):
    """A plan file from before plans named their evidence (issue 41) is shown as it was; `apply --plan` proves
    every step of it, then refuses it in one line: it does not say what its plan rests on, and a current plan
    file with its `evidence` cut out would look the same. One from before its review had a digest is shown,
    saying so, and refused as made by an older prc3cfg; one written now is proved."""
    plant = plant_here(tmp_path)
    path = tmp_path / "before.json"
    path.write_text(made_before(plant))
    shown = run_cli(capsys, "show", path)
    assert shown.code == 0 and "booth-b-pretreat" in shown.out
    loaded = load_plant(plant)
    pairs = api.select(loaded)
    images = api.load_images(factory_images(plant, tmp_path / "images.json"), loaded)
    with pytest.raises(UserError,
                       match=r'before\.json: it does not say what its plan rests on \(no '
                             r'"evidence"\).*nothing was written'):
        prove(path, read_plan(path, loaded), loaded, pairs, images, as_it_stands(loaded, loaded.buses))
    path.write_text(made_before(plant, "plan-evidence.json"))
    shown = run_cli(capsys, "show", path)
    assert shown.code == 0 and "no review digest (made by an older prc3cfg)" in shown.out
    with pytest.raises(UserError,
                       match=r"before\.json: made by an older prc3cfg — its review text has no "
                             r"digest.*plan again$"):
        prove(path, read_plan(path, loaded), loaded, pairs, images, as_it_stands(loaded, loaded.buses))
    path.write_text(made_before(plant, "plan-review.json"))
    proved = prove(path, read_plan(path, loaded), loaded, pairs, images, as_it_stands(loaded, loaded.buses))
    assert proved.message_count == 26 and len(proved.changes) == 6


def test_module_images_and_snapshots_read_back_are_written_the_same(tmp_path):
    images_file = factory_images(plant_here(tmp_path), tmp_path / "images.json")
    entries = json.loads(images_file.read_text())
    images = images_from_json(entries)
    assert json.dumps([{"bus": e["bus"], **image.to_json()} for e, image in zip(entries, images)],
                      indent=1) == images_file.read_text()
    assert all(ModuleImage.from_json(image.to_json()) == image for image in images)
    taken = Snapshot.take(tmp_path / "plant.yaml", "0" * 64,
                          {(e["bus"], image.address): image for e, image in zip(entries, images)},
                          {"booth-a": LineTaken("socket://127.0.0.1:9", "crc16", ("tcp:127.0.0.1:9",))})
    written = taken.save()
    again = Snapshot.load(written)
    text = written.read_text()
    assert again == taken and json.loads(text) == again.to_json()
    assert again.save() == written and written.read_text() == text  # one module a line, as it was written


def test_an_emulator_state_file_read_back_is_written_the_same(tmp_path):
    path = tmp_path / "state.json"
    modules = {3: ModuleState.factory(3),
               7: ModuleState(ModuleImage.factory(7), mode="run", active_program=4, fault="E12",
                              referenced=False,
                                                          read_messages=False)}
    save_state(path, modules)
    assert load_state(path) == modules
    first = json.loads(path.read_text())
    save_state(path, load_state(path), replaces=first["generation"])
    second = json.loads(path.read_text())
    assert ({k: v for k, v in second.items() if k not in ("generation", "replaces")}
            == {k: v for k, v in first.items() if k != "generation"})
