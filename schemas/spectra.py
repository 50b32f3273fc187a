"""Wavelength: the job's bands and the spectral curves of sources, surfaces, detectors and smoke (docs/spectra.md).

A scene with `spectral` is simulated in B wavelength bands at once (the geometry is traced
once; each path carries one throughput per band). Curves that vary with wavelength:

- a transmitter's relative spectral power distribution `spectrum` (its `power` [W] is the
  total over the bands; default: flat, the same power per metre of wavelength);
- a surface's reflectance (`{"type": "spectral", "reflectance": <curve>}`), in [0, 1];
- a receiver's photodiode `responsivity` [A/W] and optical `filter_transmission` in [0, 1];
- the smoke's coefficients per band (`spectral.medium`), or a particle medium's refractive
  index per band (Mie at each band centre).

A curve is one of: a number (flat), a list with one value per band, a table
`{"type": "table", "wavelengths": [...] [m], "values": [...]}` (linear between points, its
range must cover the bands), or a table shipped with owcsim `{"type": "named", "name": ...}`
(NAMED_CURVES; analytic models of typical parts, see docs/spectra.md). With `band_edges`,
curves are averaged over each band (the SPD is integrated); with `wavelengths`, they are
taken at each wavelength (the SPD at a wavelength times the width between the midpoints).
"""

from __future__ import annotations

import math
from typing import Annotated, Literal

from pydantic import BaseModel, ConfigDict, Discriminator, Field, Tag, model_validator

from .base import SpecModel
from .medium import MAX_COEFFICIENT, MAX_SIZE_PARAMETER, SIZE_WINDOW_SIGMAS, ComplexIndexSpec

#: Shortest and longest wavelength a band may reach [m] (UV-C to far infrared).
MIN_WAVELENGTH, MAX_WAVELENGTH = 100e-9, 20e-6
#: Most bands of a job (each adds one throughput per path).
MAX_BANDS = 256
#: Most points of a tabulated curve.
MAX_CURVE_POINTS = 100_000
#: Largest responsivity accepted [A/W] (a photodiode without internal gain stays near 1 A/W).
MAX_RESPONSIVITY = 10.0

#: Tables shipped with owcsim, by kind, and the wavelength range they cover [m] (engine/spectral/spectra_tables.py).
NAMED_CURVES: dict[str, tuple[str, float, float]] = {
    "white_led_cool": ("spectrum", 350e-9, 1100e-9),
    "white_led_warm": ("spectrum", 350e-9, 1100e-9),
    "ir_led_850": ("spectrum", 350e-9, 1100e-9),
    "ir_led_940": ("spectrum", 350e-9, 1100e-9),
    "white_paint": ("reflectance", 350e-9, 1100e-9),
    "plaster": ("reflectance", 350e-9, 1100e-9),
    "light_wood": ("reflectance", 350e-9, 1100e-9),
    "red_brick": ("reflectance", 350e-9, 1100e-9),
    "blue_paint": ("reflectance", 350e-9, 1100e-9),
    "grey_carpet": ("reflectance", 350e-9, 1100e-9),
    "silicon_pin": ("responsivity", 350e-9, 1100e-9),
    "daylight_filter_ir": ("filter", 350e-9, 1100e-9),
}
NamedCurve = Literal[
    "white_led_cool",
    "white_led_warm",
    "ir_led_850",
    "ir_led_940",
    "white_paint",
    "plaster",
    "light_wood",
    "red_brick",
    "blue_paint",
    "grey_carpet",
    "silicon_pin",
    "daylight_filter_ir",
]


