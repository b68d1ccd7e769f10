"""prc3cfg: plant configuration as code for PRC 3 powder reciprocator controllers.

In layers, one folder each: `core` (the pure core: images, messages, device model, framings,
planner, rendering — no I/O), `plant` (plant files), `shell` (links, emulator, locks, records,
apply), then `api` (the workflow as functions of plain values) and `cli` (arguments, prompts,
rendering). `errors` holds the one-line errors every layer raises.
"""

__version__ = "0.1.0"
