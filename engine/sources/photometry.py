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
multiplier, or EULUMDAT lamp flux x LOR) is kept as `declared_flux` for comparison.

Sampling (exact, 2-D inverse CDF of the interpolated table): the density in (gamma, C) is
R sin(gamma). On a cell [g_i, g_i+1] x [C_j, C_j+1] with the bilinear I, integrating
over C gives a + b (gamma - g_i) (linear), so the cell's mass is a S0 + b S1 with
S0 = cos g_i - cos g_i+1, S1 = sin g_i+1 - sin g_i - dg cos g_i+1 (closed form). A cell is
chosen by its mass (the uniform is re-used after remapping), gamma inverts the cell's
CDF a (cos g_i - cos g) + b (sin g - sin g_i - (g - g_i) cos g) by Newton iterations
(residual below 1e-10 of the cell's probability, ~1e-11 rad), and C, whose conditional
density is linear on [C_j, C_j+1], by the closed-form root of a quadratic.
"""

from __future__ import annotations

import functools
import math
import re
from dataclasses import dataclass, field

import numpy as np

from owcsim.engine.core.errors import SceneError
from owcsim.engine.core.sampling import GuideTable

__all__ = ["Photometry", "PhotometryError", "parse_ies", "parse_ldt", "parse_photometry"]


class PhotometryError(SceneError):
    """A photometric file that cannot be used; the message names the line and the field."""


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
        masses = _cell_masses(g, c, table)
        flux = float(masses.sum())
        if not flux > 0:
            raise PhotometryError(f"{where}: every intensity in the table is 0: the luminaire emits nothing")
        cdf = np.concatenate([[0.0], np.cumsum(masses.ravel())]) / flux
        cdf[-1] = 1.0
        return cls(
            gamma=g,
            c=c,
            intensity=table / flux,
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


# ----------------------------------------------------------------------------- symmetry
_FOLDS = {  # symmetry -> the maps C -> C' that leave the distribution unchanged [deg]
    "none": (lambda c: c,),
    "bilateral_c0_c180": (lambda c: c, lambda c: 360.0 - c),
    "bilateral_c90_c270": (lambda c: c, lambda c: 180.0 - c),
    "quadrant": (lambda c: c, lambda c: 360.0 - c, lambda c: 180.0 - c, lambda c: 180.0 + c),
}


def _expand(c_deg: np.ndarray, rows: np.ndarray, symmetry: str, where: str) -> tuple[np.ndarray, np.ndarray]:
    """Stored C planes (any subset of [0, 360)) and a symmetry -> full table on C in [0, 360]."""
    if symmetry == "rotational":
        return np.array([0.0, 360.0]), np.vstack([rows[0], rows[0]])
    values: dict[float, np.ndarray] = {}
    for fold in _FOLDS[symmetry]:
        for angle, row in zip(c_deg, rows):
            key = round(float(fold(angle)) % 360.0, 6)
            if key in values and not np.allclose(values[key], row, rtol=1e-6, atol=1e-9 * rows.max()):
                raise PhotometryError(
                    f"{where}: the C-plane at {key:g} deg is given twice with different "
                    f"intensities (symmetry {symmetry})"
                )
            values.setdefault(key, row)
    if 0.0 not in values:
        raise PhotometryError(f"{where}: no C-plane at 0 deg (or its mirror image): cannot cover 0..360 deg")
    keys = sorted(values)
    return np.array(keys + [360.0]), np.vstack([values[k] for k in keys] + [values[0.0]])


# ----------------------------------------------------------------------------- IES LM-63
_IES_TAGS = {
    "IESNA:LM-63-1995": "IES LM-63-1995",
    "IESNA:LM-63-2002": "IES LM-63-2002",
    "IES:LM-63-2019": "IES LM-63-2019",
    "IESNA91": "IES LM-63-1991",
    "IESNA:LM-63-1991": "IES LM-63-1991",
}
_NUMBER = re.compile(r"^[+-]?(\d+\.?\d*|\.\d+)([eE][+-]?\d+)?$")


class _Tokens:
    """Whitespace/comma separated numbers with their line numbers, for located errors."""

    def __init__(self, lines: list[str], first_line: int, where: str):
        self.items = [
            (tok, first_line + k) for k, line in enumerate(lines) for tok in re.split(r"[\s,]+", line.strip()) if tok
        ]
        self.pos, self.where = 0, where
        self.last_line = first_line + len(lines) - 1

    def number(self, what: str, *, integer: bool = False) -> float:
        if self.pos >= len(self.items):
            raise PhotometryError(f"{self.where}: the file ends (line {self.last_line}) before {what}")
        tok, line = self.items[self.pos]
        self.pos += 1
        if not _NUMBER.match(tok):
            raise PhotometryError(f"{self.where}: line {line}: {what} should be a number, found {tok!r}")
        val = float(tok)
        if integer and val != int(val):
            raise PhotometryError(f"{self.where}: line {line}: {what} should be a whole number, found {tok!r}")
        return val

    def numbers(self, n: int, what: str) -> np.ndarray:
        return np.array([self.number(f"{what} ({k + 1} of {n})") for k in range(n)])

    def line(self) -> int:
        return self.items[min(self.pos, len(self.items) - 1)][1] if self.items else self.last_line


def _decode(data: bytes) -> list[str]:
    if data[:3] == b"\xef\xbb\xbf":
        data = data[3:]
    try:
        text = data.decode("utf-8")
    except UnicodeDecodeError:
        text = data.decode("latin-1")  # files from Windows tools; every byte decodes
    return text.replace("\r\n", "\n").replace("\r", "\n").split("\n")


def _check_angles(values: np.ndarray, what: str, lo: float, hi: float, where: str, line: int) -> None:
    if np.any(np.diff(values) <= 0):
        raise PhotometryError(f"{where}: near line {line}: {what} must increase strictly: {values.tolist()}")
    if values[0] < lo - 1e-9 or values[-1] > hi + 1e-9:
        raise PhotometryError(
            f"{where}: near line {line}: {what} must lie in [{lo:g}, {hi:g}] deg, found {values[0]:g}..{values[-1]:g}"
        )


def parse_ies(data: bytes, where: str = "photometry") -> Photometry:
    """Parse an IES LM-63 file (1986/1991/1995/2002/2019), type-C photometry.

    Layout (LM-63-2002 sec. 5, LM-63-2019 sec. 5): a version line, keyword lines,
    `TILT=NONE|INCLUDE` (tilt data is read and not applied: it corrects lamp output for
    a tilted HID lamp, and we take the luminaire as measured), then the numbers:
    lamps, lumens per lamp (-1: absolute photometry), candela multiplier, number of
    vertical and horizontal angles, photometric type (1 = C), units, width, length,
    height, ballast factor, a reserved/file-generation field, input watts, the vertical
    angles, the horizontal angles and the candela values (one row per horizontal angle).
    """
    lines = _decode(data)
    first = lines[0].strip() if lines else ""
    source = _IES_TAGS.get(first.upper(), "IES LM-63-1986")
    if source == "IES LM-63-1986" and first.upper().startswith("IES"):
        raise PhotometryError(
            f"{where}: line 1: unknown IES version tag {first!r} (known: {', '.join(sorted(_IES_TAGS))})"
        )
    tilt = next((k for k, line in enumerate(lines) if line.strip().upper().startswith("TILT")), None)
    if tilt is None:
        raise PhotometryError(f"{where}: no TILT= line: not an IES LM-63 file")
    mode = lines[tilt].split("=", 1)[1].strip().upper() if "=" in lines[tilt] else ""
    tok = _Tokens(lines[tilt + 1 :], tilt + 2, where)
    if mode == "INCLUDE":
        tok.number("the lamp-to-luminaire geometry (TILT=INCLUDE)", integer=True)
        n_tilt = int(tok.number("the number of tilt angles", integer=True))
        tok.numbers(n_tilt, "tilt angles")
        tok.numbers(n_tilt, "tilt multiplying factors")
    elif mode != "NONE":
        raise PhotometryError(
            f"{where}: line {tilt + 1}: TILT={mode or '?'} names an external tilt file; "
            "only TILT=NONE or TILT=INCLUDE can be read"
        )
    n_lamps = tok.number("the number of lamps", integer=True)
    lumens = tok.number("the lumens per lamp")
    multiplier = tok.number("the candela multiplier")
    line = tok.line()
    n_v = int(tok.number("the number of vertical angles", integer=True))
    n_h = int(tok.number("the number of horizontal angles", integer=True))
    ptype = int(tok.number("the photometric type", integer=True))
    tok.number("the units type", integer=True)
    for what in ("the luminous width", "the luminous length", "the luminous height"):
        tok.number(what)
    ballast = tok.number("the ballast factor")
    tok.number("the ballast-lamp factor / file generation type")
    tok.number("the input watts")
    if n_lamps < 1 or not (lumens > 0 or lumens == -1) or not multiplier > 0 or not ballast > 0:
        raise PhotometryError(
            f"{where}: near line {line}: need lamps >= 1, lumens per lamp > 0 (or -1), "
            f"candela multiplier > 0 and ballast factor > 0; found {n_lamps:g}, {lumens:g}, "
            f"{multiplier:g}, {ballast:g}"
        )
    if ptype != 1:
        raise PhotometryError(
            f"{where}: near line {line}: photometric type {ptype} ({'B' if ptype == 2 else 'A'}) "
            "is not supported: owcsim reads type C (1), the type of indoor luminaires"
        )
    if n_v < 2 or n_h < 1:
        raise PhotometryError(
            f"{where}: near line {line}: need at least 2 vertical angles and 1 horizontal angle, found {n_v} and {n_h}"
        )
    line = tok.line()
    v = tok.numbers(n_v, "vertical angles")
    _check_angles(v, "vertical angles", 0.0, 180.0, where, line)
    line = tok.line()
    h = tok.numbers(n_h, "horizontal angles")
    _check_angles(h, "horizontal angles", 0.0, 360.0, where, line)
    line = tok.line()
    cd = tok.numbers(n_h * n_v, "candela values").reshape(n_h, n_v)
    if tok.pos < len(tok.items):
        extra, at = tok.items[tok.pos]
        raise PhotometryError(f"{where}: line {at}: unexpected value {extra!r} after the {n_h} x {n_v} candela table")
    if np.any(cd < 0):
        raise PhotometryError(f"{where}: near line {line}: negative candela values")
    if n_h == 1:
        if h[0] != 0:
            raise PhotometryError(f"{where}: near line {line}: a single horizontal angle must be 0 deg")
        symmetry = "rotational"
    elif h[0] == 0 and h[-1] == 90:
        symmetry = "quadrant"
    elif h[0] == 0 and h[-1] == 180:
        symmetry = "bilateral_c0_c180"
    elif h[0] == 90 and h[-1] == 270:
        symmetry = "bilateral_c90_c270"
    elif h[0] == 0 and h[-1] > 180:
        symmetry = "none"
        if h[-1] == 360:
            if not np.allclose(cd[-1], cd[0], rtol=1e-6, atol=1e-9 * cd.max()):
                raise PhotometryError(f"{where}: the horizontal angles 0 and 360 deg have different candela values")
            h, cd = h[:-1], cd[:-1]
    else:
        raise PhotometryError(
            f"{where}: horizontal angles {h[0]:g}..{h[-1]:g} deg: LM-63 type C allows 0 (one "
            "angle), 0..90, 0..180, 90..270 or 0..360"
        )
    c_full, rows = _expand(h, cd * multiplier, symmetry, where)
    declared = None if lumens == -1 else float(n_lamps * lumens * multiplier * ballast)
    return Photometry.from_table(
        v, c_full, rows, declared_flux=declared, source=source, symmetry=symmetry, where=where, candela_scale=ballast
    )


# ----------------------------------------------------------------------------- EULUMDAT
_LDT_SYMMETRY = {0: "none", 1: "rotational", 2: "bilateral_c0_c180", 3: "bilateral_c90_c270", 4: "quadrant"}


def parse_ldt(data: bytes, where: str = "photometry") -> Photometry:
    """Parse a EULUMDAT file (Stockmar 1990, "EULUMDAT: Datenformat"; line numbers as there).

    Lines 1-12: company, Ityp, Isym, Mc, Dc, Ng, Dg, report, name, number, file name,
    date; 13-21 dimensions [mm]; 22 DFF, 23 LOR [%], 24 conversion factor, 25 tilt,
    26 number n of lamp sets, then n x (number of lamps, type, flux [lm], colour,
    CRI, watts), 10 direct ratios, Mc C angles, Ng gamma angles, and the intensities
    [cd/klm] of the stored C planes (Isym 0: all Mc; 1: one; 2: C0..C180; 3: C270..C90
    through C0; 4: C0..C90), Ng values each. Decimal commas are accepted.
    """
    lines = _decode(data)

    def field_(n: int, what: str, *, integer: bool = False) -> float:
        if n > len(lines):
            raise PhotometryError(f"{where}: the file ends before line {n} ({what})")
        text = lines[n - 1].strip().replace(",", ".")
        if not _NUMBER.match(text):
            raise PhotometryError(f"{where}: line {n}: {what} should be a number, found {lines[n - 1].strip()!r}")
        val = float(text)
        if integer and val != int(val):
            raise PhotometryError(f"{where}: line {n}: {what} should be a whole number, found {text!r}")
        return val

    isym = int(field_(3, "Isym (symmetry indicator)", integer=True))
    mc = int(field_(4, "Mc (number of C planes)", integer=True))
    ng = int(field_(6, "Ng (number of intensities per C plane)", integer=True))
    if isym not in _LDT_SYMMETRY:
        raise PhotometryError(f"{where}: line 3: Isym must be 0..4, found {isym}")
    if not 1 <= mc <= 721 or not 2 <= ng <= 361:
        raise PhotometryError(f"{where}: lines 4 and 6: need 1 <= Mc <= 721 and 2 <= Ng <= 361, found {mc} and {ng}")
    if (isym in (2, 3) and mc % 2) or (isym == 4 and mc % 4):
        raise PhotometryError(f"{where}: line 4: Mc = {mc} cannot be split by the symmetry Isym = {isym}")
    lor = field_(23, "LORL (light output ratio) [%]")
    factor = field_(24, "the conversion factor for intensities")
    n_sets = int(field_(26, "the number of lamp sets", integer=True))
    if n_sets < 1:
        raise PhotometryError(f"{where}: line 26: need at least one lamp set, found {n_sets}")
    lamp_flux = sum(field_(27 + 2 * n_sets + k, f"the luminous flux of lamp set {k + 1} [lm]") for k in range(n_sets))
    first = 27 + 6 * n_sets + 10  # first line of the C angles
    tok = _Tokens([ln.replace(",", ".") for ln in lines[first - 1 :]], first, where)
    c = tok.numbers(mc, "C angles")
    line = tok.line()
    g = tok.numbers(ng, "gamma angles")
    _check_angles(c, "C angles", 0.0, 360.0, where, first)
    _check_angles(g, "gamma angles", 0.0, 180.0, where, line)
    stored = {
        0: np.arange(mc),
        1: np.arange(1),
        2: np.arange(mc // 2 + 1),
        3: (3 * mc // 4 + np.arange(mc // 2 + 1)) % mc,
        4: np.arange(mc // 4 + 1),
    }[isym]
    if isym == 3 and mc % 4:
        raise PhotometryError(f"{where}: line 4: Isym = 3 needs Mc divisible by 4, found {mc}")
    line = tok.line()
    values = tok.numbers(len(stored) * ng, "intensities [cd/klm]").reshape(len(stored), ng)
    if tok.pos < len(tok.items):
        extra, at = tok.items[tok.pos]
        raise PhotometryError(f"{where}: line {at}: unexpected value {extra!r} after the intensity table")
    if np.any(values < 0):
        raise PhotometryError(f"{where}: near line {line}: negative intensities")
    if not factor > 0 or not lamp_flux > 0:
        raise PhotometryError(f"{where}: lines 24-26: the conversion factor and the lamp flux must be positive")
    expect = {2: (0.0, 180.0), 3: (270.0, 90.0), 4: (0.0, 90.0)}.get(isym)
    c_stored = c[stored]
    if expect is not None and (abs(c_stored[0] - expect[0]) > 1e-6 or abs(c_stored[-1] - expect[1]) > 1e-6):
        raise PhotometryError(
            f"{where}: line {first}: with Isym = {isym} the stored C planes must run from "
            f"{expect[0]:g} to {expect[1]:g} deg, found {c_stored[0]:g}..{c_stored[-1]:g}"
        )
    symmetry = _LDT_SYMMETRY[isym]
    c_full, rows = _expand(c_stored, values * factor * lamp_flux / 1000.0, symmetry, where)
    return Photometry.from_table(
        g,
        c_full,
        rows,
        declared_flux=float(lamp_flux * lor / 100.0) if lor > 0 else None,
        source="EULUMDAT",
        symmetry=symmetry,
        where=where,
    )


def parse_photometry(data: bytes, fmt: str, where: str = "photometry") -> Photometry:
    """Dispatch on the format ("ies" or "ldt")."""
    if fmt == "ies":
        return parse_ies(data, where)
    if fmt == "ldt":
        return parse_ldt(data, where)
    raise PhotometryError(f"{where}: unknown photometric format {fmt!r} (ies, ldt)")


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
