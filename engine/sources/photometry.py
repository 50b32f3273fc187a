"""Luminaires from photometric files: IES LM-63 (1986/1991, 1995, 2002, 2019) and EULUMDAT (.ldt).

A photometric file tabulates the luminous intensity I(gamma, C) [cd] of a luminaire in
type-C photometry: gamma in [0, 180] deg is the polar angle from the luminaire's axis
(gamma = 0 is nadir for a downlight: the aiming direction), C in [0, 360) deg the
azimuth of the half-plane, C = 90 deg counter-clockwise from C = 0 seen from behind the
luminaire (from above a downlight; IES LM-63-2019 sec. 5.15, CIE 121-1996).

Interpolation: bilinear in (gamma, C). Neither LM-63 nor the EULUMDAT description fixes
a rule; linear interpolation between the measured angles is what lighting programs apply
to these tables (CIE 121-1996 discusses the grids it suits). Outside the file's gamma
range the intensity is 0; C is periodic. Symmetric files (rotational, bilateral about
C0-C180 or C90-C270, quadrant) are expanded to the full C range first; since the mirror
images fall on grid lines, interpolating the expanded table is the same as interpolating
the folded one.

Normalisation: the engine works per watt emitted, so the pattern is divided by its total
flux Phi = int I dOmega computed exactly for the interpolated table (`flux`): the
response R(gamma, C) = I(gamma, C) / Phi [1/sr] integrates to 1 and a sampled ray carries
weight 1, as for the Lambertian model. The flux the file declares (lamp lumens x
multiplier, or EULUMDAT lamp flux x LOR) is kept as `declared_flux` for comparison. The flux is
computed on the table divided by the power of two of its largest value (exact, so intensities up
to the float max do not overflow it); an intensity that is not a finite number is refused naming
its angles, and so is a luminous flux above MAX_PHOTOMETRIC (1e8 lm, the bound of
`luminous_output.luminous_flux`).

Sampling (exact, 2-D inverse CDF of the interpolated table): the density in (gamma, C) is
R sin(gamma). On a cell [g_i, g_i+1] x [C_j, C_j+1] with the bilinear I, integrating
over C gives a + b (gamma - g_i) (linear), so the cell's mass is a S0 + b S1 with
S0 = cos g_i - cos g_i+1, S1 = sin g_i+1 - sin g_i - dg cos g_i+1 (closed form). A cell is
chosen by its mass (the uniform is re-used after remapping), gamma inverts the cell's
CDF a (cos g_i - cos g) + b (sin g - sin g_i - (g - g_i) cos g) by Newton iterations
(residual below 1e-10 of the cell's probability, ~1e-11 rad), and C, whose conditional
density is linear on [C_j, C_j+1], by the closed-form root of a quadratic.

The files are read in photometry_files.py (`parse_ies`, `parse_ldt`, `parse_photometry`).
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass, field

import numpy as np

from owcsim.engine.core.errors import SceneError
from owcsim.engine.core.sampling import GuideTable
from owcsim.schemas.link_budget import MAX_PHOTOMETRIC

__all__ = ["Photometry", "PhotometryError", "luminaire_frame"]


class PhotometryError(SceneError):
    """A photometric file that cannot be used; the message names the line and the field. `loc`: the document's
    field it came from ("transmitters.0.photometry.data_base64"), set by the scene's loader (None otherwise)."""

    loc: str | None = None