class TableCurveSpec(SpecModel):
    """A curve tabulated at `wavelengths` [m] (strictly increasing), linear between points."""

    type: Literal["table"] = "table"
    wavelengths: list[float] = Field(min_length=2, max_length=MAX_CURVE_POINTS, description="[m], increasing")
    values: list[float] = Field(min_length=2, max_length=MAX_CURVE_POINTS, description="one value per wavelength")

    @model_validator(mode="after")
    def _table(self) -> "TableCurveSpec":
        if len(self.wavelengths) != len(self.values):
            raise ValueError(f"`wavelengths` has {len(self.wavelengths)} points but `values` has {len(self.values)}")
        w = self.wavelengths
        bad = next((i for i in range(1, len(w)) if not w[i] > w[i - 1]), None)
        if bad is not None:
            raise ValueError(
                f"`wavelengths` must be strictly increasing: entry {bad} ({w[bad]!r}) does not exceed "
                f"entry {bad - 1} ({w[bad - 1]!r})"
            )
        if not w[0] > 0:
            raise ValueError(f"`wavelengths` must be positive [m], got {w[0]!r}")
        return self


class NamedCurveSpec(SpecModel):
    """A curve shipped with owcsim (schemas.spectra.NAMED_CURVES, docs/spectra.md)."""

    type: Literal["named"] = "named"
    name: NamedCurve


def _curve_kind(value) -> str | None:
    if isinstance(value, dict):
        return value.get("type")
    if isinstance(value, BaseModel):
        return getattr(value, "type", None)
    if isinstance(value, (list, tuple)):
        return "bands"
    return "number"


_CURVE_HELP = (
    'a spectral curve is a number (flat), a list of one value per band, {"type": "table", '
    '"wavelengths": [...], "values": [...]} or {"type": "named", "name": ...}'
)

#: A spectral curve: flat number, per-band list, table, or named table (checked against the bands by SceneSpec).
Curve = Annotated[
    Annotated[float, Tag("number")]
    | Annotated[list[float], Tag("bands")]
    | Annotated[TableCurveSpec, Tag("table")]
    | Annotated[NamedCurveSpec, Tag("named")],
    Discriminator(_curve_kind, custom_error_type="invalid_curve", custom_error_message=_CURVE_HELP),
]


class SpectralSurfaceSpec(SpecModel):
    """A Lambertian surface whose reflectance varies with wavelength (BRDF rho(lambda) / pi)."""

    type: Literal["spectral"] = "spectral"
    reflectance: Curve = Field(description="reflectance per band, in [0, 1] (a spectral curve)")


class BandMediumSpec(SpecModel):
    """The smoke per band: coefficients of a homogeneous medium, or a particle medium's refractive index.

    Without it the medium is grey (the same in every band), except a particle medium, whose Mie
    optics are computed at every band centre with its one refractive index.
    """

    sigma_a: list[float] | None = Field(None, description="absorption coefficient per band [1/m]")
    sigma_s: list[float] | None = Field(None, description="scattering coefficient per band [1/m]")
    refractive_index: list[ComplexIndexSpec] | None = Field(
        None, description="particle refractive index per band (particle media)"
    )

    @model_validator(mode="after")
    def _one(self) -> "BandMediumSpec":
        coeffs = self.sigma_a is not None or self.sigma_s is not None
        if coeffs == (self.refractive_index is not None):
            raise ValueError("give `sigma_a` and `sigma_s` (homogeneous medium) or `refractive_index` (particles)")
        if coeffs and (self.sigma_a is None or self.sigma_s is None):
            raise ValueError("give both `sigma_a` and `sigma_s` per band [1/m]")
        for name in ("sigma_a", "sigma_s"):
            values = getattr(self, name) or []
            bad = next((i for i, v in enumerate(values) if not 0.0 <= v <= MAX_COEFFICIENT), None)
            if bad is not None:
                raise ValueError(f"`{name}` entry {bad} is {values[bad]!r}: must lie in [0, {MAX_COEFFICIENT:g}] 1/m")
        return self


