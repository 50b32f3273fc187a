"""Build `MediumFrames` (frames.py) from their document (schemas/frames.py); one function per kind of source.

Inline frames here, FDS output in fds.py, netCDF files in frames_netcdf.py.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from owcsim.engine.media.fds import fds_frames
from owcsim.engine.media.frames import MediumFrames
from owcsim.engine.media.frames_netcdf import netcdf_frames
from owcsim.schemas.frames import FdsFramesSpec, FramesSpec, InlineFramesSpec, NetcdfFramesSpec


def _inline(spec: InlineFramesSpec) -> MediumFrames:
    shape = (len(spec.times), *spec.shape)

    def stack(values: list[float | list[float]]) -> np.ndarray:
        return np.stack(
            [np.broadcast_to(np.asarray(v, np.float64).reshape(-1), (int(np.prod(spec.shape)),)) for v in values]
        ).reshape(shape)

    return MediumFrames(
        np.asarray(spec.times, np.float64),
        np.asarray(spec.min),
        np.asarray(spec.max),
        stack(spec.sigma_a),
        stack(spec.sigma_s),
        spec.phase,
        source="inline frames (the document)",
    )


def frames_from_spec(spec: FramesSpec, base_dir: str | Path | None = None) -> MediumFrames:
    """The frames a document describes; `base_dir` resolves relative file names of file-based kinds."""
    if isinstance(spec, InlineFramesSpec):
        return _inline(spec)
    if isinstance(spec, FdsFramesSpec):
        return fds_frames(spec, base_dir)
    if isinstance(spec, NetcdfFramesSpec):
        return netcdf_frames(spec, base_dir)
    raise TypeError(f"unknown frames source {type(spec).__name__}")
