"""Modules imported on their first use, not when the engine is imported.

`trimesh` pulls in scipy (0.3-1.5 s of a command's start-up, issue 10) and is needed only for
mesh files and mesh regions: `from .lazy import trimesh` gives a stand-in whose first attribute
access imports the real module.
"""

from __future__ import annotations

import importlib
from types import ModuleType


class LazyModule:
    """Stand-in for the module `name`: attribute access imports it (once; Python caches modules)."""

    def __init__(self, name: str):
        self._name = name

    def __getattr__(self, attr: str):
        module: ModuleType = importlib.import_module(self._name)
        return getattr(module, attr)

    def __repr__(self) -> str:
        return f"<lazy module {self._name!r}>"


trimesh = LazyModule("trimesh")
