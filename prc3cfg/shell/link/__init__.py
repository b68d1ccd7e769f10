"""The link: PRC 3 messages over a real line (device path, pyserial URL or `emulator://`)."""

from prc3cfg.shell.link.client import Exchange, Link, LinkError, NoReadMessages, PortFailed, PossibleWrite
from prc3cfg.shell.link.ports import open_link, open_plant_links, open_port
from prc3cfg.shell.link.trace import Trace

__all__ = ["Exchange", "Link", "LinkError", "NoReadMessages", "PortFailed", "PossibleWrite", "Trace", "open_link", "open_plant_links", "open_port"]
