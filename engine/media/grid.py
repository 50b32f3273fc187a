"""Heterogeneous medium: a 3-D grid of homogeneous cells (report section 4, "grille 3D de fragments homogenes").

The box lo..hi is cut into shape = (nx, ny, nz) equal cells; cell (i, j, k) spans
lo + (i, j, k) h .. lo + (i + 1, j + 1, k + 1) h with h = (hi - lo) / shape, and holds
constant sigma_a, sigma_s [1/m]. Flat coefficient lists are in C order, x slowest,
z fastest: cell (i, j, k) is entry (i * ny + j) * nz + k (numpy `reshape(nx, ny, nz)`).
Outside the box there is no medium.

Optical depth is exact: the segment is clipped to the box, then walked cell by cell
(Amanatides & Woo 1987 3-D DDA), vectorized over rays, one loop step per cell boundary
crossed (at most nx + ny + nz steps). Each boundary distance is recomputed from the cell
index (lo + (i + 1) h - o) / d rather than accumulated, so rounding does not build up.
Regular tracking inverts the depth inside the cell where it reaches -ln(1 - u); delta
tracking (in `Medium`) uses the grid's largest sigma_t as majorant.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike

from owcsim.engine.core.arrays import BoolArray, FloatArray, IntArray
from owcsim.engine.media.medium import Medium
from owcsim.engine.media.regions import clip_box
from owcsim.schemas.medium import GridMediumSpec, IsotropicPhaseSpec, PhaseSpec


def _field(values: ArrayLike, shape: tuple[int, ...]) -> FloatArray:
    """Coefficients as an (nx, ny, nz) float64 array; one number is broadcast (no memory per cell)."""
    a = np.asarray(values, dtype=np.float64)
    if a.size == 1:
        return np.broadcast_to(a.reshape(()), shape)
    if a.size != int(np.prod(shape)):
        raise ValueError(f"expected 1 or {int(np.prod(shape))} coefficient values, got {a.size}")
    return a.reshape(shape)


class GridMedium(Medium):
    """Cells of constant `sigma_a`, `sigma_s` [1/m] filling the box lo..hi (see the module docstring)."""

    def __init__(
        self,
        lo: ArrayLike,
        hi: ArrayLike,
        shape: tuple[int, ...] | list[int],
        sigma_a: ArrayLike,
        sigma_s: ArrayLike,
        phase_spec: PhaseSpec | None = None,
    ):
        self.lo, self.hi = np.asarray(lo, np.float64), np.asarray(hi, np.float64)
        self.shape = tuple(int(s) for s in shape)
        self.h = (self.hi - self.lo) / np.asarray(self.shape)
        a, s = _field(sigma_a, self.shape), _field(sigma_s, self.shape)
        if min(a.min(), s.min()) < 0 or not (np.isfinite(a).all() and np.isfinite(s).all()):
            raise ValueError("grid coefficients must be finite and >= 0")
        self.sigma_s_grid = s
        uniform = a.strides == s.strides == (0, 0, 0)  # both given as one number: keep it one number
        self.sigma_t_grid = np.broadcast_to(a[0, 0, 0] + s[0, 0, 0], self.shape) if uniform else a + s
        self._sigma_t_max = float(self.sigma_t_grid.max())
        self.sigma_t_min = float(self.sigma_t_grid.min())
        self.bounds = (self.lo, self.hi)
        self.phase_spec = phase_spec if phase_spec is not None else IsotropicPhaseSpec()
        self.evaluations = 0

    @property
    def sigma_t_max(self) -> float:
        """Largest cell sigma_t [1/m] (the delta-tracking majorant)."""
        return self._sigma_t_max

    @property
    def scatters(self) -> bool:
        """True when some cell has sigma_s > 0."""
        return bool(np.max(self.sigma_s_grid) > 0)

    @property
    def max_albedo(self) -> float:
        """Largest cell albedo sigma_s / sigma_t [-] (0 in cells with sigma_t = 0)."""
        st, ss = self.sigma_t_grid, self.sigma_s_grid
        return float(np.max(np.where(st > 0, ss / np.where(st > 0, st, 1.0), 0.0)))

    def cells(self, points: FloatArray) -> tuple[IntArray, BoolArray]:
        """(cell indices (n, 3), inside the box?) of points (n, 3); points on the box's faces are inside."""
        idx = np.floor((points - self.lo) / self.h).astype(np.int64)
        np.clip(idx, 0, np.asarray(self.shape) - 1, out=idx)
        return idx, np.all((points >= self.lo) & (points <= self.hi), axis=1)

    def _coefficients_at(self, p: FloatArray) -> tuple[FloatArray, FloatArray]:
        idx, inside = self.cells(p)
        i, j, k = idx.T
        return (np.where(inside, self.sigma_t_grid[i, j, k], 0.0), np.where(inside, self.sigma_s_grid[i, j, k], 0.0))

    def _optical_depth(self, o: FloatArray, d: FloatArray, L: FloatArray) -> tuple[FloatArray, int]:
        tau, _, _, n = self._march(o, d, L, None)
        return tau, n

    def _regular(
        self, o: FloatArray, d: FloatArray, L: FloatArray, need: FloatArray
    ) -> tuple[FloatArray, BoolArray, int]:
        _, t, scattered, n = self._march(o, d, L, need)
        return t, scattered, n

    def _march(
        self, o: FloatArray, d: FloatArray, L: FloatArray, need: FloatArray | None
    ) -> tuple[FloatArray, FloatArray, BoolArray, int]:
        """3-D DDA over the cells: (tau, t, scattered, number of segments crossing the grid).

        With `need` (target optical depths), rays stop at their collision (regular tracking);
        tau is then only meaningful for rays that did not collide.
        """
        n = len(L)
        tau, t_out, scattered = np.zeros(n), L.copy(), np.zeros(n, bool)
        t0, t1 = clip_box(o, d, L, self.lo, self.hi)
        ids: np.ndarray = np.flatnonzero(t1 > t0)
        n_cross = len(ids)
        oo, dd, tc, te = o[ids], d[ids], t0[ids], t1[ids]
        acc: np.ndarray = np.zeros(len(ids))
        want = need[ids] if need is not None else None
        cell, _ = self.cells(oo + tc[:, None] * dd)
        step: np.ndarray = np.sign(dd).astype(np.int64)
        with np.errstate(divide="ignore"):
            inv = np.where(step != 0, 1.0 / np.where(step != 0, dd, 1.0), np.inf)
        upper = np.asarray(self.shape)
        for _ in range(sum(self.shape) + 3):  # every step crosses one cell boundary
            if len(ids) == 0:
                break
            boundary = self.lo + (cell + (step > 0)) * self.h  # the next plane of each axis, toward the ray
            with np.errstate(invalid="ignore"):
                tm = np.where(step != 0, (boundary - oo) * inv, np.inf)
            axis = np.argmin(tm, axis=1)
            rows = np.arange(len(ids))
            t_next = tm[rows, axis]
            t_end = np.maximum(np.minimum(t_next, te), tc)
            sigma = self.sigma_t_grid[cell[:, 0], cell[:, 1], cell[:, 2]]
            dtau = sigma * (t_end - tc)
            done = t_next >= te
            if want is not None:
                rem = want - acc
                hit = dtau > rem  # dtau > rem >= 0 implies sigma > 0: no division by zero
                if hit.any():
                    hi_ = np.flatnonzero(hit)
                    t_out[ids[hi_]] = tc[hi_] + rem[hi_] / sigma[hi_]
                    scattered[ids[hi_]] = True
                done |= hit
            acc += dtau
            tc = t_end
            cell[rows, axis] += step[rows, axis]
            c_ax = cell[rows, axis]
            done |= (c_ax < 0) | (c_ax >= upper[axis])
            fin = np.flatnonzero(done)
            tau[ids[fin]] = acc[fin]
            keep = np.flatnonzero(~done)
            if len(keep) < len(ids):
                ids, oo, dd, tc, te, acc, cell, step, inv = (
                    x[keep] for x in (ids, oo, dd, tc, te, acc, cell, step, inv)
                )
                if want is not None:
                    want = want[keep]
        tau[ids] = acc  # (none left: the loop bound is the longest walk)
        return tau, t_out, scattered, n_cross


def grid_from_spec(spec: GridMediumSpec) -> GridMedium | None:
    """The `grid` kind (registry.py): the grid of the document; None when sigma_t = 0 in every cell."""
    medium = GridMedium(spec.min, spec.max, spec.shape, spec.sigma_a, spec.sigma_s, spec.phase)
    return None if medium.sigma_t_max == 0.0 else medium
