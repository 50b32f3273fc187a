"""owcsim: optical wireless channel simulator.

The installed package holds the layers as subpackages: `owcsim.schemas` (wire models),
`owcsim.engine` (simulation core), `owcsim.server` (HTTP service), `owcsim.clients`
(HTTP client) and this package's command line. Heavy modules load on first use, so
`import owcsim` and `owcsim --version` stay fast.
"""
from __future__ import annotations

from importlib.metadata import PackageNotFoundError, version as _version

try:
    __version__ = _version("owcsim")
except PackageNotFoundError:  # a source tree that was not installed
    __version__ = "0+unknown"

__all__ = ["__version__"]
