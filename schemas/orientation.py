"""Receivers as people hold them (docs/orientation.md): random orientation and angle-diversity receivers.

Request models:

- `OrientationSpec` (a receiver's or a grid's `orientation`): the device normal is tilted from the
  receiver's `normal` by a random polar angle theta and turned by a uniform azimuth omega. The
  measured statistics of Soltani, Purwita, Zeng, Haas & Safari, "Modeling the random orientation of
  mobile devices: measurement, analysis and LiFi use case", IEEE Trans. Commun. 67(3), 2157-2172,
  2019 (arXiv:1805.07999; forty participants): sitting users, theta ~ Laplace(mu = 41.39 deg,
  b = 7.68 deg); walking users, theta ~ Gaussian(mu = 29.67 deg, sigma = 7.78 deg); both truncated to
  [0, 90] deg here; omega uniform on [0, 360) deg. Each point becomes `samples` ordinary receivers at
  the same position, one per cell of a stratified grid over (F(theta), omega / 2 pi) (n_theta x
  n_omega cells, one point drawn in each from a generator seeded by `seed`: the rule is fixed, so a
  document gives the same normals every time), and the result averages them with weights
  1 / samples (engine/results/orientation.py).
- `AngleDiversityReceiverSpec` (the scene's `angle_diversity_receivers`): several photodiodes at one
  point, each with its own normal, FOV and area, combined by selection, equal-gain and maximum-ratio
  combining (Carruthers & Kahn, "Angle diversity for nondirected wireless infrared communication",
  IEEE Trans. Commun. 48(6), 960-969, 2000; Chen, Basnayaka, Wu & Haas, "Interference mitigation for
  indoor optical attocell networks using an angle diversity receiver", J. Lightw. Technol. 36(18),
  3866-3881, 2018).

Both add hidden receivers after the document's own (explicit receivers, then grid points): first the
orientation samples of the explicit receivers, then those of each grid's points (point-major), then
each angle-diversity receiver's photodiodes. Their ids are `{point id}@o{k}` and `{id}@pd{k}`.
"""

from __future__ import annotations

import math
import random
from collections.abc import Iterator
from dataclasses import dataclass
from enum import StrEnum
from statistics import NormalDist
from typing import Annotated, Any

from pydantic import BaseModel, ConfigDict, Field, model_validator

from .base import Direction, Point, SpecModel

#: Most hidden receivers (orientation samples and photodiodes) a scene may add.
MAX_HIDDEN_RECEIVERS = 200_000
#: BER target whose SNR is the default outage threshold: Q^-1(1e-6)^2 = 22.6 (13.5 dB), OOK-NRZ.
DEFAULT_OUTAGE_BER = 1e-6


class OrientationModel(StrEnum):
    """The polar-angle statistics of a handheld device (Soltani et al. 2019)."""

    SITTING = "sitting"  # truncated Laplace, mu = 41.39 deg, b = 7.68 deg
    WALKING = "walking"  # truncated Gaussian, mu = 29.67 deg, sigma = 7.78 deg
    CUSTOM = "custom"  # `distribution`, `mean_deg`, `scale_deg` given


class PolarDistribution(StrEnum):
    """Shape of the polar-angle density, truncated to [0, 90] deg."""

    LAPLACE = "laplace"  # f ~ exp(-|theta - mu| / b)
    GAUSSIAN = "gaussian"  # f ~ exp(-(theta - mu)^2 / (2 sigma^2))


#: (distribution, mean [deg], scale [deg]) of the measured models (Soltani et al. 2019).
MEASURED = {
    OrientationModel.SITTING: (PolarDistribution.LAPLACE, 41.39, 7.68),
    OrientationModel.WALKING: (PolarDistribution.GAUSSIAN, 29.67, 7.78),
}

Angle90 = Annotated[float, Field(ge=0.0, le=90.0)]