@dataclass
class Photometry:
    """A tabulated luminous intensity, normalised to a radiant intensity per watt.

    `gamma` (n_g,) and `c` (n_c,) are increasing angles [rad]; `c` runs from 0 to 2 pi
    (the last column repeats the first). `intensity` (n_c, n_g) is I / Phi [1/sr].
    """

    gamma: np.ndarray
    c: np.ndarray
    intensity: np.ndarray
    flux: float  # int I dOmega of the file's table, in the file's unit [lm] (or [W])
    declared_flux: float | None = None  # what the file states [lm], None for absolute photometry
    #: factor from the table to the luminaire's intensities [cd] (IES: the ballast factor; EULUMDAT: 1)
    candela_scale: float = 1.0
    source: str = ""  # "IES LM-63-2002", "EULUMDAT", ...
    symmetry: str = "none"
    #: cumulative cell masses, (n_c-1)*(n_g-1)+1 (`from_table` computes them)
    _cdf: np.ndarray = field(default_factory=lambda: np.zeros(0), repr=False)

    @classmethod
    def from_table(
        cls,
        gamma_deg,
        c_deg,
        candela,
        *,
        declared_flux=None,
        source="",
        symmetry="none",
        where="photometry",
        candela_scale=1.0,
    ) -> "Photometry":
        """From a full table: `c_deg` from 0 to 360 inclusive, `candela` (n_c, n_g) [cd]."""
        g = np.radians(np.asarray(gamma_deg, float))
        c = np.radians(np.asarray(c_deg, float))
        table = np.asarray(candela, float)
        _check_finite(table, c_deg, gamma_deg, where)
        # the common factor first: table = t 2^e with max t in [0.5, 1) (exact), so that the flux of values up to
        # the float max is computed without overflow (an ordinary table gives the same bits as without)
        exponent = int(np.frexp(table.max())[1]) if table.size else 0
        scaled = np.ldexp(table, -exponent)
        masses = _cell_masses(g, c, scaled)
        scaled_flux = float(masses.sum())
        if not scaled_flux > 0:
            raise PhotometryError(f"{where}: every intensity in the table is 0: the luminaire emits nothing")
        flux = _ldexp_or_inf(scaled_flux, exponent)
        lumens = flux * candela_scale
        if not lumens <= MAX_PHOTOMETRIC:
            size = f"{lumens:.4g} lm" if math.isfinite(lumens) else "beyond the largest number a double holds"
            raise PhotometryError(
                f"{where}: the table's luminous flux is {size} (intensities up to {table.max():.4g} cd), more "
                f"than the {MAX_PHOTOMETRIC:.0e} lm a luminaire may have (as luminous_output.luminous_flux): "
                "check the candela multiplier or the conversion factor"
            )
        cdf = np.concatenate([[0.0], np.cumsum(masses.ravel())]) / scaled_flux
        cdf[-1] = 1.0
        return cls(
            gamma=g,
            c=c,
            intensity=scaled / scaled_flux,
            flux=flux,
            declared_flux=declared_flux,
            source=source,
            symmetry=symmetry,
            candela_scale=candela_scale,
            _cdf=cdf,
        )

    @property
    def luminous_flux(self) -> float:
        """The luminaire's luminous flux [lm]: int I dOmega of its candela (IES: the table x candela multiplier x
        ballast factor, in absolute and relative photometry alike, relative photometry's candela being those of
        the rated lamps; EULUMDAT: cd/klm x lamp flux / 1000 x conversion factor, i.e. lamp flux x LOR)."""
        return self.flux * self.candela_scale

    @functools.cached_property
    def max_gamma(self) -> float:
        """Largest gamma with light [rad] (> pi/2: the luminaire also emits backwards)."""
        lit = np.flatnonzero(self.intensity.max(axis=0) > 0)
        return float(self.gamma[min(lit[-1] + 1, len(self.gamma) - 1)]) if len(lit) else 0.0

    @functools.cached_property
    def _flat(self) -> np.ndarray:
        """The table flattened (C-major): corner (j, i) is at j * n_g + i (one `take` per corner)."""
        return np.ascontiguousarray(self.intensity).ravel()

    @functools.cached_property
    def _guide(self):
        """O(1) cell lookup by the cumulative masses (sampling.GuideTable: the same cell as a binary search)."""
        return GuideTable(self._cdf, 0.0, 1.0)

    @functools.cached_property
    def _inv_steps(self) -> tuple[np.ndarray, np.ndarray]:
        """1 / (grid step) per gamma cell and per C cell."""
        return 1.0 / np.diff(self.gamma), 1.0 / np.diff(self.c)

    def _corners(self, j, i):
        """The table at the four corners of cells (j, i): (j, i), (j, i+1), (j+1, i), (j+1, i+1)."""
        n_g, flat = len(self.gamma), self._flat
        k = j * n_g + i
        return flat.take(k), flat.take(k + 1), flat.take(k + n_g), flat.take(k + n_g + 1)

    @functools.cached_property
    def _even_steps(self) -> tuple[float | None, float | None]:
        """The gamma and C grid steps when evenly spaced (the usual 2.5, 5 or 15 deg), else None."""
        return _even_step(self.gamma.tobytes()), _even_step(self.c.tobytes())

    def eval_angles(self, gamma, c) -> np.ndarray:
        """R(gamma, C) [1/sr]: bilinear interpolation of the table; 0 outside its gamma range."""
        gamma, c = np.asarray(gamma, float), np.mod(np.asarray(c, float), 2 * np.pi)
        g, cc = self.gamma, self.c
        i, s = _cell_and_fraction(g, gamma, self._even_steps[0], self._inv_steps[0])
        j, t = _cell_and_fraction(cc, c, self._even_steps[1], self._inv_steps[1])
        t00, t01, t10, t11 = self._corners(j, i)
        lo = t00 + s * (t01 - t00)
        val = lo + t * (t10 + s * (t11 - t10) - lo)
        if g[0] > 0 or g[-1] < np.pi:  # gamma = arccos(.) lies in [0, pi]: outside the file's range, 0
            val = np.where((gamma >= g[0]) & (gamma <= g[-1]), val, 0.0)
        return val

    def eval_local(self, local) -> np.ndarray:
        """R at local directions (..., 3) (z along the aiming axis, x along C = 0, y along C = 90)."""
        local = np.asarray(local, float)
        return self.eval_rows(local[..., 0], local[..., 1], local[..., 2])

    def eval_rows(self, x, y, z) -> np.ndarray:
        """R at local directions given as component arrays x, y, z."""
        return self.eval_angles(np.arccos(np.clip(z, -1.0, 1.0)), np.arctan2(y, x))

    def sample_angles(self, u1, u2, with_trig: bool = False):
        """(gamma, C) [rad] with density R(gamma, C) sin(gamma) (exact inversion, module docstring);
        `with_trig`: also (cos gamma, sin gamma), which the inversion computes anyway."""
        u1, u2 = np.asarray(u1, float), np.asarray(u2, float)
        n_g = len(self.gamma) - 1
        # cells of zero mass are never chosen: the lookup (searchsorted(side="right") - 1) skips them
        cell = self._guide.find(u1)
        lo, hi = self._cdf.take(cell), self._cdf.take(cell + 1)
        v = np.clip((u1 - lo) / np.where(hi > lo, hi - lo, 1.0), 0.0, 1.0)
        j, i = np.divmod(cell, n_g)
        g0, g1 = self.gamma.take(i), self.gamma.take(i + 1)
        t00, t01, t10, t11 = self._corners(j, i)
        dg = g1 - g0
        a = t00 + t10  # the common factor dC / 2 cancels
        b = (t01 + t11 - a) / dg
        cos_g, sin_g = _trig(self.gamma)[:2]
        trig = (cos_g.take(i), sin_g.take(i), cos_g.take(i + 1), sin_g.take(i + 1))
        gamma, cx, sx = _invert_gamma_cdf(a, b, g0, g1, v, trig=trig, with_trig=True)
        s = np.clip((gamma - g0) / dg, 0.0, 1.0)
        ca = t00 + s * (t01 - t00)  # density along C: (1 - t) ca + t cb
        cb = t10 + s * (t11 - t10)
        root = np.sqrt(np.maximum(ca * ca + u2 * (cb * cb - ca * ca), 0.0))
        den = ca + root
        t = np.where(den > 0, u2 * (ca + cb) / np.where(den > 0, den, 1.0), u2)
        c0 = self.c.take(j)
        c = c0 + np.clip(t, 0.0, 1.0) * (self.c.take(j + 1) - c0)
        return (gamma, c, cx, sx) if with_trig else (gamma, c)

    def sample_rows(self, u1, u2) -> np.ndarray:
        """Local directions (3, n) (component rows) with pdf R (solid angle).

        The azimuth's cosine and sine are evaluated in float32 and renormalised in float64
        (as sampling.cosine_about_soa: numpy vectorizes float32 trigonometry), so the
        azimuth is off by a few 1e-7 rad at most, far below Embree's float32 ray precision.
        """
        _, c, cg, sg = self.sample_angles(u1, u2, with_trig=True)
        c32 = c.astype(np.float32)
        cc, sc = np.cos(c32).astype(float), np.sin(c32).astype(float)
        scale = sg / np.sqrt(cc * cc + sc * sc)
        out = np.empty((3, len(cg)))
        np.multiply(scale, cc, out=out[0])
        np.multiply(scale, sc, out=out[1])
        out[2] = cg
        return out

    def sample_local(self, u1, u2) -> np.ndarray:
        """Local directions (n, 3) with pdf R (solid angle)."""
        return self.sample_rows(u1, u2).T


