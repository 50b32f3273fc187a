"""Frames by reweighting: one set of paths, a per-frame throughput ratio row per path (issue 26, item 4).

The kernel traces each path once in a *carrier* grid medium c and keeps, besides the carrier
weight w, a ratio row r_f (F, n) (`Paths.ratio`): frame f's path throughput over the sampled
one, so that w r_f is the path's weight as if the scene held frame f's medium. Every frame's
estimate comes from the same paths and random numbers: the frames are correlated and the
differences between frames have small errors. The part implements the kernel's ratio interface
`PathRatios` (below), the one the spectral bands use (engine/spectral/spectra.py `SceneSpectra`):
the integrator calls `ctx.ratios.<method>(...)` once per event, whichever part it is.

Unbiasedness (importance sampling of path space with the carrier's densities; Szirmay-Kalos,
Toth and Magdics 2011 "Free path sampling in high resolution inhomogeneous participating media";
Novak, Selle and Jarosz 2014 "Residual ratio tracking for estimating attenuation in participating
media"; Kutz, Habel, Li and Novak 2017 "Spectral and decomposition tracking for rendering
heterogeneous volumes", whose spectral tracking is this construction with frames for wavelengths).
A path x_0 .. x_k has in frame f the measurement contribution
    f_f(x) = prod(surface terms) prod_segments T_f(seg) prod_collisions sigma_s,f(x_j) p(cos_j),
and the kernel samples it with the carrier's density p_c(x), in which free flights carry
sigma_t,c(x) T_c at a collision and T_c past a surface (algorithm 5), or take T_c as a weight
(algorithms 1-4). The carrier estimate is f_c / p_c = w; the frame estimate f_f / p_c = w r_f with
    r_f = prod_segments T_f / T_c * prod_collisions sigma_s,f(x_j) / sigma_s,c(x_j),
because the surface terms, the phase function (shared by every frame), the emission and the
geometry are the same in every frame and cancel. Per event:
  - segment without collision (a flight to a surface, a connection, algorithm 1's segments):
        r_f *= exp(-(tau_f - tau_c)),  tau = integral of sigma_t along the segment;
  - collision at x after a flight sampled with density sigma_t,c(x) T_c (the carrier weight keeps
    albedo_c = sigma_s,c / sigma_t,c):
        r_f *= [sigma_s,f(x) T_f] / [sigma_s,c(x) T_c];
  - a point on a segment scattering toward a device (algorithms 2-4), weighted by sigma_s,c T_c:
    the same factor.
E_c[w r_f] = integral of (f_f / p_c) p_c = integral of f_f: unbiased for every frame wherever p_c > 0
wherever f_f > 0, the support condition: sigma_s,c > 0 wherever some frame has sigma_s,f > 0
(else frame f's scattering there is never sampled), and T_c > 0 (a finite grid). Where only
absorption changes between frames the collision factor is 1 and the ratios are the pure
Beer-Lambert factors along each path's fixed geometry: exact reweighting.

The carrier (`carrier_grid`): the cell-wise mean over a window of frames, sigma_a,c = mean_f
sigma_a,f, sigma_s,c = mean_f sigma_s,f. The mean is positive wherever one frame scatters, so the
support condition holds by construction. Variance: the ratio row multiplies every frame by
exp(-(tau_f - tau_c)); a frame far from the carrier (|tau_f - tau_c| >> 1 along typical paths)
gets weights with a large spread and a heavy tail (frames thinner than the carrier:
exp(+delta tau) > 1 on rare paths; thicker: most paths near 0). The mean keeps |tau_f - tau_c|
at most (1 - 1/F) of the window's range of depths along a path (half of it for F = 2; a lone thick frame
among F - 1 clear ones is the worst case, hence the windows below); a carrier at the frame-wise maximum would make every
thinner frame's ratios exceed 1 (exp(+Delta tau)), one at the minimum violates the support
condition when early frames hold no smoke. `effective_fraction` measures it per frame: the
effective sample size of the per-path estimates x_f = w r_f (summed over the path's estimates) as a
fraction of the carrier's own, ESS_f / ESS_c = [E(x_f)^2 / E(x_f^2)] / [E(x_c)^2 / E(x_c^2)]
= (1 + cv_c^2) / (1 + cv_f^2), cv^2 the per-path relative variance (Kong 1992; 1 when every ratio
is 1). engine/run/frames_reweighted.py splits the frames into windows of their own carriers while some
frame's fraction falls below MIN_EFFECTIVE_FRACTION.

Optical depths of every frame: one 3-D DDA walk of each segment through the shared grid
(Amanatides & Woo 1987, as grid.py), accumulating at each cell crossed length x sigma_t,f[cell]
for all F frames and the carrier at once: a (segments, F + 1) array, one gather per step; the
loop runs over cell crossings only, never over frames or paths.
"""

