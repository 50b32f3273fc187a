"""Spectral scenes: B wavelength bands traced together, one throughput per band and path (docs/spectra.md).

The model. Within a band every curve is taken constant (its band average; the SPD is
integrated), so a path's power in band b is the product of its grey geometry (the same
for all bands) and the band's reflectances and transmittances. The kernel traces every
path once with a *carrier*: the grey scene whose surfaces reflect rho_c = max_b rho_b and
whose medium has sigma_t,c = min_b sigma_t,b (band c, the least attenuated). The path's
weight w is the carrier's; its per-band ratio r_b (`_Paths.ratio`, shape (B, n)) collects

    r_b *= rho_b(x) / rho_c(x)                at every reflection (the NEE from x too),
    r_b *= exp(-tau_c (sigma_t,b / sigma_t,c - 1))   on every segment (algorithm 1),

tau_c the carrier's optical depth (kept as a row of the state and applied at each estimate), so
that w r_b is exactly the band-b path weight. Reflections and extinction keep r_b <= 1 (the carrier
is the brightest band: roulette driven by w leaves every band's weight bounded by the carrier's);
scattering (below) multiplies by bounded constants. Bands share the paths and the random numbers,
so they differ only through these factors (a two-band run equals two one-band runs with the same
seed up to rounding, when the carrier's sampling decisions are the bands' own: no roulette, and
smoke that does not vary per band).

Channels tallied per link (engine/tally/spectral.py, one contraction per path group and kernel step), V = B + 3:
  - band b: H_b, gain per watt emitted in band b [-];
  - optical: H = sum_b f_b H_b, f_b the transmitter's power fraction in band b [-] (also the
    main tally, so the result's dc_gain, CIR and delay figures are those of the whole spectrum);
  - electrical: G = sum_b f_b T_b R_b H_b [A/W], R_b the responsivity, T_b the filter;
  - luminous: H_v = sum_b f_b K_m Vbar_b H_b [lm/W], Vbar_b the SPD-weighted mean of V(lambda)
    over the band; illuminance E_v = P_t H_v / (A T_s g) [lx] (the illuminance a cosine sensor
    with the receiver's field of view reads, all reflection orders included).
Per-band smoke: homogeneous coefficients per band, or Mie per band centre for particles
(engine/media/mie.py). Algorithms 1-4 in any spectral scene: a scattering point p placed by the carrier
(points on segments, or a collision starting a branch of single_scatter.first_segment_branch) multiplies
the band's ratio by sigma_s,b / sigma_s,c and its depth factor, and the direction taken from p (the
connection, or the branch's sampled direction) by p_b(cos) / p_c(cos). Algorithm 5 by spectral
ratio tracking: the carrier samples free flights with sigma_t,c and keeps albedo_c at a collision;
an uncollided flight to a surface multiplies band b by T_b / T_c (`transmit_rows`), a collision and
each scattering point's estimate by sigma_s,b T_b / (sigma_s,c T_c) (`scatter`), the sampled
direction by p_b / p_c (`turn`).

Where the parts live: this module holds the band model (band averages, `SceneSpectra` and the kernel's
hooks on it, `scene_tables`, `carrier_bands`); the scene becomes the carrier in engine/scene/scene.py
(`spectral_scene`), the channels are tallied in engine/tally/spectral.py and reported by
engine/results/spectral.py.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np

from owcsim.engine.core.errors import SceneError
from owcsim.engine.media.mie import medium_coefficients, particle_optics
from owcsim.engine.media.phase import phase_from_spec
from owcsim.engine.spectral.spectra_tables import CURVES, K_M, VISIBLE, v_lambda
from owcsim.schemas.medium import MiePhaseSpec

#: Most channels x links a spectral job may tally (each link holds ~(B + 10) x 16 sums per direction).
MAX_CHANNEL_LINKS = 400_000
#: Wavelength step of the band integrals [m].
_STEP = 0.25e-9
#: Channels after the B bands: combined optical gain, electrical gain, luminous gain.
EXTRA = ("optical", "electrical", "luminous")


# --- curves over bands ----------------------------------------------------------------------------------------------
def _grid(lo: float, hi: float, knots=None) -> np.ndarray:
    n = int(min(20001, max(65, np.ceil((hi - lo) / _STEP) + 1)))
    g = np.linspace(lo, hi, n)
    if knots is not None:
        k = np.asarray(knots, float)
        g = np.union1d(g, k[(k > lo) & (k < hi)])
    return g


def _function(curve):
    """A callable of wavelength [m] for tables and named curves (None for numbers and per-band lists)."""
    if isinstance(curve, (int, float, list, tuple)):
        return None, None
    if curve.type == "table":
        w, v = np.asarray(curve.wavelengths, float), np.asarray(curve.values, float)
        return (lambda lam: np.interp(lam, w, v)), w
    return CURVES[curve.name], None


def band_average(curve, spectral) -> np.ndarray:
    """(B,) the curve's mean over each band (band_edges) or its value at each wavelength (wavelengths)."""
    n = spectral.n_bands
    if isinstance(curve, (int, float)):
        return np.full(n, float(curve))
    if isinstance(curve, (list, tuple)):
        return np.asarray(curve, float)
    fn, knots = _function(curve)
    if spectral.wavelengths is not None:
        return np.asarray(fn(np.asarray(spectral.wavelengths, float)), float)
    e = spectral.edges()
    out = np.empty(n)
    for b in range(n):  # a loop over bands
        g = _grid(e[b], e[b + 1], knots)
        out[b] = np.trapezoid(fn(g), g) / (e[b + 1] - e[b])
    return out


