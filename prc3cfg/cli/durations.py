"""Times on the command line: seconds, or a number with a unit (500ms, 5s, 2m, 1h) — parsed for the options
that take one, and bounded with a usage error that says the bound as the user would write it."""

from __future__ import annotations

import math
import re
from collections.abc import Callable
from decimal import Decimal
from typing import Any

import typer

#: A time on the command line: seconds, or a number with a unit (`parse_duration`).
_DURATION = re.compile(r"(\d+(?:\.\d*)?|\.\d+)(ms|s|m|h)?")
_SECONDS = {"ms": Decimal("0.001"), "s": Decimal(1), "m": Decimal(60), "h": Decimal(3600)}


def parse_duration(text: str) -> float:
    """ "30", "0.5", "500ms", "5s", "2m", "1h" → seconds; ValueError, saying what to write, for anything
    else."""
    match = _DURATION.fullmatch(text.strip())
    if match is None:
        raise ValueError(f"'{text}' is not a time — write seconds (30, 0.5) or with a unit: 500ms, "
                         "5s, 2m, 1h")
    return float(Decimal(match.group(1)) * _SECONDS[match.group(2) or "s"])


def _said(seconds: float) -> str:
    """A bound as the user would write it: 4ms, 1h, 65.535s."""
    exact = Decimal(str(seconds))
    unit = next((u for u in ("h", "m") if exact >= _SECONDS[u] and exact % _SECONDS[u] == 0), "s"
                if exact >= 1 or not exact else "ms")
    return f"{(exact / _SECONDS[unit]).normalize():f}{unit}"


def duration(low: float, high: float = math.inf) -> Callable[[Any], float]:
    """A time option's parser: `parse_duration` within low..high seconds, else a usage error (exit 64)."""

    def parse(value: Any) -> float:
        if isinstance(value, int | float):  # the default
            return float(value)
        try:
            seconds = parse_duration(value)
        except ValueError as error:
            raise typer.BadParameter(str(error)) from None
        if not low <= seconds <= high:
            raise typer.BadParameter(f"{value} is {'less' if seconds < low else 'more'} than "
                                     f"{_said(low if seconds < low else high)}")
        return seconds

    return parse


#: How a time may be written, for option help.
TIMES = "seconds, or 500ms, 5s, 2m, 1h"
