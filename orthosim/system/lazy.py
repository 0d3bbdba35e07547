"""A package's names imported on first use (PEP 562), so that importing the package stays light.

`orthosim`, `orthosim.collision` and `orthosim.spheretree` each name what they offer in a table
(name -> the module that defines it) and take their module `__getattr__` from `lazy_names`: a name
is imported from its module the first time it is asked for, then kept in the package.
"""

from __future__ import annotations

import importlib
import sys
from typing import Any, Callable, Mapping


def lazy_names(package: str, where: Mapping[str, str]) -> Callable[[str], Any]:
    """The module `__getattr__` of `package` (its `__name__`) for the names in `where` (name ->
    module): each imported on first use and kept in the package; any other name raises
    AttributeError as a module does."""

    def __getattr__(name: str) -> Any:
        if name not in where:
            raise AttributeError(f"module {package!r} has no attribute {name!r}")
        value = getattr(importlib.import_module(where[name]), name)
        setattr(sys.modules[package], name, value)
        return value

    return __getattr__