def band_spd(curve, spectral) -> tuple[np.ndarray, np.ndarray]:
    """(power fraction per band (B,), K_m Vbar_b per band (B,) [lm/W]) of a relative SPD (None: flat).

    Numbers are a flat density (power proportional to the band's width); per-band lists are the
    bands' powers; tables and named curves are integrated over each band (band_edges) or taken at
    each wavelength times the band's width (wavelengths). Vbar_b = int_b S V / int_b S (S flat
    inside the band for numbers and lists; V(lambda) at the wavelength with `wavelengths`)."""
    n = spectral.n_bands
    e = np.asarray(spectral.edges(), float)
    width = np.diff(e)
    visible = e[0] < VISIBLE[1] and e[-1] > VISIBLE[0]
    fn, knots = _function(curve if curve is not None else 1.0)
    if spectral.wavelengths is not None:
        lam = np.asarray(spectral.wavelengths, float)
        if curve is None or isinstance(curve, (int, float)):
            power = width.copy()
        elif isinstance(curve, (list, tuple)):
            power = np.asarray(curve, float)
        else:
            power = fn(lam) * width
        vbar = v_lambda(lam) if visible else np.zeros(n)
    else:
        power, vbar = np.empty(n), np.zeros(n)
        for b in range(n):  # a loop over bands
            g = _grid(e[b], e[b + 1], knots)
            vis = visible and e[b] < VISIBLE[1] and e[b + 1] > VISIBLE[0]
            v = v_lambda(g) if vis else None
            if fn is None:  # flat inside the band
                power[b] = width[b] if not isinstance(curve, (list, tuple)) else float(curve[b])
                if v is not None:
                    vbar[b] = np.trapezoid(v, g) / width[b]
            else:
                s = np.maximum(fn(g), 0.0)
                power[b] = np.trapezoid(s, g)
                if vis and power[b] > 0:
                    vbar[b] = np.trapezoid(s * v, g) / power[b]
    total = power.sum()
    if not total > 0:
        raise SceneError("a transmitter's spectrum has no power in the scene's bands")
    frac = power / total
    return frac, K_M * vbar


