"""prc3cfg: plant configuration as code for PRC 3 powder reciprocator controllers.

The pure core (`image`, `codec`, `device`, `framing`, `line`, the planner) does no I/O;
the link client, the emulator server and the CLI are the thin shell around it.
"""

__version__ = "0.1.0"