@dataclass(frozen=True)
class PolarLaw:
    """A polar-angle density truncated to [0, pi/2]: `distribution`, location `mean` [rad], `scale` [rad]
    (b of the Laplace, sigma of the Gaussian)."""

    distribution: PolarDistribution
    mean: float
    scale: float

    def _cdf(self, x: float) -> float:
        """The untruncated CDF at x [rad]."""
        if self.distribution is PolarDistribution.GAUSSIAN:
            return NormalDist(self.mean, self.scale).cdf(x)
        z = (x - self.mean) / self.scale
        return 0.5 * math.exp(z) if z < 0 else 1.0 - 0.5 * math.exp(-z)

    def _quantile(self, p: float) -> float:
        """The untruncated inverse CDF at p in (0, 1) [rad]."""
        if self.distribution is PolarDistribution.GAUSSIAN:
            return NormalDist(self.mean, self.scale).inv_cdf(p)
        return (
            self.mean + self.scale * math.log(2.0 * p) if p < 0.5 else self.mean - self.scale * math.log(2.0 * (1 - p))
        )

    def quantile(self, u: float) -> float:
        """theta [rad] with truncated CDF F(theta) = u: F^-1(F0 + u (F1 - F0)), F0, F1 the CDF at 0 and pi/2."""
        lo, hi = self._cdf(0.0), self._cdf(math.pi / 2)
        theta = self._quantile(min(max(lo + u * (hi - lo), 1e-300), 1.0 - 1e-16))
        return min(max(theta, 0.0), math.pi / 2)

    def pdf(self, theta: float) -> float:
        """The truncated density at theta [1/rad] (0 outside [0, pi/2]): for references and plots."""
        if not 0.0 <= theta <= math.pi / 2:
            return 0.0
        mass = self._cdf(math.pi / 2) - self._cdf(0.0)
        if self.distribution is PolarDistribution.GAUSSIAN:
            return NormalDist(self.mean, self.scale).pdf(theta) / mass
        return math.exp(-abs(theta - self.mean) / self.scale) / (2.0 * self.scale) / mass


class OrientationSpec(SpecModel):
    """Random orientation of a handheld receiver (Soltani et al. 2019): each point becomes `samples` receivers.

    The device normal is the receiver's `normal` tilted by theta (the polar law of `model`) toward the
    azimuth omega (uniform). Per point and channel the result gives the mean received power, the mean
    SNR and the outage probability P(SNR < threshold) over orientations (docs/orientation.md).
    """

    model: OrientationModel = Field(
        OrientationModel.SITTING,
        description="`sitting` (truncated Laplace, mu = 41.39 deg, b = 7.68 deg), `walking` (truncated Gaussian, "
        "mu = 29.67 deg, sigma = 7.78 deg; Soltani et al. 2019) or `custom` (give distribution, mean_deg, scale_deg)",
    )
    distribution: PolarDistribution | None = Field(None, description="custom model: `laplace` or `gaussian`")
    mean_deg: Angle90 | None = Field(None, description="custom model: location mu of the polar angle [deg]")
    scale_deg: float | None = Field(
        None, ge=0.1, le=90.0, description="custom model: scale (Laplace b, Gaussian sigma) of the polar angle [deg]"
    )
    samples: int = Field(
        32,
        ge=4,
        le=4096,
        description="orientations per point, an even number: a stratified grid of n_theta x n_omega cells",
    )
    outage_snr_db: float | None = Field(
        None, ge=-50.0, le=100.0, description="outage threshold: SNR [dB] below which a sample is in outage"
    )
    outage_ber: float | None = Field(
        None,
        gt=0.0,
        lt=0.5,
        description="outage threshold as a BER target of OOK-NRZ: SNR_th = Q^-1(BER)^2 "
        "(default when no threshold is given: 1e-6, 13.5 dB)",
    )
    seed: int = Field(0, ge=0, le=2**63 - 1, description="seed of the points drawn in the cells (a fixed rule)")

    @model_validator(mode="after")
    def _check(self) -> "OrientationSpec":
        custom = (self.distribution, self.mean_deg, self.scale_deg)
        if self.model is OrientationModel.CUSTOM and None in custom:
            raise ValueError("a `custom` orientation needs `distribution`, `mean_deg` and `scale_deg`")
        if self.model is not OrientationModel.CUSTOM and any(c is not None for c in custom):
            raise ValueError(
                f"`distribution`, `mean_deg` and `scale_deg` are for `model: custom`, not `{self.model.value}`"
            )
        if self.samples % 2:
            raise ValueError(f"samples must be even (the error pairs neighbouring cells), not {self.samples}")
        if self.outage_snr_db is not None and self.outage_ber is not None:
            raise ValueError("give `outage_snr_db` or `outage_ber`, not both")
        return self

    @property
    def law(self) -> PolarLaw:
        """The polar-angle law, in radians."""
        if self.model is OrientationModel.CUSTOM:
            assert self.distribution is not None and self.mean_deg is not None and self.scale_deg is not None
            dist, mean, scale = self.distribution, self.mean_deg, self.scale_deg
        else:
            dist, mean, scale = MEASURED[self.model]
        return PolarLaw(dist, math.radians(mean), math.radians(scale))

    @property
    def strata(self) -> tuple[int, int]:
        """(n_theta, n_omega): n_theta the largest even divisor of `samples` not above its square root (2 at least)."""
        n = self.samples
        n_theta = max([d for d in range(2, math.isqrt(n) + 1, 2) if n % d == 0], default=2)
        return n_theta, n // n_theta

    @property
    def threshold_snr(self) -> float:
        """Outage threshold SNR_th [-] (linear): from `outage_snr_db`, else Q^-1(BER)^2 for the BER target."""
        if self.outage_snr_db is not None:
            return 10.0 ** (self.outage_snr_db / 10.0)
        ber = self.outage_ber if self.outage_ber is not None else DEFAULT_OUTAGE_BER
        return NormalDist().inv_cdf(ber) ** 2

    def angles(self) -> list[tuple[float, float]]:
        """(theta, omega) [rad] of every sample, theta-cell-major: cell (k, l) holds sample k n_omega + l, its
        point (F^-1((k + a) / n_theta), 2 pi (l + b) / n_omega) with a, b uniform from `seed`."""
        n_theta, n_omega = self.strata
        law, rng = self.law, random.Random(self.seed)
        out = []
        for k in range(n_theta):  # a loop over at most 4096 cells, once per document
            for j in range(n_omega):
                a, b = rng.random(), rng.random()
                out.append((law.quantile((k + a) / n_theta), 2.0 * math.pi * (j + b) / n_omega))
        return out

    def normals(self, reference: tuple[float, float, float]) -> list[tuple[float, float, float]]:
        """Unit device normals: `reference` tilted by theta toward azimuth omega of its tangent frame."""
        return [tilted(reference, theta, omega) for theta, omega in self.angles()]