class SpectralSpec(SpecModel):
    """The job's wavelength bands: `band_edges` (B + 1 increasing edges [m]) or `wavelengths` (B increasing [m]).

    With `wavelengths`, band i spans the midpoints to its neighbours (the outer bands are
    symmetric about their wavelength; a single wavelength has the width `band_width`).
    """

    band_edges: list[float] | None = Field(
        None, min_length=2, max_length=MAX_BANDS + 1, description="band edges [m], strictly increasing"
    )
    wavelengths: list[float] | None = Field(
        None, min_length=1, max_length=MAX_BANDS, description="band wavelengths [m], strictly increasing"
    )
    band_width: float = Field(10e-9, gt=0.0, le=1e-6, description="width of a single-wavelength band [m]")
    medium: BandMediumSpec | None = Field(None, description="the medium per band (default: grey)")

    @model_validator(mode="after")
    def _bands(self) -> "SpectralSpec":
        if (self.band_edges is None) == (self.wavelengths is None):
            raise ValueError("give exactly one of `band_edges` and `wavelengths` [m]")
        name = "band_edges" if self.band_edges is not None else "wavelengths"
        w: list[float] = self.band_edges if self.band_edges is not None else (self.wavelengths or [])
        bad = next((i for i, x in enumerate(w) if not MIN_WAVELENGTH <= x <= MAX_WAVELENGTH), None)
        if bad is not None:
            raise ValueError(
                f"`{name}` entry {bad} is {w[bad]!r} m: wavelengths are in metres, between "
                f"{MIN_WAVELENGTH:g} and {MAX_WAVELENGTH:g} (e.g. 550e-9 for 550 nm)"
            )
        bad = next((i for i in range(1, len(w)) if not w[i] > w[i - 1]), None)
        if bad is not None:
            raise ValueError(
                f"`{name}` must be strictly increasing: entry {bad} ({w[bad]!r}) does not exceed "
                f"entry {bad - 1} ({w[bad - 1]!r})"
            )
        return self

    @property
    def n_bands(self) -> int:
        return len(self.wavelengths) if self.wavelengths is not None else len(self.band_edges) - 1  # type: ignore

    def edges(self) -> list[float]:
        """Band edges [m] (B + 1) from either input form."""
        if self.band_edges is not None:
            return list(self.band_edges)
        w = self.wavelengths or []
        if len(w) == 1:
            return [w[0] - self.band_width / 2, w[0] + self.band_width / 2]
        mid = [(a + b) / 2 for a, b in zip(w[:-1], w[1:])]
        return [w[0] - (mid[0] - w[0])] + mid + [w[-1] + (w[-1] - mid[-1])]

    def centres(self) -> list[float]:
        """Band centres [m]: the wavelengths, or the middles of the edges."""
        if self.wavelengths is not None:
            return list(self.wavelengths)
        e = self.band_edges
        return [(a + b) / 2 for a, b in zip(e[:-1], e[1:])]  # type: ignore[index]


def check_curve(
    curve, spectral: SpectralSpec, where: str, kind: str, lo: float | None = 0.0, hi: float | None = None
) -> None:
    """ValueError naming `where` when `curve` does not fit the bands (length, coverage, range, kind of table)."""
    n = spectral.n_bands
    if isinstance(curve, (int, float)):
        values = [float(curve)]
    elif isinstance(curve, (list, tuple)):
        if len(curve) != n:
            raise ValueError(f"{where}: {len(curve)} values but the scene has {n} band(s): give one per band")
        values = list(curve)
    elif curve.type == "table":
        edges = spectral.edges() if spectral.band_edges is not None else spectral.centres()
        if curve.wavelengths[0] > edges[0] * (1 + 1e-12) or curve.wavelengths[-1] < edges[-1] * (1 - 1e-12):
            raise ValueError(
                f"{where}: the table covers {curve.wavelengths[0]:.6g}..{curve.wavelengths[-1]:.6g} m "
                f"but the bands span {edges[0]:.6g}..{edges[-1]:.6g} m: extend the table"
            )
        values = list(curve.values)
    else:
        k, a, b = NAMED_CURVES[curve.name]
        if k != kind:
            raise ValueError(
                f"{where}: {curve.name!r} is a {k} table, not a {kind}; the {kind} tables are "
                f"{sorted(n for n, v in NAMED_CURVES.items() if v[0] == kind)}"
            )
        edges = spectral.edges()
        if edges[0] < a or edges[-1] > b:
            raise ValueError(
                f"{where}: {curve.name!r} covers {a:.4g}..{b:.4g} m but the bands span "
                f"{edges[0]:.4g}..{edges[-1]:.4g} m"
            )
        return
    bad = next((i for i, v in enumerate(values) if (lo is not None and v < lo) or (hi is not None and v > hi)), None)
    if bad is not None:
        rng = f"[{lo:g}, {hi:g}]" if hi is not None else f">= {lo:g}"
        at = "" if len(values) == 1 else f" entry {bad}"
        raise ValueError(f"{where}:{at} value {values[bad]!r} outside {rng}")
    if kind == "spectrum" and not any(v > 0 for v in values):
        raise ValueError(f"{where}: the spectral power distribution is zero everywhere")