from __future__ import annotations

from typing import Any, Protocol

import numpy as np
from numpy.typing import ArrayLike

from owcsim.engine.core.arrays import FloatArray, IntArray
from owcsim.engine.media.frames import MediumFrames
from owcsim.engine.media.grid import GridMedium
from owcsim.engine.media.regions import as_rows, clip_box

#: Below this fraction ESS_f / ESS_c for some frame, the frames are split into windows of their own carriers.
MIN_EFFECTIVE_FRACTION = 0.3

#: A batch of segments as the media take them: (origins (n, 3), unit directions (n, 3), lengths (n,) [m]).
Segments = tuple[ArrayLike, ArrayLike, ArrayLike]


class PathRatios(Protocol):
    """The kernel's interface to per-path ratio rows (spectral bands, frames of a time-varying medium).

    `ratio` arrays are a part's path state (rows, n); `tau` the carrier's optical depth of the segments
    the event concerns (n,), `seg` the segments themselves (frames need their own depths along them)."""

    carry: bool  # the kernel carries ratios (else the part is inactive)
    phase_bands: list | None  # per-row phase functions when they differ from the carrier's

    @property
    def n_bands(self) -> int: ...  # rows of the estimates' ratios

    @property
    def depth_row(self) -> bool: ...  # algorithm 5's uncollided flights and collisions change the ratios

    def initial_ratio(self, n: int) -> np.ndarray: ...

    def reflect(self, ratio: np.ndarray, prims: np.ndarray) -> np.ndarray: ...

    def transmit(self, ratio: np.ndarray, tau: np.ndarray, seg: Segments | None = None) -> np.ndarray: ...

    def transmit_rows(
        self, ratio: np.ndarray, rows: np.ndarray, tau: np.ndarray, seg: Segments | None = None
    ) -> np.ndarray: ...

    def scatter(self, ratio: np.ndarray, tau: np.ndarray, seg: Segments | None = None) -> np.ndarray: ...

    def turn(self, ratio: np.ndarray, cos: np.ndarray) -> np.ndarray: ...

    def phase_ratio(self, cos: np.ndarray) -> np.ndarray: ...

    def estimate_ratio(
        self, ratio: np.ndarray, tau: np.ndarray | None = None, seg: Segments | None = None
    ) -> np.ndarray: ...


def carrier_grid(frames: MediumFrames) -> GridMedium:
    """The carrier of `frames`: their cell-wise mean sigma_a, sigma_s [1/m] (the module docstring)."""
    return GridMedium(
        frames.lo, frames.hi, frames.shape, frames.sigma_a.mean(axis=0), frames.sigma_s.mean(axis=0), frames.phase
    )