def _check_finite(table: np.ndarray, c_deg, gamma_deg, where: str) -> None:
    """PhotometryError naming the first intensity that is not a finite number, by its C and gamma angles."""
    bad = np.argwhere(~np.isfinite(table))
    if len(bad):
        j, i = (int(x) for x in bad[0])
        raise PhotometryError(
            f"{where}: the intensity at C = {float(np.asarray(c_deg)[j]):g} deg, gamma = "
            f"{float(np.asarray(gamma_deg)[i]):g} deg is {table[j, i]}, not a finite number"
        )


def _ldexp_or_inf(x: float, exponent: int) -> float:
    """x 2^exponent, inf past the float max (math.ldexp raises instead)."""
    try:
        return math.ldexp(x, exponent)
    except OverflowError:
        return math.inf


@functools.lru_cache(maxsize=64)
def _even_step(grid_bytes: bytes) -> float | None:
    """The step of an evenly spaced grid (given as float64 bytes), None if uneven."""
    grid = np.frombuffer(grid_bytes)
    step = (grid[-1] - grid[0]) / (len(grid) - 1)
    return step if np.allclose(np.diff(grid), step, rtol=1e-9, atol=0.0) else None


def _cell_index(grid: np.ndarray, x: np.ndarray) -> np.ndarray:
    """Index i of the cell grid[i] <= x < grid[i+1] (unclipped): arithmetic on an even grid, else a search."""
    step = _even_step(grid.tobytes())
    if step is not None:  # the usual case: 2.5, 5 or 15 deg steps
        i = np.floor((x - grid[0]) * (1.0 / step)).astype(np.int64)
        # rounding at a grid line: step back where x falls below the cell's start
        i -= (i > 0) & (i < len(grid)) & (x < grid[np.clip(i, 0, len(grid) - 1)])
        return i
    return np.searchsorted(grid, x, side="right") - 1