# --- the scene's spectral tables ------------------------------------------------------------------------------------
@dataclass
class SceneSpectra:
    """Per-band tables of a scene (built once per process with the Scene)."""

    edges: np.ndarray  # (B + 1,) [m]
    centres: np.ndarray  # (B,) [m]
    face_rho: np.ndarray  # (B, F) reflectance per band
    face_ratio: np.ndarray  # (B, F) rho_b / rho_c (1 where rho_c = 0)
    tx_fraction: np.ndarray  # (n_tx, B) power fraction f_b
    tx_luminous: np.ndarray  # (n_tx, B) K_m Vbar_b [lm/W]
    rx_electrical: np.ndarray  # (n_rx, B) T_b R_b [A/W]
    rx_responsive: np.ndarray  # (n_rx,) receivers with a responsivity
    n_links: int
    #: per-band medium: sigma_a, sigma_s (B,) [1/m], or None when grey
    sigma_a: np.ndarray | None = None
    sigma_s: np.ndarray | None = None
    carrier_band: int = 0
    #: sigma_t,b / sigma_t,c - 1 (B,) >= 0: the exponent of the transmittance ratio per unit carrier depth
    tau_scale: np.ndarray | None = None
    #: True when the kernel carries per-band ratios (some band differs from the carrier somewhere)
    carry: bool = False
    medium_bands: list = field(default_factory=list)
    warnings: list = field(default_factory=list)
    _face_ratio_depth: np.ndarray | None = None
    #: sigma_s,b / sigma_s,c (B,) of a medium varying per band
    scatter_scale: np.ndarray | None = None
    #: the bands' phase functions when they differ (particles: Mie per band), else None
    phase_bands: list | None = None

    @property
    def n_bands(self) -> int:
        return len(self.centres)

    @property
    def n_channels(self) -> int:
        return self.n_bands + len(EXTRA)

    @property
    def has_luminous(self) -> bool:
        return bool(np.any(self.tx_luminous > 0))

    # --- kernel ------------------------------------------------------------------------
    def initial_ratio(self, n: int) -> np.ndarray:
        """A path's ratio state: (B, n) ones (rows: prod rho_b / rho_c), plus a row of the carrier optical depth
        travelled (0) when the medium varies per band; (0, n) when the kernel carries no ratios."""
        rows = (self.n_bands + (self.tau_scale is not None)) if self.carry else 0
        r = np.ones((rows, n))
        if rows > self.n_bands:
            r[-1] = 0.0
        return r

    def reflect(self, ratio: np.ndarray, prims: np.ndarray) -> np.ndarray:
        """The state after a reflection on faces `prims`: bands times rho_b / rho_c."""
        if not self.carry:
            return ratio
        if len(ratio) > self.n_bands:  # the depth row is multiplied by 1
            if self._face_ratio_depth is None:
                self._face_ratio_depth = np.vstack([self.face_ratio, np.ones((1, self.face_ratio.shape[1]))])
            return ratio * self._face_ratio_depth.take(prims, axis=1)
        return ratio * self.face_ratio.take(prims, axis=1)

    def transmit(self, ratio: np.ndarray, tau: np.ndarray, seg=None) -> np.ndarray:
        """The state after segments of carrier optical depth `tau` (n,): the depth row grows (the band factors
        T_b / T_c = exp(-tau_c (sigma_t,b / sigma_t,c - 1)) are applied once, at the estimates)."""
        if not self.carry or self.tau_scale is None:
            return ratio
        out = ratio.copy()
        out[-1] += tau
        return out

    @property
    def depth_row(self) -> bool:
        """True when the ratio state has the carrier-depth row (ratios carried, smoke varying per band)."""
        return self.carry and self.tau_scale is not None

    def transmit_rows(self, ratio: np.ndarray, rows: np.ndarray, tau: np.ndarray, seg=None) -> np.ndarray:
        """`transmit` for the paths `rows` only (algorithm 5: the flights that reached a surface uncollided; the
        carrier's weight is unchanged, T_c / P(no collision) = 1, band b's is T_b / T_c)."""
        if not self.depth_row:
            return ratio
        out = ratio.copy()
        out[-1, rows] += tau
        return out

    def scatter(self, ratio: np.ndarray, tau: np.ndarray, seg=None) -> np.ndarray:
        """The state of paths scattered at points a carrier depth `tau` (n,) along their segment (algorithms 2-4):
        bands times sigma_s,b / sigma_s,c, depth + tau (the density sigma_s T of the point, over the carrier's)."""
        if not self.carry or self.tau_scale is None:
            return ratio
        out = ratio.copy()
        if self.scatter_scale is not None:  # None: the carrier does not scatter (algorithm 1 only)
            out[: self.n_bands] *= self.scatter_scale[:, None]
        out[-1] += tau
        return out

    def turn(self, ratio: np.ndarray, cos: np.ndarray) -> np.ndarray:
        """The state after a direction sampled from the carrier's phase function (cosine `cos` (n,)): p_b / p_c."""
        if self.phase_bands is None or not self.carry:
            return ratio
        out = ratio.copy()
        out[: self.n_bands] *= self.phase_ratio(cos)
        return out

    def phase_ratio(self, cos: np.ndarray) -> np.ndarray:
        """(B, m) p_b(cos) / p_c(cos) of the bands' phase functions over the carrier's (1 where p_c = 0)."""
        assert self.phase_bands is not None
        c = self.phase_bands[self.carrier_band].eval(cos)
        ok = c > 0
        inv = np.where(ok, 1.0 / np.where(ok, c, 1.0), 0.0)
        return np.stack(
            [
                np.where(ok, p.eval(cos) * inv, 1.0) if b != self.carrier_band else np.ones(len(cos))
                for b, p in enumerate(self.phase_bands)
            ]
        )

    def estimate_ratio(self, ratio: np.ndarray, tau: np.ndarray | None = None, seg=None) -> np.ndarray:
        """(B, m) band ratios of estimates from path states `ratio`, their connections adding carrier depth `tau`.

        `seg` (here and in transmit, transmit_rows, scatter): the segments of the event, read by the parts whose
        ratios need more than the carrier depth (engine/media/frame_ratios.py `PathRatios`); bands ignore it."""
        if not self.carry or self.tau_scale is None:
            return ratio
        depth = ratio[-1] if tau is None else ratio[-1] + tau
        out = np.multiply.outer(-self.tau_scale, depth)  # in place from here: a third of the time of temporaries
        np.exp(out, out=out)
        out *= ratio[: self.n_bands]
        return out

    def channel_power(self, power, ratio, tx, rx) -> tuple[np.ndarray, np.ndarray]:
        """(optical power (m,), channel powers (V, m)) of estimates of carrier power `power` (m,), band ratios
        (B, m) (or (0, m): all 1), transmitter and receiver indices (m,)."""
        r = ratio if ratio.shape[0] else np.ones((self.n_bands, len(power)))
        f = self.tx_fraction.take(tx, axis=0).T  # (B, m)
        bands = power[None, :] * r
        fb = f * bands
        optical = fb.sum(axis=0)
        electrical = (fb * self.rx_electrical.take(rx, axis=0).T).sum(axis=0)
        luminous = (fb * self.tx_luminous.take(tx, axis=0).T).sum(axis=0)
        return optical, np.concatenate([bands, optical[None], electrical[None], luminous[None]])


