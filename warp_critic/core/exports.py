"""Lazy re-exports for the packages' ``__init__`` (PEP 562).

A package lists its public names by module; each is imported on first use, so importing a package
imports nothing heavy (the CLI and the tools pay only for the modules a command needs).
"""

from __future__ import annotations

import importlib
import sys
from collections.abc import Callable, Mapping
from typing import Any


def lazy_exports(
    package: str, exports: Mapping[str, tuple[str, ...]]
) -> tuple[list[str], Callable[[str], Any], Callable[[], list[str]]]:
    """``(__all__, __getattr__, __dir__)`` for ``package``, which re-exports ``exports[module]`` from
    each module::

        __all__, __getattr__, __dir__ = lazy_exports(__name__, {"pkg.mod": ("name", ...)})
    """
    where = {name: module for module, names in exports.items() for name in names}

    def __getattr__(name: str) -> Any:
        module = where.get(name)
        if module is None:
            raise AttributeError(f"module {package!r} has no attribute {name!r}")
        return getattr(importlib.import_module(module), name)

    def __dir__() -> list[str]:
        return sorted(set(vars(sys.modules[package])) | set(where))

    return list(where), __getattr__, __dir__
