"""The shell: everything that touches a line, the disk, a clock, a signal or a thread.

Bounded reads and atomic writes (`files`), plant files read for `prc3cfg.plant`
(`plant_files`), the link client and ports (`link`), the emulator and its server
(`emulator`), line locks (`locks`), a command's lines locked and opened (`sessions`), snapshots
and journals (`records`), Ctrl-C (`cancel`), read-back and apply over live lines (`readback`,
`apply`, and `engine`: an apply's writes from the lines' threads), what differs between POSIX and
Windows (`platform`: every other module calls it), and the emulated buses for tests
(`testing`, `pytest_plugin`). `prc3cfg.api` composes it
with the core; the CLI only parses arguments and renders.
"""