def check_scene(scene) -> None:
    """Every spectral field of a SceneSpec against its bands (ValueError with the location); no bands: none allowed."""
    spectral = scene.spectral
    fields = list(_spectral_fields(scene))
    if spectral is None:
        if fields:
            raise ValueError(
                f"{fields[0][0]}: a spectral curve needs the scene's wavelength bands: add `spectral` "
                "with `band_edges` or `wavelengths` [m]"
            )
        return
    for where, curve, kind, lo, hi in fields:
        check_curve(curve, spectral, where, kind, lo, hi)
    n = spectral.n_bands
    bm = spectral.medium
    if bm is not None:
        med = scene.medium
        if med is None:
            raise ValueError("spectral.medium: the scene has no medium")
        if bm.refractive_index is not None:
            if med.type != "particles":
                raise ValueError(
                    "spectral.medium.refractive_index: only a particle medium takes a refractive index "
                    "per band (give `sigma_a` and `sigma_s` per band)"
                )
            if len(bm.refractive_index) != n:
                raise ValueError(f"spectral.medium.refractive_index: {len(bm.refractive_index)} values for {n} bands")
        else:
            if med.type != "homogeneous":
                raise ValueError(
                    f"spectral.medium: `sigma_a` / `sigma_s` per band apply to a homogeneous medium, not "
                    f"a {med.type} one"
                    + (" (particle media take `refractive_index` per band)" if med.type == "particles" else "")
                )
            for name in ("sigma_a", "sigma_s"):
                if len(getattr(bm, name)) != n:
                    raise ValueError(f"spectral.medium.{name}: {len(getattr(bm, name))} values for {n} bands")
    if scene.medium is not None and scene.medium.type == "particles":
        p = scene.medium.particles
        s = math.log(p.geometric_std)
        d_max = p.geometric_mean_diameter * math.exp(2 * s * s + SIZE_WINDOW_SIGMAS * s)
        x = math.pi * d_max * p.medium_index / min(spectral.centres())
        if x > MAX_SIZE_PARAMETER:
            raise ValueError(
                f"medium.particles: at the shortest band ({min(spectral.centres()):.4g} m) the size "
                f"distribution reaches size parameter {x:.4g}, above {MAX_SIZE_PARAMETER:g}"
            )


def _spectral_fields(scene):
    """(location, curve, kind, min, max) of every spectral curve in the scene document."""
    for i, t in enumerate(scene.transmitters):
        if t.spectrum is not None:
            yield f"transmitters[{i}].spectrum", t.spectrum, "spectrum", 0.0, None
    receivers = [(f"receivers[{i}]", r) for i, r in enumerate(scene.receivers)]
    receivers += [(f"receiver_grids[{i}]", g) for i, g in enumerate(scene.receiver_grids)]
    for where, r in receivers:
        if r.responsivity is not None:
            yield f"{where}.responsivity", r.responsivity, "responsivity", 0.0, MAX_RESPONSIVITY
        if r.filter_transmission is not None:
            yield f"{where}.filter_transmission", r.filter_transmission, "filter", 0.0, 1.0
    for where, surface in _surfaces(scene):
        if getattr(surface, "type", None) == "spectral":
            yield f"{where}.reflectance", surface.reflectance, "reflectance", 0.0, 1.0


