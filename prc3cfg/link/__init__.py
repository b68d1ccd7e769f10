"""The link: PRC 3 messages over a real line (device path, pyserial URL or `emulator://`)."""

from prc3cfg.link.client import Exchange, Link, LinkError
from prc3cfg.link.ports import open_link, open_plant_links, open_port
from prc3cfg.link.trace import Trace

__all__ = ["Exchange", "Link", "LinkError", "Trace", "open_link", "open_plant_links", "open_port"]
