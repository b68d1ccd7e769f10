"""Plant files: the declarative description of every bus, module, system parameter and program.

    from prc3cfg.plant import parse_plant, PlantError, Plant, Bus, Module

`parse_plant(path, data)` reads the bytes `data` of the plant file `path` (docs/plant-files.md)
and returns a `Plant`, or raises `PlantError` listing every problem as `file:line:column: what
is wrong — what would be right`. Pure: the shell reads the file (`prc3cfg.shell.plant_files`).
The parts: `models` (the file's structure and the JSON Schema), `document` (YAML with
positions), `scalars` (what a scalar's text reads as in YAML 1.1 and 1.2), `messages` (wording),
`profiles` (layering), `rules` (cross-value checks), `plant` (the loaded plant), `loader`; and the
two writers, `importer` (a plant file from modules) and `adopt` (a plant file rewritten in place,
its values spliced into the text by `splice`). Units are `prc3cfg.core.units`.
"""

from prc3cfg.plant.loader import parse_plant
from prc3cfg.plant.models import Gateway, plant_schema, plant_schema_text
from prc3cfg.plant.plant import Bus, Module, Plant
from prc3cfg.plant.problems import PlantError

__all__ = ["Bus", "Gateway", "Module", "Plant", "PlantError", "parse_plant", "plant_schema",
           "plant_schema_text"]
