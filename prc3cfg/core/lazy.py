"""Names of a package that live in its modules, each module imported the first time one of its names is asked
for (PEP 562): `prc3cfg.api`, whose workflows a command uses one of, and `prc3cfg.core.render`, whose outputs
a command shows one or two of. The package lists where each name lives; the type checker reads the same names
from imports under TYPE_CHECKING (a test holds the two to each other)."""

from __future__ import annotations

import importlib
from collections.abc import Callable, Mapping


def lazy_names(namespace: dict[str, object], homes: Mapping[str, tuple[str, ...]],
               ) -> tuple[Callable[[str], object], Callable[[], list[str]]]:
    """The `__getattr__` and `__dir__` of the package whose globals are `namespace` and whose names live in
    the modules `homes` lists: a name is imported from its module when first asked for, then kept."""
    names = sorted(name for held in homes.values() for name in held)

    def __getattr__(name: str) -> object:
        for module, held in homes.items():
            if name in held:
                value = getattr(importlib.import_module(module), name)
                namespace[name] = value
                return value
        raise AttributeError(f"module {namespace['__name__']!r} has no attribute {name!r}")

    def __dir__() -> list[str]:
        return sorted({*namespace, *names})

    return __getattr__, __dir__
