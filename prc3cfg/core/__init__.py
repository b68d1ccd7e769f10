"""The pure core: what a PRC 3 module holds and does, and what a plan for it is.

Module images and their chains (`image`, `chains`), units (`units`), the messages (`codec`, `error_codes`),
the device model (`device`), the framings (`framing`), line settings and their bus-time cost (`line`,
`bustime`), the planner (`planner`, `plant_plan`, `plant_planner`, `broadcast_search`), what to read of the
modules and what their record becomes (`what_to_read`), what an apply concludes of their axes (`axes`), the CP
524/525 INIT block (`gateway`) and every rendering of a plan (`render`, `motion`, `plot`). No I/O, no threads,
no `serial`, no sockets: values in, values out. It imports nothing of prc3cfg outside itself but
`prc3cfg.errors` (tested).
"""
