"""Optional dependencies of the formats (xarray, scipy, pandas, matplotlib: the `engine` extra)."""

from __future__ import annotations

import importlib
from types import ModuleType


def need(module: str, what: str) -> ModuleType:
    """Import an optional dependency, or say which install brings it."""
    try:
        return importlib.import_module(module)
    except ImportError as exc:
        raise ImportError(f"{what} needs {module.split('.')[0]}: pip install 'owcsim[engine]'") from exc