def surface_bands(surface, spectral) -> np.ndarray:
    """(B,) reflectance per band of one surface: a number, a material (its total rho, grey) or a spectral spec."""
    if isinstance(surface, (int, float)):
        return np.full(spectral.n_bands, float(surface))
    if surface.type == "spectral":
        return np.clip(band_average(surface.reflectance, spectral), 0.0, 1.0)
    return np.full(spectral.n_bands, float(surface.reflectance))


def spectral_faces(surfaces: np.ndarray, spectral) -> tuple[np.ndarray, np.ndarray]:
    """(face indices, (B, m) band reflectances) of the faces whose surface is spectral.

    Faces of one mesh or room face share one surface object: each distinct object is evaluated once.
    """
    keys = np.fromiter((id(s) for s in surfaces), np.int64, len(surfaces))
    _, first, inverse = np.unique(keys, return_index=True, return_inverse=True)
    bands = np.full((len(first), spectral.n_bands), np.nan)
    for u, i in enumerate(first):  # a loop over distinct surface objects
        if getattr(surfaces[i], "type", None) == "spectral":
            bands[u] = surface_bands(surfaces[i], spectral)
    faces = np.flatnonzero(~np.isnan(bands[inverse, 0]))
    return faces, bands[inverse[faces]].T


def grey_surfaces(surfaces: np.ndarray, spec) -> np.ndarray:
    """The carrier's surfaces: each spectral surface replaced by its largest band reflectance (geometry.py)."""
    if surfaces.dtype != object or spec.spectral is None:
        return surfaces
    faces, bands = spectral_faces(surfaces, spec.spectral)
    out = surfaces.copy()
    out[faces] = bands.max(axis=0)
    if all(isinstance(v, (int, float)) for v in out):
        return out.astype(float)
    return out


