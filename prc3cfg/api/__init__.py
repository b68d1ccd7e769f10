"""The Python API: everything the command line does, as functions of plain values.

    from prc3cfg import api

    plant = api.load("plant.yaml")
    plan = api.plan(plant)                          # reads every module back
    for change in plan.changes:
        print(change.bus, change.name, len(change.steps), "steps")
    result = api.apply(plant, gates=api.Gates(allow_axis_release=True))
    assert result.verified and not api.plan(plant).changes
    print("travel to reference point:", [run.name for run in result.released])
    api.told(result)                                # shown: the records of those releases go

(a test runs this example, and docs/api.md's, against emulated buses.)

Each function returns values — a `Plant`, module images, a `PlantPlan`, an `ApplyResult` —
and raises a `UserError` subclass whose `str()` is one line saying what is wrong and what to
do: `PlantError`, `LinkError`, `LineBusy`, `StalePlan`, `AxisReleaseRefused`, `NotApproved`,
`ApplyFailed` and `ApplyInterrupted` (both carry the `ApplyResult`, for the account).
Every function that talks on a line takes `LineOptions`: retries, the lock time-out, a frame
trace, a cancel event (Ctrl-C, `prc3cfg.shell.cancel`) and a `Progress` to report to.

Owns the workflows: which modules, what to read, locking the lines, reading back, planning
each line as it is read (and probing it before broadcasts), proving a plan file, gating, the
snapshot and the journal, running and verifying, restoring, drift, adopting Teach In into the
plant file, scanning, importing, a gateway's INIT block, the pictures of a module's motion and
serving an emulated bus. Does not own what they are made of (the pure core, `prc3cfg.core` —
the planner and its cache, `prc3cfg.core.plant_planner`; plant files, `prc3cfg.plant`; the shell:
links, locks, records, apply, files, the emulator, `prc3cfg.shell`), nor arguments, prompts
and output (`prc3cfg.cli`). `__all__` is what the CLI and users' scripts call.

Its modules, one workflow each: `_types` (the values and errors), `_plan` (load, select, what to read, read,
plan, drift), `_apply` (apply, restore, plan files), `_bus` (scan, import, doctor), `_plant` (adopt, records,
gateways, pictures), `_policy` (the policy judged), `_fleet` (a fleet's lines, its CI matrix and summary),
`_emulator` (an emulated bus) and `_machine` (the machine's folders, ports and terminal). Each name is
imported from its module when it is first asked for (`__getattr__`): a script, or a command, loads what it
uses — a plan from saved images no link, no pyserial.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from prc3cfg.core.lazy import lazy_names

if TYPE_CHECKING:  # the names as the type checker sees them; at run time each is imported when asked for
    from prc3cfg.api._apply import apply as apply
    from prc3cfg.api._apply import plan_document as plan_document
    from prc3cfg.api._apply import plan_file_plant as plan_file_plant
    from prc3cfg.api._apply import restore as restore
    from prc3cfg.api._apply import told as told
    from prc3cfg.api._bus import doctor as doctor
    from prc3cfg.api._bus import import_modules as import_modules
    from prc3cfg.api._bus import import_plant as import_plant
    from prc3cfg.api._bus import measurable as measurable
    from prc3cfg.api._bus import scan as scan
    from prc3cfg.api._bus import slower_than_priced as slower_than_priced
    from prc3cfg.api._emulator import emulator as emulator
    from prc3cfg.api._emulator import listen as listen
    from prc3cfg.api._emulator import open_pty as open_pty
    from prc3cfg.api._emulator import served_pty as served_pty
    from prc3cfg.api._fleet import fleet_lines as fleet_lines
    from prc3cfg.api._fleet import fleet_matrix as fleet_matrix
    from prc3cfg.api._fleet import fleet_summary as fleet_summary
    from prc3cfg.api._machine import SerialPort as SerialPort
    from prc3cfg.api._machine import device_number as device_number
    from prc3cfg.api._machine import serial_ports as serial_ports
    from prc3cfg.api._machine import setup_machine as setup_machine
    from prc3cfg.api._machine import terminal_path as terminal_path
    from prc3cfg.api._machine import unshared_records as unshared_records
    from prc3cfg.api._machine import wait_for as wait_for
    from prc3cfg.api._plan import drift as drift
    from prc3cfg.api._plan import left_alone as left_alone
    from prc3cfg.api._plan import load as load
    from prc3cfg.api._plan import load_images as load_images
    from prc3cfg.api._plan import plan as plan
    from prc3cfg.api._plan import read as read
    from prc3cfg.api._plan import select as select
    from prc3cfg.api._plant import Adoption as Adoption
    from prc3cfg.api._plant import adopt as adopt
    from prc3cfg.api._plant import init_data_block as init_data_block
    from prc3cfg.api._plant import list_records as list_records
    from prc3cfg.api._plant import picture as picture
    from prc3cfg.api._plant import plot_format as plot_format
    from prc3cfg.api._plant import prune_records as prune_records
    from prc3cfg.api._plant import serve_status as serve_status
    from prc3cfg.api._plant import status as status
    from prc3cfg.api._plant import verify_records as verify_records
    from prc3cfg.api._plant import write_adoption as write_adoption
    from prc3cfg.api._policy import PolicyRefused as PolicyRefused
    from prc3cfg.api._policy import PolicyReport as PolicyReport
    from prc3cfg.api._policy import WindowShut as WindowShut
    from prc3cfg.api._policy import policy as policy
    from prc3cfg.api._types import ApplyFailed as ApplyFailed
    from prc3cfg.api._types import ApplyInterrupted as ApplyInterrupted
    from prc3cfg.api._types import ApplyResult as ApplyResult
    from prc3cfg.api._types import AxisReleaseRefused as AxisReleaseRefused
    from prc3cfg.api._types import Gates as Gates
    from prc3cfg.api._types import NotApproved as NotApproved
    from prc3cfg.core.axes import Release as Release
    from prc3cfg.core.plan_file import StalePlan as StalePlan
    from prc3cfg.core.render import Drift as Drift
    from prc3cfg.errors import UserError as UserError
    from prc3cfg.plant import PlantError as PlantError
    from prc3cfg.shell.apply import Verify as Verify
    from prc3cfg.shell.audit import Verified as Verified
    from prc3cfg.shell.doctor import Diagnosis as Diagnosis
    from prc3cfg.shell.doctor import Search as Search
    from prc3cfg.shell.link.client import LinkError as LinkError
    from prc3cfg.shell.link.ports import FormatRefused as FormatRefused
    from prc3cfg.shell.locks import LineBusy as LineBusy
    from prc3cfg.shell.phases import Progress as Progress
    from prc3cfg.shell.recorded_runs import Pruned as Pruned
    from prc3cfg.shell.recorded_runs import RecordedRun as RecordedRun
    from prc3cfg.shell.sessions import BareLine as BareLine
    from prc3cfg.shell.sessions import LineOptions as LineOptions
    from prc3cfg.shell.sessions import default_parity as default_parity

#: Where each name of the API lives (a test checks it against the imports above).
_HOMES: dict[str, tuple[str, ...]] = {
    "prc3cfg.api._apply": ("apply", "plan_document", "plan_file_plant", "restore", "told"),
    "prc3cfg.api._bus": ("doctor", "import_modules", "import_plant", "measurable", "scan",
                         "slower_than_priced"),
    "prc3cfg.api._emulator": ("emulator", "listen", "open_pty", "served_pty"),
    "prc3cfg.api._machine": ("SerialPort", "device_number", "serial_ports", "setup_machine", "terminal_path",
                             "unshared_records", "wait_for"),
    "prc3cfg.api._plan": ("drift", "left_alone", "load", "load_images", "plan", "read", "select"),
    "prc3cfg.api._plant": ("Adoption", "adopt", "init_data_block", "list_records", "picture", "plot_format",
                           "prune_records",
                           "serve_status", "status", "verify_records", "write_adoption"),
    "prc3cfg.api._fleet": ("fleet_lines", "fleet_matrix", "fleet_summary"),
    "prc3cfg.api._policy": ("PolicyRefused", "PolicyReport", "WindowShut", "policy"),
    "prc3cfg.api._types": ("ApplyFailed", "ApplyInterrupted", "ApplyResult", "AxisReleaseRefused", "Gates",
                           "NotApproved"),
    "prc3cfg.core.plan_file": ("StalePlan",),
    "prc3cfg.core.render": ("Drift",),
    "prc3cfg.core.axes": ("Release",),
    "prc3cfg.errors": ("UserError",),
    "prc3cfg.plant": ("PlantError",),
    "prc3cfg.shell.apply": ("Verify",),
    "prc3cfg.shell.audit": ("Verified",),
    "prc3cfg.shell.doctor": ("Diagnosis", "Search"),
    "prc3cfg.shell.link.client": ("LinkError",),
    "prc3cfg.shell.link.ports": ("FormatRefused",),
    "prc3cfg.shell.locks": ("LineBusy",),
    "prc3cfg.shell.phases": ("Progress",),
    "prc3cfg.shell.recorded_runs": ("Pruned", "RecordedRun"),
    "prc3cfg.shell.sessions": ("BareLine", "LineOptions", "default_parity"),
}

#: What the CLI, the pytest plugin and users' scripts call (a test keeps the CLI to these).
__all__ = sorted(name for names in _HOMES.values() for name in names)


__getattr__, __dir__ = lazy_names(globals(), _HOMES)