class FrameRatios:
    """Per-frame ratio rows (F, n) of paths sampled in the carrier `carrier` (same grid as `frames`)."""

    carry: bool = True
    phase_bands: list | None = None

    def __init__(self, frames: MediumFrames, carrier: GridMedium, rx_frames: ArrayLike | None = None):
        if tuple(carrier.shape) != frames.shape or not (
            np.array_equal(carrier.lo, frames.lo) and np.array_equal(carrier.hi, frames.hi)
        ):
            raise ValueError("the carrier must be a grid medium on the frames' grid")
        self.frames, self.carrier = frames, carrier
        F, n_cells = frames.n_frames, int(np.prod(frames.shape))
        #: (cells, F + 1) extinction [1/m] of every frame and, last, the carrier's: one gather per DDA step
        self.sigma_t = np.ascontiguousarray(
            np.vstack([frames.sigma_t.reshape(F, n_cells), np.asarray(carrier.sigma_t_grid).reshape(1, n_cells)]).T
        )
        ss_c = np.asarray(carrier.sigma_s_grid).reshape(n_cells)
        ss_f = frames.sigma_s.reshape(F, n_cells)
        if np.any((ss_c <= 0) & (ss_f > 0).any(axis=0)):
            raise ValueError(
                "frames: the carrier does not scatter in a cell where a frame does (support condition of "
                "engine/media/frame_ratios.py): its scattering would never be sampled"
            )
        #: (cells, F) sigma_s,f / sigma_s,c (0 where the carrier does not scatter: no collision is kept there)
        with np.errstate(divide="ignore", invalid="ignore"):
            self.scatter_ratio = np.ascontiguousarray(np.where(ss_c > 0, ss_f / np.where(ss_c > 0, ss_c, 1.0), 0.0).T)
        self.segments = 0  # segments walked (a cost figure)
        self._memo: tuple[FloatArray, FloatArray, FloatArray, FloatArray] | None = None  # the last walk
        #: per receiver, the one frame whose tally it enters (a moving receiver: one receiver per frame), -1: all
        self.rx_frames = None if rx_frames is None else np.asarray(rx_frames, np.int64)

    def frame_targets(self, forward: bool, source: int, tgt: IntArray) -> np.ndarray:
        """(F, T) which of a batch's targets `tgt` each frame tallies (receivers by `rx_frames`): forward, the
        targets are receivers; backward, the source is."""
        F = self.n_bands
        if self.rx_frames is None:
            return np.ones((F, len(tgt)), bool)
        rx = self.rx_frames.take(np.asarray(tgt, np.int64)) if forward else np.full(len(tgt), self.rx_frames[source])
        return (rx[None, :] == -1) | (rx[None, :] == np.arange(F)[:, None])  # (-2: a frame of another window)

    @property
    def n_bands(self) -> int:
        """Rows of a ratio: F frames."""
        return self.frames.n_frames

    @property
    def depth_row(self) -> bool:
        """Frames change along uncollided flights and at collisions (algorithm 5 ratio tracking)."""
        return True

    # --- optical depths of every frame --------------------------------------------------------------------
    def depths(self, seg: Segments) -> FloatArray:
        """(n, F + 1) optical depths of the segments in every frame and (last column) the carrier [-]; the
        segments the carrier medium (`FramedGrid`) walked last are not walked again."""
        o, d = as_rows(seg[0]), as_rows(seg[1])
        L = np.asarray(seg[2], np.float64).reshape(-1)
        memo = self._memo
        if memo is not None and len(memo[2]) == len(L):
            if np.array_equal(memo[2], L) and np.array_equal(memo[0], o) and np.array_equal(memo[1], d):
                return memo[3]
        return self.walk(o, d, L)[0]

    def walk(self, o: FloatArray, d: FloatArray, L: FloatArray) -> tuple[FloatArray, int]:
        """(depths (n, F + 1) as `depths`, segments crossing the grid): one 3-D DDA walk (the steps of grid._march,
        each adding length x sigma_t of every frame and the carrier; finished rays add 0 until a quarter of them
        is done, then the arrays shrink)."""
        g = self.carrier
        n, width = len(L), self.sigma_t.shape[1]
        tau = np.zeros((n, width))
        t0, t1 = clip_box(o, d, L, g.lo, g.hi)
        ids: IntArray = np.flatnonzero(t1 > t0)
        n_cross = len(ids)
        self.segments += n_cross
        self._memo = (o.copy(), d.copy(), L.copy(), tau)  # copies: a caller may reuse its buffers
        if n_cross == 0:
            return tau, 0
        oo, dd, tc, te = o[ids], d[ids], t0[ids], t1[ids]
        acc = np.zeros((len(ids), width))
        live = np.ones(len(ids), bool)
        cell, _ = g.cells(oo + tc[:, None] * dd)
        step: IntArray = np.sign(dd).astype(np.int64)
        with np.errstate(divide="ignore"):
            inv = np.where(step != 0, 1.0 / np.where(step != 0, dd, 1.0), np.inf)
        upper = np.asarray(g.shape)
        strides = np.array([g.shape[1] * g.shape[2], g.shape[2], 1], np.int64)
        last = self.sigma_t.shape[0] - 1
        n_live = len(ids)
        for _ in range(sum(g.shape) + 3):  # every step crosses one cell boundary (the same walk as grid._march)
            if n_live == 0:
                break
            boundary = g.lo + (cell + (step > 0)) * g.h
            with np.errstate(invalid="ignore"):
                tm = np.where(step != 0, (boundary - oo) * inv, np.inf)
            axis = np.argmin(tm, axis=1)
            rows = np.arange(len(ids))
            t_next = tm[rows, axis]
            t_end = np.maximum(np.minimum(t_next, te), tc)
            flat = np.clip(cell @ strides, 0, last)  # (finished rays may have left the grid: they add 0)
            acc += self.sigma_t.take(flat, axis=0) * (t_end - tc)[:, None]
            done = t_next >= te
            tc = t_end
            cell[rows, axis] += step[rows, axis]
            c_ax = cell[rows, axis]
            done |= (c_ax < 0) | (c_ax >= upper[axis])
            fin = np.flatnonzero(done & live)
            if len(fin):
                tau[ids[fin]] = acc[fin]
                live[fin] = False
                te[fin] = tc[fin]  # from here on t_end = tc: nothing more
                n_live -= len(fin)
            if n_live * 4 < len(ids) * 3:  # shrink once a quarter has finished
                keep = np.flatnonzero(live)
                state: list[Any] = [x[keep] for x in (ids, oo, dd, tc, te, acc, cell, step, inv, live)]
                ids, oo, dd, tc, te, acc, cell, step, inv, live = state
        return tau, n_cross

    def transmittance_ratio(self, seg: Segments) -> FloatArray:
        """(F, n) T_f / T_c = exp(-(tau_f - tau_c)) along the segments."""
        tau = self.depths(seg)
        out = tau[:, :-1] - tau[:, -1:]
        np.negative(out, out=out)
        np.exp(out, out=out)
        return out.T

    def scatter_ratios(self, points: FloatArray) -> FloatArray:
        """(F, n) sigma_s,f(x) / sigma_s,c(x) at points (n, 3) (0 outside the grid or where the carrier is clear)."""
        g = self.carrier
        idx, inside = g.cells(as_rows(points))
        flat = (idx[:, 0] * g.shape[1] + idx[:, 1]) * g.shape[2] + idx[:, 2]
        out = self.scatter_ratio.take(flat, axis=0)
        out[~inside] = 0.0
        return out.T

    # --- the kernel's interface (PathRatios) -----------------------------------------------------------------
    def initial_ratio(self, n: int) -> FloatArray:
        """(F, n) ones."""
        return np.ones((self.n_bands, n))

    def reflect(self, ratio: FloatArray, prims: IntArray) -> FloatArray:
        """Surfaces are the same in every frame: unchanged."""
        return ratio

    def turn(self, ratio: FloatArray, cos: FloatArray) -> FloatArray:
        """The phase function is the same in every frame: unchanged."""
        return ratio

    def phase_ratio(self, cos: FloatArray) -> FloatArray:
        """(F, m) ones: one phase function for every frame."""
        return np.ones((self.n_bands, len(cos)))

    def transmit(self, ratio: FloatArray, tau: FloatArray, seg: Segments | None = None) -> FloatArray:
        """After segments `seg` without collision: r_f T_f / T_c."""
        assert seg is not None, "frames need the segments"
        return ratio * self.transmittance_ratio(seg)

    def transmit_rows(
        self, ratio: FloatArray, rows: IntArray, tau: FloatArray, seg: Segments | None = None
    ) -> FloatArray:
        """`transmit` for the paths `rows` only (`seg` holds their segments)."""
        assert seg is not None, "frames need the segments"
        out = ratio.copy()
        out[:, rows] *= self.transmittance_ratio(seg)
        return out

    def scatter(self, ratio: FloatArray, tau: FloatArray, seg: Segments | None = None) -> FloatArray:
        """Scattered at the segments' ends x: r_f sigma_s,f(x) T_f / (sigma_s,c(x) T_c)."""
        assert seg is not None, "frames need the segments"
        o, d = as_rows(seg[0]), as_rows(seg[1])
        L = np.asarray(seg[2], np.float64).reshape(-1)
        return ratio * self.transmittance_ratio((o, d, L)) * self.scatter_ratios(o + L[:, None] * d)

    def estimate_ratio(
        self, ratio: FloatArray, tau: FloatArray | None = None, seg: Segments | None = None
    ) -> FloatArray:
        """(F, m) ratios of estimates from path states `ratio`, their connections `seg` (None: none)."""
        return ratio if seg is None else ratio * self.transmittance_ratio(seg)