def _cell_and_fraction(grid: np.ndarray, x: np.ndarray, step: float | None, inv_steps: np.ndarray):
    """(cell i, fraction s in [0, 1]) of x on the grid, for bilinear interpolation (clipped to the grid).

    Even grid: i = floor((x - grid[0]) / step), s its fractional part; a value on a grid line
    may land at s = 1 of one cell or s = 0 of the next, the same interpolated value (to rounding).
    """
    last = len(grid) - 2
    if step is not None:
        y = (x - grid[0]) * (1.0 / step)
        i = np.clip(y.astype(np.int64), 0, last)  # truncation: y < 0 (outside, zeroed by the caller) -> 0
        return i, np.clip(y - i, 0.0, 1.0)
    i = np.clip(_cell_index(grid, x), 0, last)
    return i, np.clip((x - grid.take(i)) * inv_steps.take(i), 0.0, 1.0)


def _cell_masses(g: np.ndarray, c: np.ndarray, table: np.ndarray) -> np.ndarray:
    """int int I(gamma, C) sin(gamma) dgamma dC per cell (n_c - 1, n_g - 1), bilinear I, exact."""
    dg = np.diff(g)
    dc = np.diff(c)[:, None]
    s0 = np.cos(g[:-1]) - np.cos(g[1:])
    s1 = np.sin(g[1:]) - np.sin(g[:-1]) - dg * np.cos(g[1:])
    a = 0.5 * dc * (table[:-1, :-1] + table[1:, :-1])
    b = (0.5 * dc * (table[:-1, 1:] + table[1:, 1:]) - a) / dg
    return np.maximum(a * s0 + b * s1, 0.0)


@functools.lru_cache(maxsize=16)
def _trig_cached(grid_bytes: bytes) -> tuple[np.ndarray, np.ndarray]:
    grid = np.frombuffer(grid_bytes)
    return np.cos(grid), np.sin(grid)


