"""A time-varying medium: a sequence of grid media on one spatial grid, with their times (issue 26).

Frame f holds cells of constant sigma_a[f], sigma_s[f] [1/m] filling the box lo..hi cut into
shape = (nx, ny, nz) equal cells, laid out as in grid.py (C order, x slowest, z fastest), and one
phase function shared by every frame and cell. `frame(f)` is that frame as a static `GridMedium`:
a frame run alone must equal the same grid given as a static medium, bit for bit.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from owcsim.engine.core.arrays import FloatArray
from owcsim.engine.media.grid import GridMedium
from owcsim.schemas.medium import IsotropicPhaseSpec, PhaseSpec


@dataclass(frozen=True)
class MediumFrames:
    """Frames of one grid: `times` [s] (F,), strictly increasing; `sigma_a`, `sigma_s` [1/m] (F, nx, ny, nz).

    `source` says where the frames came from and how their quantities became sigma_a, sigma_s
    (e.g. "FDS slice EXT_3D_CELL, K = 8700 m^2/kg x rho_soot, albedo 0.2 (Mie)"): printed in results.
    """

    times: FloatArray
    lo: FloatArray
    hi: FloatArray
    sigma_a: FloatArray
    sigma_s: FloatArray
    phase: PhaseSpec = field(default_factory=IsotropicPhaseSpec)
    source: str = ""

    def __post_init__(self) -> None:
        t = np.asarray(self.times, np.float64)
        a, s = np.asarray(self.sigma_a, np.float64), np.asarray(self.sigma_s, np.float64)
        lo, hi = np.asarray(self.lo, np.float64), np.asarray(self.hi, np.float64)
        if t.ndim != 1 or len(t) < 1:
            raise ValueError("`times` must be a 1-D array of at least one time [s]")
        if not np.all(np.isfinite(t)) or np.any(np.diff(t) <= 0):
            raise ValueError("`times` must be finite and strictly increasing [s]")
        if a.ndim != 4 or a.shape != s.shape or a.shape[0] != len(t):
            raise ValueError(
                f"sigma_a and sigma_s must both be (F, nx, ny, nz) with F = {len(t)} frames; "
                f"got {a.shape} and {s.shape}"
            )
        if not (np.isfinite(a).all() and np.isfinite(s).all()) or min(a.min(), s.min()) < 0:
            raise ValueError("frame coefficients must be finite and >= 0 [1/m]")
        if lo.shape != (3,) or hi.shape != (3,) or not np.all(hi > lo):
            raise ValueError("the grid box needs `hi` > `lo` on every axis [m]")
        for name, value in (("times", t), ("lo", lo), ("hi", hi), ("sigma_a", a), ("sigma_s", s)):
            object.__setattr__(self, name, value)

    @property
    def n_frames(self) -> int:
        """Number of frames F."""
        return len(self.times)

    @property
    def shape(self) -> tuple[int, int, int]:
        """Cells per axis (nx, ny, nz)."""
        nx, ny, nz = self.sigma_a.shape[1:]
        return int(nx), int(ny), int(nz)

    @property
    def sigma_t(self) -> FloatArray:
        """Extinction sigma_a + sigma_s [1/m] (F, nx, ny, nz)."""
        return self.sigma_a + self.sigma_s

    def frame(self, f: int) -> GridMedium:
        """Frame f as a static grid medium (the same cells, coefficients and phase function)."""
        return GridMedium(self.lo, self.hi, self.shape, self.sigma_a[f], self.sigma_s[f], self.phase)

    def select(self, indices: np.ndarray | list[int]) -> MediumFrames:
        """The frames at `indices` (increasing), e.g. a sub-sampled or chosen set of times."""
        idx = np.asarray(indices, np.int64)
        return MediumFrames(
            self.times[idx], self.lo, self.hi, self.sigma_a[idx], self.sigma_s[idx], self.phase, self.source
        )
