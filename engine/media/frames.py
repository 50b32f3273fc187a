"""A time-varying medium: a sequence of grid media on one spatial grid, with their times (issue 26).

Frame f holds cells of constant sigma_a[f], sigma_s[f] [1/m] filling the box lo..hi cut into
shape = (nx, ny, nz) equal cells, laid out as in grid.py (C order, x slowest, z fastest), and one
phase function shared by every frame and cell. `frame(f)` is that frame as a static `GridMedium`:
a frame run alone must equal the same grid given as a static medium, bit for bit.

File sources (FDS, netCDF: engine/media/fds.py, frames_netcdf.py) share two steps kept here: which frames
(`select_frame_indices`) and how an extinction field becomes sigma_a, sigma_s (`scattering_optics`):
sigma_s = albedo sigma_t, sigma_a = sigma_t - sigma_s, with the albedo and phase given or from Mie theory.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from owcsim.engine.core.arrays import FloatArray
from owcsim.engine.core.errors import SceneError
from owcsim.engine.media.grid import GridMedium
from owcsim.engine.media.mie import particle_optics
from owcsim.schemas.frames import FramesReportPublic
from owcsim.schemas.medium import GridMediumSpec, IsotropicPhaseSpec, MiePhaseSpec, ParticlesSpec, PhaseSpec


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
    report: FramesReportPublic | None = None

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

    def grid_spec(self, f: int | None) -> GridMediumSpec:
        """Frame f as a document's static `grid` medium (f None: the frames' cell-wise mean, a carrier)."""
        a = self.sigma_a.mean(axis=0) if f is None else self.sigma_a[f]
        s = self.sigma_s.mean(axis=0) if f is None else self.sigma_s[f]
        return GridMediumSpec(
            min=tuple(self.lo.tolist()),
            max=tuple(self.hi.tolist()),
            shape=self.shape,
            sigma_a=a.ravel().tolist(),
            sigma_s=s.ravel().tolist(),
            phase=self.phase,
        )

    def select(self, indices: np.ndarray | list[int]) -> MediumFrames:
        """The frames at `indices` (increasing), e.g. a sub-sampled or chosen set of times."""
        idx = np.asarray(indices, np.int64)
        report = self.report
        if report is not None:
            report = report.model_copy(update={"times_s": [float(t) for t in self.times[idx]]})
        return MediumFrames(
            self.times[idx], self.lo, self.hi, self.sigma_a[idx], self.sigma_s[idx], self.phase, self.source, report
        )

    def frames_report(self) -> FramesReportPublic:
        """The structured mapping of the source to sigma_a, sigma_s (a plain description for inline frames)."""
        if self.report is not None:
            return self.report
        st = self.sigma_t
        return FramesReportPublic(
            kind="inline",
            quantity="sigma_a, sigma_s [1/m]",
            cell_values="as given",
            albedo_from="given per cell",
            phase=str(getattr(self.phase, "type", "")),
            grid_min=tuple(float(v) for v in self.lo),
            grid_max=tuple(float(v) for v in self.hi),
            grid_shape=self.shape,
            times_s=[float(t) for t in self.times],
            max_sigma_t=float(st.max()),
        )


def select_frame_indices(
    times: np.ndarray, times_s: list[float] | None, t_min: float | None, t_max: float | None, every: int
) -> np.ndarray:
    """Indices of the frames kept: nearest to each of `times_s` (sorted, without repeats), or those in
    [t_min, t_max] [s], then every `every`-th. A SceneError when none is left."""
    t = np.asarray(times, np.float64)
    if times_s is not None:
        idx = np.unique(np.argmin(np.abs(t[None, :] - np.asarray(times_s, np.float64)[:, None]), axis=1))
    else:
        keep = np.ones(len(t), bool)
        if t_min is not None:
            keep &= t >= t_min
        if t_max is not None:
            keep &= t <= t_max
        idx = np.flatnonzero(keep)[::every]
    if len(idx) == 0:
        raise SceneError(
            f"frames: no frame in the chosen times; the file has {len(t)} frames at {t.min():g}..{t.max():g} s"
        )
    return idx


def scattering_optics(
    albedo: float | None, phase: PhaseSpec | None, particles: ParticlesSpec | None
) -> tuple[float, PhaseSpec, str]:
    """(albedo, phase, where from) of an extinction field: given (isotropic phase if omitted), or from the
    Mie model of `particles` (albedo = <C_sca> / <C_ext>, the size-averaged Mie phase function)."""
    if particles is not None:
        optics = particle_optics(particles)
        return float(optics.c_sca / optics.c_ext), MiePhaseSpec(particles=particles), "mie"
    assert albedo is not None  # the schema asks for `albedo` or `particles`
    return float(albedo), phase if phase is not None else IsotropicPhaseSpec(), "given"


def split_extinction(sigma_t: np.ndarray, albedo: float) -> tuple[np.ndarray, np.ndarray]:
    """(sigma_a, sigma_s) [1/m] = (sigma_t - albedo sigma_t, albedo sigma_t): exact for albedo 0 and 1."""
    sigma_s = sigma_t * albedo
    return sigma_t - sigma_s, sigma_s