class FramedGrid(GridMedium):
    """The carrier as the kernel's medium: its optical depths come from the walk that also gives every frame's
    (`FrameRatios.walk`), so the ratios of the same segments asked next cost no second walk."""

    def __init__(self, carrier: GridMedium, ratios: FrameRatios):
        super().__init__(carrier.lo, carrier.hi, carrier.shape, 0.0, carrier.sigma_s_grid, carrier.phase_spec)
        self.sigma_t_grid = carrier.sigma_t_grid  # (the carrier's own sums: the same numbers)
        self._sigma_t_max, self.sigma_t_min = carrier.sigma_t_max, carrier.sigma_t_min
        self.ratios = ratios

    def _optical_depth(self, o: FloatArray, d: FloatArray, L: FloatArray) -> tuple[FloatArray, int]:
        tau, n = self.ratios.walk(o, d, L)
        return tau[:, -1].copy(), n


def effective_fraction(rel2_carrier: FloatArray, rel2_frames: FloatArray) -> FloatArray:
    """ESS_f / ESS_c = (1 + cv_c^2) / (1 + cv_f^2) from the per-path relative second moments cv^2 = Var / mean^2 of
    the carrier's estimate (...,) and the frames' (F, ...) (module docstring); 1 where a frame has no estimate."""
    c = np.asarray(rel2_carrier, np.float64)
    f = np.asarray(rel2_frames, np.float64)
    ok = np.isfinite(f) & np.isfinite(c)
    return np.where(ok, (1.0 + np.where(ok, c, 0.0)) / (1.0 + np.where(ok, f, 0.0)), 1.0)