def tangent_frame(n: tuple[float, float, float]) -> tuple[tuple[float, ...], tuple[float, ...], tuple[float, ...]]:
    """(t1, t2, n) orthonormal, n normalised: t2 = n x e / |n x e|, t1 = t2 x n, with e = x unless n is near x
    (then z). For n = +z: t1 = +x, t2 = +y, so omega is the azimuth from +x toward +y."""
    norm = math.sqrt(sum(c * c for c in n))
    nx, ny, nz = (c / norm for c in n)
    ex, ey, ez = (1.0, 0.0, 0.0) if abs(nx) < 0.9 else (0.0, 0.0, 1.0)
    t2 = (ny * ez - nz * ey, nz * ex - nx * ez, nx * ey - ny * ex)
    s = math.sqrt(sum(c * c for c in t2))
    t2 = (t2[0] / s, t2[1] / s, t2[2] / s)
    t1 = (t2[1] * nz - t2[2] * ny, t2[2] * nx - t2[0] * nz, t2[0] * ny - t2[1] * nx)
    return t1, t2, (nx, ny, nz)


def tilted(reference: tuple[float, float, float], theta: float, omega: float) -> tuple[float, float, float]:
    """cos(theta) n + sin(theta) (cos(omega) t1 + sin(omega) t2) in the tangent frame of `reference`."""
    t1, t2, n = tangent_frame(reference)
    c, s, co, so = math.cos(theta), math.sin(theta), math.cos(omega), math.sin(omega)
    return tuple(c * n[i] + s * (co * t1[i] + so * t2[i]) for i in range(3))  # type: ignore[return-value]


# --- angle-diversity receivers -----------------------------------------------------------------


class PhotodiodeSpec(SpecModel):
    """One photodiode of an angle-diversity receiver (the fields of a receiver, without a position)."""

    normal: Direction
    area: float = Field(gt=0.0, le=1.0, description="detector area A [m^2]")
    fov_deg: float = Field(90.0, ge=1e-6, le=90.0, description="field of view, half-angle [deg]")
    filter_gain: float = Field(1.0, gt=0.0, le=1.0, description="optical filter gain T_s")
    concentrator_index: float | None = Field(None, ge=1.0, le=4.0, description="concentrator refractive index n_c")


class PyramidSpec(SpecModel):
    """`sides` photodiodes tilted by `tilt_deg` from the receiver's axis at azimuths `azimuth_deg` + 360 k / sides,
    and one along the axis when `top` (the pyramid receiver of Chen et al. 2018)."""

    sides: int = Field(4, ge=2, le=16, description="photodiodes around the axis")
    tilt_deg: float = Field(gt=0.0, le=90.0, description="polar angle of the side photodiodes' normals [deg]")
    azimuth_deg: float = Field(0.0, ge=-360.0, le=360.0, description="azimuth of the first side photodiode [deg]")
    top: bool = Field(True, description="one more photodiode along the axis")
    area: float = Field(gt=0.0, le=1.0, description="area of each photodiode [m^2]")
    fov_deg: float = Field(90.0, ge=1e-6, le=90.0, description="field of view of each photodiode, half-angle [deg]")
    filter_gain: float = Field(1.0, gt=0.0, le=1.0, description="optical filter gain T_s")
    concentrator_index: float | None = Field(None, ge=1.0, le=4.0, description="concentrator refractive index n_c")


