"""owcsim: optical wireless channel simulator.

    import owcsim
    result = owcsim.simulate("examples/barry_config_a.json")   # or a dict, or a SceneSpec
    result.links[0].dc_gain, result.grid_maps()                    # typed result, numpy arrays
    from owcsim import build                                       # box_room, lamp, photodiode, work_plane, scene

The installed package holds the layers as subpackages: `owcsim.schemas` (wire models),
`owcsim.formats` (result files and plots), `owcsim.engine` (simulation core), `owcsim.server`
(HTTP service), `owcsim.clients` (HTTP client) and this package's command line. Heavy modules load on first use, so
`import owcsim` and `owcsim --version` stay fast.
"""

from __future__ import annotations

from .version import __version__

__all__ = ["__version__", "simulate", "Result", "SceneSpec"]


def __getattr__(name: str):
    if name == "simulate":
        from .api import simulate

        return simulate
    if name == "Result":
        from owcsim.clients.result import Result

        return Result
    if name == "SceneSpec":
        from owcsim.schemas import SceneSpec

        return SceneSpec
    raise AttributeError(f"module 'owcsim' has no attribute {name!r}")
