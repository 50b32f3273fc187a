"""The installed package's version: the one lookup, at the bottom of the layers (engine, server and
the command line import it from here)."""

from __future__ import annotations

from importlib.metadata import PackageNotFoundError
from importlib.metadata import version as _version

try:
    __version__ = _version("owcsim")
except PackageNotFoundError:  # a source tree that was not installed
    __version__ = "0+unknown"