class AngleDiversityReceiverSpec(SpecModel):
    """Several photodiodes at one point, combined (docs/orientation.md): give `photodiodes` or a `pyramid`.

    Per channel the result gives every photodiode's SNR and the combined SNR of selection (SC: the largest
    SNR_i), equal-gain (EGC: (sum I_i)^2 / sum sigma_i^2) and maximum-ratio combining (MRC: sum SNR_i), with
    I_i = gamma P_i the photocurrent and sigma_i^2 the noise of photodiode i (needs `link_budget`).
    """

    id: str = Field(min_length=1, max_length=200, description="id; its photodiodes are `{id}@pd{k}`")
    position: Point
    normal: Direction = Field((0.0, 0.0, 1.0), description="the axis of a `pyramid` (not used with `photodiodes`)")
    photodiodes: list[PhotodiodeSpec] | None = Field(None, min_length=1, max_length=64)
    pyramid: PyramidSpec | None = None

    @model_validator(mode="after")
    def _one_form(self) -> "AngleDiversityReceiverSpec":
        if (self.photodiodes is None) == (self.pyramid is None):
            raise ValueError("give exactly one of `photodiodes` and `pyramid`")
        return self

    def expanded(self) -> list[PhotodiodeSpec]:
        """The photodiodes (a pyramid's: sides first, then the top one)."""
        if self.photodiodes is not None:
            return list(self.photodiodes)
        p = self.pyramid
        assert p is not None
        fields = dict(
            area=p.area, fov_deg=p.fov_deg, filter_gain=p.filter_gain, concentrator_index=p.concentrator_index
        )
        tilt = math.radians(p.tilt_deg)
        out = [
            PhotodiodeSpec(
                normal=tilted(self.normal, tilt, math.radians(p.azimuth_deg + 360.0 * k / p.sides)), **fields
            )
            for k in range(p.sides)
        ]
        if p.top:
            out.append(PhotodiodeSpec(normal=self.normal, **fields))
        return out


# --- the hidden receivers of a scene -----------------------------------------------------------


@dataclass(frozen=True)
class HiddenBlock:
    """Hidden receivers of one request: `kind` "orientation" (samples of the points `points`, global receiver
    indices) or "diversity" (photodiodes of `diversity`); `first` its first receiver index, `per_point` the
    receivers per point."""

    kind: str
    first: int
    points: range
    per_point: int
    orientation: OrientationSpec | None = None
    diversity: AngleDiversityReceiverSpec | None = None

    @property
    def count(self) -> int:
        return len(self.points) * self.per_point


def hidden_blocks(scene: Any) -> list[HiddenBlock]:
    """The hidden receivers of a SceneSpec, in order: the explicit receivers' orientation samples, each grid's,
    then the angle-diversity photodiodes. `points` of a diversity block is range(1) (the block's own point)."""
    out: list[HiddenBlock] = []
    first = len(scene.receivers) + sum(g.count for g in scene.receiver_grids)
    for i, r in enumerate(scene.receivers):  # a loop over explicit receivers (few)
        if r.orientation is not None:
            out.append(HiddenBlock("orientation", first, range(i, i + 1), r.orientation.samples, r.orientation))
            first += r.orientation.samples
    start = len(scene.receivers)
    for g in scene.receiver_grids:
        if g.orientation is not None:
            block = HiddenBlock(
                "orientation", first, range(start, start + g.count), g.orientation.samples, g.orientation
            )
            out.append(block)
            first += block.count
        start += g.count
    for a in scene.angle_diversity_receivers:
        n = len(a.expanded())
        out.append(HiddenBlock("diversity", first, range(1), n, diversity=a))
        first += n
    return out


def hidden_count(scene: Any) -> int:
    """Receivers the orientation requests and angle-diversity receivers add to a SceneSpec."""
    return sum(b.count for b in hidden_blocks(scene))


def hidden_ids(scene: Any, point_ids: list[str]) -> Iterator[str]:
    """Ids of the hidden receivers, in order (`point_ids`: the ids of the explicit receivers and grid points)."""
    for b in hidden_blocks(scene):
        if b.diversity is not None:
            yield from (f"{b.diversity.id}@pd{k}" for k in range(b.per_point))
        else:
            for p in b.points:
                yield from (f"{point_ids[p]}@o{k}" for k in range(b.per_point))


