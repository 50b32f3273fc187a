"""Participating media: extinction and free-flight sampling along ray segments (physics.md section 3).

Every medium answers the same questions on batches of segments origin + t direction,
0 <= t <= length (origins, directions: (n, 3) float64 in any memory layout, e.g. the
transpose of a (3, n) array; unit directions; lengths (n,) [m]):

- `optical_depth(o, d, L)` -> tau (n,): the integral of sigma_t along each segment (exact);
- `transmittance(o, d, L)` = exp(-tau) (Beer-Lambert, multiplicative along a ray);
- `sample_distance(o, d, L, u)` -> (t, scattered): free flight, the t with optical depth
  -ln(1 - u) from the origin; where that exceeds the segment's depth, t = L and
  scattered = False. "scattered" means a collision (absorption or scattering; the
  caller weights by `albedo_at`). Exact inversion ("regular tracking") by default;
  `method="delta", rng=...` does delta (Woodcock) tracking against the majorant
  `sigma_t_max`, which samples the same distribution;
- `sigma_t_at(p)`, `sigma_s_at(p)`, `albedo_at(p)` at points (n, 3) [1/m], [1/m], [-]
  (0 outside the medium; the albedo is 0 where sigma_t = 0, never NaN);
- `phase_spec` and `phase` (the phase function built from it, once), `bounds` ((lo, hi) or None for
  the whole scene), `sigma_t_max` [1/m].

`evaluations` counts the segments the first three methods were asked about that actually
cross the medium's region (for the whole-scene medium: every segment). Segments that
never enter a bounded region are rejected by a bounding-box test and cost nothing else.
`scatters` and `max_albedo` answer, once the medium is built, what kind of medium it is
(does any path scatter; the largest single-scattering albedo, which bounds each scattering
order's share). Homogeneous media (and particle smoke, homogeneous with its Mie coefficients)
are in `media.py`, the 3-D grid of homogeneous cells in `grid.py`, the regions (box, closed
mesh) in `regions.py`, the phase functions in `phase.py`.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from functools import cached_property

import numpy as np
from numpy.typing import ArrayLike

from owcsim.engine.core.arrays import BoolArray, FloatArray
from owcsim.engine.media.phase import PhaseFunction, phase_from_spec
from owcsim.engine.media.regions import as_rows, clip_box
from owcsim.schemas.medium import PhaseSpec


class Medium(ABC):
    """The interface every medium implements (see the module docstring); subclasses fill the abstract members."""

    evaluations: int
    phase_spec: PhaseSpec
    bounds: tuple[FloatArray, FloatArray] | None

    @property
    @abstractmethod
    def sigma_t_max(self) -> float:
        """Majorant of sigma_t over the medium [1/m]."""

    @property
    @abstractmethod
    def scatters(self) -> bool:
        """True when sigma_s > 0 somewhere in the medium (paths can scatter, not only be attenuated)."""

    @property
    @abstractmethod
    def max_albedo(self) -> float:
        """Largest single-scattering albedo sigma_s / sigma_t over the medium [-] (0 where sigma_t = 0)."""

    @cached_property
    def phase(self) -> PhaseFunction:
        """The phase function of `phase_spec` (phase.phase_from_spec), built once per medium."""
        return phase_from_spec(self.phase_spec)

    # --- to implement ----------------------------------------------------------------
    @abstractmethod
    def _optical_depth(self, o: FloatArray, d: FloatArray, L: FloatArray) -> tuple[FloatArray, int]:
        """(tau, number of segments crossing the region)."""

    @abstractmethod
    def _regular(
        self, o: FloatArray, d: FloatArray, L: FloatArray, need: FloatArray
    ) -> tuple[FloatArray, BoolArray, int]:
        """Regular tracking to optical depth `need`: (t, scattered, number of crossing segments)."""

    @abstractmethod
    def _coefficients_at(self, p: FloatArray) -> tuple[FloatArray, FloatArray]:
        """(sigma_t, sigma_s) at points p (n, 3), 0 outside."""

    def _span(self, o: FloatArray, d: FloatArray, L: FloatArray) -> tuple[FloatArray, FloatArray]:
        """(t_enter, t_exit) of each segment in a box holding the region (delta tracking works inside it)."""
        if self.bounds is None:
            return np.zeros(len(L)), L
        return clip_box(o, d, L, *self.bounds)

    # --- the interface -------------------------------------------------------------------
    @staticmethod
    def _inputs(
        origins: ArrayLike, directions: ArrayLike, lengths: ArrayLike
    ) -> tuple[FloatArray, FloatArray, FloatArray]:
        return as_rows(origins), as_rows(directions), np.asarray(lengths, dtype=np.float64).reshape(-1)

    def optical_depth(self, origins: ArrayLike, directions: ArrayLike, lengths: ArrayLike) -> FloatArray:
        """Integral of sigma_t along each segment [-]; counts crossing segments in `evaluations`."""
        tau, n = self._optical_depth(*self._inputs(origins, directions, lengths))
        self.evaluations += n
        return tau

    def transmittance(self, origins: ArrayLike, directions: ArrayLike, lengths: ArrayLike) -> FloatArray:
        """T = exp(-optical depth) along each segment [-]; counts crossing segments in `evaluations`."""
        return np.exp(-self.optical_depth(origins, directions, lengths))

    def sample_distance(
        self,
        origins: ArrayLike,
        directions: ArrayLike,
        lengths: ArrayLike,
        u: ArrayLike | None = None,
        *,
        method: str = "regular",
        rng: np.random.Generator | None = None,
    ) -> tuple[FloatArray, BoolArray]:
        """Free-flight distance along each segment: (t [m], scattered (bool)); see the module docstring.

        `u` (n,) uniforms in [0, 1) drive regular tracking (drawn from `rng` if omitted);
        delta tracking draws its own numbers from `rng` (a numpy Generator) and ignores `u`.
        Counts crossing segments in `evaluations`.
        """
        o, d, L = self._inputs(origins, directions, lengths)
        if method == "regular":
            if u is None:
                if rng is None:
                    raise ValueError("sample_distance needs `u` or `rng`")
                u = rng.random(len(L))
            t, scattered, n = self._regular(o, d, L, -np.log1p(-np.asarray(u, dtype=np.float64)))
        elif method == "delta":
            if rng is None:
                raise ValueError("delta tracking needs `rng` (a numpy Generator)")
            t, scattered, n = self._delta(o, d, L, rng)
        else:
            raise ValueError(f"unknown free-flight method {method!r} (use 'regular' or 'delta')")
        self.evaluations += n
        return t, scattered

    def _delta(
        self, o: FloatArray, d: FloatArray, L: FloatArray, rng: np.random.Generator
    ) -> tuple[FloatArray, BoolArray, int]:
        """Delta tracking: tentative collisions at rate sigma_t_max, real with probability sigma_t / sigma_t_max."""
        t, scattered = L.copy(), np.zeros(len(L), bool)
        t0, t1 = self._span(o, d, L)
        ids = np.flatnonzero(t1 > t0)
        n = len(ids)
        majorant = float(self.sigma_t_max)
        if majorant <= 0.0:
            return t, scattered, n
        tc, te = t0[ids], t1[ids]
        while len(ids):  # ends with probability 1: every tentative step moves on by Exp(majorant)
            u = rng.random((2, len(ids)))
            tc = tc - np.log1p(-u[0]) / majorant
            k = np.flatnonzero(tc < te)
            ids, tc, te, u1 = ids[k], tc[k], te[k], u[1, k]
            sigma_t, _ = self._coefficients_at(o[ids] + tc[:, None] * d[ids])
            real = u1 * majorant < sigma_t
            t[ids[real]], scattered[ids[real]] = tc[real], True
            k = np.flatnonzero(~real)
            ids, tc, te = ids[k], tc[k], te[k]
        return t, scattered, n

    @property
    def uniform_coefficients(self) -> tuple[float, float] | None:
        """(sigma_t, sigma_s) [1/m] when they are the same at every point of the scene, else None."""
        return None

    def coefficients_at(self, points: ArrayLike) -> tuple[FloatArray, FloatArray]:
        """(sigma_t, sigma_s) at each point [1/m] (0 outside the medium), in one evaluation."""
        return self._coefficients_at(as_rows(points))

    def sigma_t_at(self, points: ArrayLike) -> FloatArray:
        """Extinction coefficient at each point [1/m] (0 outside the medium)."""
        return self._coefficients_at(as_rows(points))[0]

    def sigma_s_at(self, points: ArrayLike) -> FloatArray:
        """Scattering coefficient at each point [1/m] (0 outside the medium)."""
        return self._coefficients_at(as_rows(points))[1]

    def albedo_at(self, points: ArrayLike) -> FloatArray:
        """Single-scattering albedo sigma_s / sigma_t at each point [-]; 0 where sigma_t = 0."""
        sigma_t, sigma_s = self._coefficients_at(as_rows(points))
        pos = sigma_t > 0
        return np.where(pos, sigma_s / np.where(pos, sigma_t, 1.0), 0.0)