def _trig(grid: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(cos, sin, cos, sin) of the grid angles: gathered at i, i, i+1, i+1 by the sampler."""
    c, s = _trig_cached(grid.tobytes())
    return c, s, c, s


def _invert_gamma_cdf(a, b, g0, g1, v, iterations: int = 60, trig=None, with_trig: bool = False):
    """Solve F(g) = v F(g1) on [g0, g1], F(g) = int_g0^g (a + b (x - g0)) sin x dx.

    Start: the exact inverse for the intensity taken linear in cos(gamma) over the cell
    (relative error ~1e-3 of the cell); then two Newton steps on every sample (kept inside
    the cell; quadratic convergence: ~1e-11 rad), taken in mu = cos(gamma), where a step
    needs arccos and a square root (vectorized by numpy) instead of cos and sin; the rare
    samples whose residual is still above 1e-10 F(g1) continue with Newton steps safeguarded by bisection on a bracket
    (at most `iterations`, to 1e-12 rad). `with_trig`: returns (x, cos x, sin x).
    """
    shape = np.shape(v)
    a, b, g0, g1, v = (
        x if np.shape(x) == shape else np.broadcast_to(x, shape)
        for x in (np.asarray(y, float) for y in (a, b, g0, g1, v))
    )
    # cos, sin of the cell's ends (`trig`: precomputed and gathered by the caller)
    cos0, sin0, cos1, sin1 = trig if trig is not None else (np.cos(g0), np.sin(g0), np.cos(g1), np.sin(g1))
    total = a * (cos0 - cos1) + b * (sin1 - sin0 - (g1 - g0) * cos1)
    target = v * total
    ia, ib = a, a + b * (g1 - g0)
    root = np.sqrt(np.maximum(ia * ia + v * (ib * ib - ia * ia), 0.0))
    den = ia + root
    t = np.where(den > 0, v * (ia + ib) / np.where(den > 0, den, 1.0), v)
    mu = np.clip(cos0 - t * (cos0 - cos1), cos1, cos0)  # the start, in mu = cos(gamma)

    def residual(x, cos0, sin0, a, b, g0, target):
        cx, sx = np.cos(x), np.sin(x)
        return a * (cos0 - cx) + b * (sx - sin0 - (x - g0) * cx) - target, (a + b * (x - g0)) * sx

    # Newton in mu: F(mu) = a (cos0 - mu) + b (sin x - sin0 - (x - g0) mu), x = arccos(mu), dF/dmu = -(a + b (x - g0)):
    # arccos and sqrt (vectorized by numpy) instead of cos and sin (not vectorized) at every step
    with np.errstate(divide="ignore", invalid="ignore"):
        for _ in range(2):
            x = np.arccos(mu)
            sx = np.sqrt((1.0 - mu) * (1.0 + mu))
            f = a * (cos0 - mu) + b * (sx - sin0 - (x - g0) * mu) - target
            dens = a + b * (x - g0)
            mu = np.clip(np.where(dens > 0, mu + f / dens, mu), cos1, cos0)
    x = np.clip(np.arccos(mu), g0, g1)
    cx, sx = mu, np.sqrt((1.0 - mu) * (1.0 + mu))
    f = a * (cos0 - cx) + b * (sx - sin0 - (x - g0) * cx) - target
    act = np.flatnonzero(~(np.abs(f) <= 1e-10 * total))
    if len(act) == 0:
        return (x, cx, sx) if with_trig else x
    # safeguarded Newton (bisection when a step leaves the bracket) for the few left
    x = x.copy()
    xa, ga, g1a, aa, ba, c0, s0, ta = x[act], g0[act], g1[act], a[act], b[act], cos0[act], sin0[act], target[act]
    lo, hi = ga.copy(), g1a.copy()
    for _ in range(iterations):
        f, dens = residual(xa, c0, s0, aa, ba, ga, ta)
        lo = np.where(f <= 0, xa, lo)
        hi = np.where(f > 0, xa, hi)
        with np.errstate(divide="ignore", invalid="ignore"):
            step = xa - f / dens
        bad = ~np.isfinite(step) | (step < lo) | (step > hi)
        new = np.where(bad, 0.5 * (lo + hi), step)
        done = np.all((np.abs(new - xa) < 1e-12) | (hi - lo < 1e-12))
        xa = new
        if done:
            break
    x[act] = xa
    if with_trig:
        cx[act], sx[act] = np.cos(xa), np.sin(xa)
        return x, cx, sx
    return x


def luminaire_frame(aim, c0_direction=None, rotation_deg: float = 0.0) -> np.ndarray:
    """Rows (e_C0, e_C90, aim): local (x, y, z) -> world is `local @ frame`.

    e_C0 is `c0_direction` (default: world +x, or +y if the aim is along x) made
    perpendicular to the aim, then turned by `rotation_deg` about the aim so that
    C = 90 deg lies counter-clockwise seen from behind the luminaire:
    e_C90 = e_C0 x aim (for a downlight aimed at -z with C0 along +x, C90 is +y).
    """
    aim = np.asarray(aim, float)
    aim = aim / np.linalg.norm(aim)
    ref = np.asarray(
        c0_direction if c0_direction is not None else ((1.0, 0.0, 0.0) if abs(aim[0]) < 0.9 else (0.0, 1.0, 0.0)), float
    )
    e0 = ref - (ref @ aim) * aim
    norm = np.linalg.norm(e0)
    if norm < 1e-6:
        raise SceneError("photometry.c0_direction is parallel to the aiming direction (the normal)")
    e0 /= norm
    e90 = np.cross(e0, aim)
    r = math.radians(rotation_deg)
    e0, e90 = math.cos(r) * e0 + math.sin(r) * e90, -math.sin(r) * e0 + math.cos(r) * e90
    return np.stack((e0, e90, aim))