def hidden_receiver_fields(scene: Any, index: int) -> dict:
    """The ReceiverSpec fields of hidden receiver `index` (global receiver index), for `SceneSpec.receiver_at`."""
    for b in hidden_blocks(scene):
        if b.first <= index < b.first + b.count:
            p, k = divmod(index - b.first, b.per_point)
            if b.diversity is not None:
                pd = b.diversity.expanded()[k]
                return dict(position=b.diversity.position, **pd.model_dump(), id=f"{b.diversity.id}@pd{k}")
            assert b.orientation is not None
            base = scene.receiver_at(b.points[p])
            return dict(
                id=f"{base.id or f'rx{b.points[p]}'}@o{k}",
                position=base.position,
                normal=b.orientation.normals(base.normal)[k],
                area=base.area,
                fov_deg=base.fov_deg,
                filter_gain=base.filter_gain,
                concentrator_index=base.concentrator_index,
            )
    raise IndexError("receiver index out of range")


def check_hidden(scene: Any) -> None:
    """ValueError for requests the engine cannot honour: too many hidden receivers, a spectral scene."""
    blocks = hidden_blocks(scene)
    if not blocks:
        return
    if scene.spectral is not None:
        raise ValueError(
            "`orientation` and `angle_diversity_receivers` are not supported in spectral scenes yet: "
            "run the scene grey (no `spectral`)"
        )
    n = sum(b.count for b in blocks)
    if n > MAX_HIDDEN_RECEIVERS:
        raise ValueError(
            f"orientation samples and angle-diversity photodiodes add {n} receivers, more than the "
            f"{MAX_HIDDEN_RECEIVERS} allowed: lower `samples` or use a coarser grid"
        )


# --- result models -----------------------------------------------------------------------------


class _Public(BaseModel):
    """Output model: tolerant of fields added by newer engines (as schemas.results.PublicModel)."""

    model_config = ConfigDict(extra="ignore")


class OrientationPointPublic(_Public):
    """One point under random orientation, for one channel: statistics over its `samples` oriented receivers.

    Errors are one standard error: the quadrature's (stratified cells, neighbouring cells paired) and the
    Monte Carlo's (per-sample errors added as if fully correlated: an upper bound) in quadrature.
    """

    receiver: str = Field(description="the point: an explicit receiver's id or a grid point's `{id_prefix}[i,j]`")
    receiver_index: int = Field(description="index of the point in `receivers`")
    channel: str = Field(description="transmitter group name, or transmitter id when the scene has no group")
    samples: int = Field(description="oriented receivers of this point")
    first_sample_index: int = Field(description="index in `receivers` of the first oriented receiver (`{id}@o0`)")
    received_power_mean_w: float | None = Field(description="mean received optical power over orientations [W]")
    received_power_mean_w_stderr: float | None = Field(description="its standard error [W]")
    snr_mean_db: float | None = Field(
        None, description="10 log10 of the mean linear SNR over orientations [dB] (with `link_budget`)"
    )
    snr_mean_db_stderr: float | None = Field(None, description="its standard error [dB]")
    outage_probability: float | None = Field(
        None, description="P(SNR < outage threshold) over orientations [-] (with `link_budget`)"
    )
    outage_probability_stderr: float | None = Field(None, description="its standard error [-]")
    outage_snr_db: float = Field(description="the outage threshold [dB]")


class CombinedSnrPublic(_Public):
    """An angle-diversity receiver's SNR for one channel: per photodiode and combined (linear SNRs in dB)."""

    receiver: str = Field(description="the angle-diversity receiver's id")
    channel: str = Field(description="transmitter group name, or transmitter id when the scene has no group")
    photodiodes: list[str] = Field(description="receiver ids of its photodiodes (`{id}@pd{k}`)")
    first_photodiode_index: int = Field(description="index in `receivers` of the first photodiode")
    received_power_w: list[float | None] = Field(description="per photodiode: received optical power [W]")
    snr_db: list[float | None] = Field(description="per photodiode: SNR [dB]")
    selected: int | None = Field(None, description="the photodiode selection combining picks (largest SNR)")
    snr_sc_db: float | None = Field(None, description="selection combining: max_i SNR_i [dB]")
    snr_sc_db_stderr: float | None = None
    snr_egc_db: float | None = Field(None, description="equal-gain combining: (sum_i I_i)^2 / sum_i sigma_i^2 [dB]")
    snr_egc_db_stderr: float | None = None
    snr_mrc_db: float | None = Field(None, description="maximum-ratio combining: sum_i SNR_i [dB]")
    snr_mrc_db_stderr: float | None = None