def medium_bands(spec, spectral):
    """Per band (sigma_a, sigma_s) arrays and phase specs, or None for a grey medium."""
    med = spec.medium
    if med is None:
        return None
    bm = spectral.medium
    centres = spectral.centres()
    if med.type == "particles":
        idx = bm.refractive_index if bm is not None else [med.particles.refractive_index] * len(centres)
        sa, ss, phases = [], [], []
        for lam, m in zip(centres, idx):  # a loop over bands: one Mie average each
            p = med.particles.model_copy(update={"wavelength": float(lam), "refractive_index": m})
            a, s = medium_coefficients(med.model_copy(update={"particles": p}))
            sa.append(a)
            ss.append(s)
            phases.append(MiePhaseSpec(particles=p))
        return np.array(sa), np.array(ss), phases
    if bm is None:
        return None
    return np.asarray(bm.sigma_a, float), np.asarray(bm.sigma_s, float), [med.phase] * len(centres)


def receiver_bands(spec, n_rx: int) -> tuple[np.ndarray, np.ndarray]:
    """(rx_electrical (n_rx, B) T_b R_b [A/W], rx_responsive (n_rx,)) of the document's receivers, explicit ones
    first, then every grid point (grid points share their grid's curves)."""
    spectral = spec.spectral
    electrical, responsive = np.zeros((n_rx, spectral.n_bands)), np.zeros(n_rx, bool)
    rows = [(r, 1) for r in spec.receivers] + [(g, g.count) for g in spec.receiver_grids]
    start = 0
    for r, count in rows:  # a loop over receivers and grids
        if r.responsivity is not None:
            e = band_average(r.responsivity, spectral)
            if r.filter_transmission is not None:
                e = e * band_average(r.filter_transmission, spectral)
            electrical[start : start + count] = e
            responsive[start : start + count] = True
        start += count
    return electrical, responsive


def with_receivers(sp: SceneSpectra, spec, n_tx: int, n_rx: int) -> SceneSpectra:
    """The tables of a scene whose receivers were replaced by those of `spec` (auto.with_receivers: the
    truncation pilot's subset, or a job sharing a worker's built geometry): the receivers' rows and the link
    count follow them; everything else (surfaces, transmitters, medium) is shared."""
    electrical, responsive = receiver_bands(spec, n_rx)
    return replace(sp, rx_electrical=electrical, rx_responsive=responsive, n_links=n_tx * n_rx)


def scene_tables(spec, reflectance: np.ndarray, surfaces: np.ndarray | None, n_rx: int) -> SceneSpectra:
    """The per-band tables of surfaces and devices (the medium's come from `carrier_bands`).

    `reflectance` (F,) is the carrier's (geometry.build_geometry via grey_surfaces), `surfaces` the
    faces' surface objects (None when every face is grey), `n_rx` the receivers (grid points included).
    """
    spectral = spec.spectral
    B = spectral.n_bands
    face_rho = np.repeat(np.asarray(reflectance, float)[None, :], B, axis=0)
    spectral_surfaces = False
    if surfaces is not None:
        faces, bands = spectral_faces(surfaces, spectral)
        face_rho[:, faces] = bands
        spectral_surfaces = len(faces) > 0
    carrier = np.asarray(reflectance, float)
    with np.errstate(invalid="ignore", divide="ignore"):
        face_ratio = np.where(carrier[None, :] > 0, face_rho / np.where(carrier > 0, carrier, 1.0)[None, :], 1.0)
    n_tx = len(spec.transmitters)
    frac, lum = np.zeros((n_tx, B)), np.zeros((n_tx, B))
    for i, t in enumerate(spec.transmitters):  # a loop over transmitters
        frac[i], lum[i] = band_spd(t.spectrum, spectral)
    electrical, responsive = receiver_bands(spec, n_rx)
    out = SceneSpectra(
        edges=np.asarray(spectral.edges(), float),
        centres=np.asarray(spectral.centres(), float),
        face_rho=face_rho,
        face_ratio=face_ratio,
        tx_fraction=frac,
        tx_luminous=lum,
        rx_electrical=electrical,
        rx_responsive=responsive,
        n_links=n_tx * n_rx,
    )
    if out.n_channels * out.n_links > MAX_CHANNEL_LINKS:
        raise SceneError(
            f"spectral: {B} bands over {out.n_links} links need {out.n_channels * out.n_links} "
            f"tally channels, more than {MAX_CHANNEL_LINKS}: use fewer bands or fewer receivers"
        )
    out.carry = B >= 2 and spectral_surfaces  # (and smoke varying per band: `carrier_bands`)
    return out


