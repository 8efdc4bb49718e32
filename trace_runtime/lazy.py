"""Package names imported on first use (PEP 562), so importing a package costs nothing
until one of its names is asked for: ``trace-audit --help`` stays light, and importing one
codec does not import them all.

A package lists each public name with the module that defines it and ends with

    __getattr__, __dir__ = lazy_exports(__name__, _EXPORTS, __all__)
"""

from __future__ import annotations

import importlib
import sys
from collections.abc import Callable, Mapping, Sequence
from typing import Any

__all__ = ["lazy_exports"]


def lazy_exports(
    package: str, exports: Mapping[str, str], names: Sequence[str]
) -> tuple[Callable[[str], Any], Callable[[], list[str]]]:
    """The module ``__getattr__`` and ``__dir__`` of ``package``: a name in ``exports`` is
    imported from its module when first asked for, then kept in the package's namespace."""

    def attribute(name: str) -> Any:
        module = exports.get(name)
        if module is None:
            raise AttributeError(f"module {package!r} has no attribute {name!r}")
        value = getattr(importlib.import_module(module), name)
        vars(sys.modules[package])[name] = value
        return value

    def names_listed() -> list[str]:
        return list(names)

    return attribute, names_listed