def _surfaces(scene):
    if scene.room is not None:
        rr = scene.room.reflectance
        for name in ("floor", "ceiling", "walls", "wall_x_min", "wall_x_max", "wall_y_min", "wall_y_max"):
            v = getattr(rr, name)
            if v is not None:
                yield f"room.reflectance.{name}", v
    for i, b in enumerate(scene.furniture):
        yield f"furniture[{i}].reflectance", b.reflectance
    for i, m in enumerate(scene.meshes):
        yield f"meshes[{i}].reflectance", m.reflectance
        for k, v in m.group_reflectance.items():
            yield f"meshes[{i}].group_reflectance[{k!r}]", v


# --- the result's `spectral` section -------------------------------------------------------------------------------


class _Out(BaseModel):
    model_config = ConfigDict(extra="ignore")


class SpectralBandPublic(_Out):
    index: int
    lower_m: float = Field(description="lower band edge [m]")
    upper_m: float = Field(description="upper band edge [m]")
    centre_m: float = Field(description="band centre (or the given wavelength) [m]")
    reflectance_range: list[float] | None = Field(None, description="[min, max] surface reflectance in this band")


class SpectralTransmitterPublic(_Out):
    id: str
    band_power_fraction: list[float] = Field(description="f_b: share of the optical power in each band")
    luminous_efficacy_by_band_lm_per_w: list[float] = Field(description="K_m Vbar_b per band [lm/W]")
    luminous_efficacy_lm_per_w: float = Field(description="luminous efficacy of the spectrum, sum f_b K_m Vbar_b")
    luminous_flux_lm: float = Field(description="P_t x the luminous efficacy [lm]")


class SpectralReceiverPublic(_Out):
    id: str = Field(description="receiver id, or a grid's id_prefix (its points share the curves)")
    electrical_weight_a_per_w: list[float] | None = Field(None, description="T_b R_b per band [A/W]")


class SpectralLinkPublic(_Out):
    """Per link: every band's gain, and the optical, electrical and luminous combinations (null when not defined)."""

    transmitter: str
    receiver: str
    dc_gain_by_band: list[float | None] = Field(description="H_b, gain per watt emitted in band b")
    dc_gain_by_band_stderr: list[float | None]
    mean_delay_s_by_band: list[float | None]
    rms_delay_spread_s_by_band: list[float | None]
    optical_gain: float | None = Field(description="sum_b f_b H_b: the whole spectrum (= the link's dc_gain)")
    optical_gain_stderr: float | None
    electrical_gain_a_per_w: float | None = Field(None, description="sum_b f_b T_b R_b H_b [A/W]")
    electrical_gain_a_per_w_stderr: float | None = None
    electrical_gain_by_band_a_per_w: list[float | None] | None = None
    electrical_rms_delay_spread_s: float | None = None
    electrical_rms_delay_spread_s_stderr: float | None = None
    photocurrent_a: float | None = Field(None, description="P_t x the electrical gain [A]")
    illuminance_lx: float | None = Field(
        None, description="P_t sum_b f_b K_m Vbar_b H_b / (A T_s g) [lx], all reflection orders"
    )
    illuminance_lx_stderr: float | None = None
    illuminance_by_band_lx: list[float | None] | None = None
    illuminance_direct_lx: float | None = Field(None, description="the line of sight's part [lx]")


class SpectralResultPublic(_Out):
    """The `spectral` section of a spectral scene's result (docs/spectra.md)."""

    bands: list[SpectralBandPublic]
    carried_ratios: bool = Field(description="whether paths carried per-band ratios (spectral surfaces or smoke)")
    transmitters: list[SpectralTransmitterPublic]
    receivers: list[SpectralReceiverPublic]
    medium_bands: list[dict] | None = Field(
        None, description="per band: sigma_a, sigma_s, sigma_t [1/m], albedo, visibility [m] (and g for particles)"
    )
    links: list[SpectralLinkPublic]
    model: str