def carrier_bands(out: SceneSpectra, sigma_a: np.ndarray, sigma_s: np.ndarray, phases: list) -> int | None:
    """Fill the per-band medium tables of `out` (sigma_a, sigma_s (B,) [1/m], phase specs per band) and return
    the carrier band c = argmin_b sigma_t,b (the least attenuated), or None when no band attenuates."""
    sigma_t = sigma_a + sigma_s
    c = int(np.argmin(sigma_t))
    out.sigma_a, out.sigma_s, out.carrier_band = sigma_a, sigma_s, c
    out.medium_bands = [
        {
            "band": b,
            "centre_m": float(out.centres[b]),
            "sigma_a": float(sigma_a[b]),
            "sigma_s": float(sigma_s[b]),
            "sigma_t": float(sigma_t[b]),
            "albedo": float(sigma_s[b] / sigma_t[b]) if sigma_t[b] > 0 else 0.0,
            "visibility_m": float(3.912 / sigma_t[b]) if sigma_t[b] > 0 else None,
        }
        for b in range(len(sigma_t))
    ]
    if sigma_t.max() == 0:
        return None
    if sigma_t[c] == 0:
        raise SceneError(
            f"spectral.medium: band {c} has sigma_t = 0 while others attenuate: give every band a "
            "positive extinction (e.g. 1e-9 1/m) or no medium"
        )
    for b, p in enumerate(phases):
        if p.type == "mie":
            out.medium_bands[b]["g"] = float(particle_optics(p.particles).g)
    varies = not (np.all(sigma_a == sigma_a[c]) and np.all(sigma_s == sigma_s[c]))
    out.tau_scale = sigma_t / sigma_t[c] - 1.0 if varies else None
    if varies:
        with np.errstate(invalid="ignore", divide="ignore"):
            out.scatter_scale = np.where(sigma_s > 0, sigma_s / sigma_s[c], 0.0) if sigma_s[c] > 0 else None
        if len({p.model_dump_json() for p in phases}) > 1:
            out.phase_bands = [phase_from_spec(p) for p in phases]
    out.carry = out.n_bands >= 2 and (out.carry or out.tau_scale is not None)
    return c


def unsupported(out: SceneSpectra, has_mirrors: bool, has_medium: bool, samples_scattering: bool) -> str | None:
    """Why the kernel cannot run these tables, or None: per-band ratios needed by a part that does not carry
    them (perfect mirrors; a carrier band that does not scatter while the run samples scattering points)."""
    if not out.carry:
        return None
    if has_mirrors:
        return (
            "spectral: perfect-mirror surfaces are not supported with spectral surfaces or smoke yet "
            "(use a Phong material with a large exponent, or run one job per band)"
        )
    if not has_medium or out.tau_scale is None or not samples_scattering:
        return None
    if out.scatter_scale is None and out.sigma_s is not None and np.any(out.sigma_s > 0):
        return (
            f"spectral.medium: band {out.carrier_band} (the least attenuated) does not scatter while "
            "others do: algorithms 2-5 sample scattering points in that band; give it a positive "
            "sigma_s (e.g. 1e-9 1/m), or use algorithm 1"
        )
    return None
