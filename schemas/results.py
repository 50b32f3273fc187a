"""The result document: what `owcsim run` writes as result.json and the API returns.

Every Monte Carlo figure has a `_stderr` twin (one standard error). Delays are
absolute (from emission), not relative to the line-of-sight arrival; `los_delay_s`
gives the offset for a LOS-relative view. Figures that do not exist (an unreachable
link's delays, a bandwidth above the binning's Nyquist frequency, an error bar
from fewer than two batch groups) are null.
"""

from __future__ import annotations

from enum import StrEnum

from pydantic import BaseModel, ConfigDict, Field

from .algorithms import Direction
from .cells import CellsPublic
from .lighting import LightingResultPublic
from .orientation import CombinedSnrPublic, OrientationPointPublic
from .scene import SceneSpec
from .spectra import SpectralResultPublic
from .timeline import TimelineResultPublic


class StopReason(StrEnum):
    """Why a run ended."""

    PATHS = "paths"  # the asked number of paths is traced
    TARGET_REACHED = "target_reached"  # every link's relative standard error of H0 is at or below the target
    TIME_BUDGET = "time_budget"  # an accuracy run spent its time_budget_s
    CANCELLED = "cancelled"  # stopped from outside (should_stop)
    NOTHING_TO_SIMULATE = "nothing_to_simulate"  # every link exact or skipped (unreachable receivers)
    EXACT = "exact"  # line of sight only, computed in closed form


class PublicModel(BaseModel):
    """Output model: tolerant of fields added by newer engines."""

    model_config = ConfigDict(extra="ignore")


class CirPublic(PublicModel):
    """Binned impulse response of one link: power per bin per watt (h(t) = power / dt [1/s])."""

    total: list[float]
    total_stderr: list[float | None] = Field(
        description="standard error per bin: spread of 16 batch groups, or of the 16 path groups of a run of one "
        "batch; null where fewer than two groups hold paths (or the one-batch CIR is too large for path groups)"
    )
    by_reflection_order: list[list[float]] | None = Field(
        None, description="[k][bin], k = 0..max_reflections (when the order split is asked)"
    )
    by_scattering_order: list[list[float]] | None = Field(
        None, description="[s][bin], s = 0..S of the algorithm (when the order split is asked)"
    )


class LightingPublic(PublicModel):
    """Illuminance and link-budget figures of a link or a group's channel (null when not asked)."""

    illuminance_lx: float | None = Field(
        None,
        description="total illuminance on the receiver plane [lx]: direct light plus every reflection and scattering "
        "order (when a transmitter gives light: luminous_output, a photometric file or a spectrum; docs/lighting.md)",
    )
    illuminance_lx_stderr: float | None = Field(None, description="standard error of illuminance_lx [lx]")
    illuminance_direct_lx: float | None = Field(None, description="the direct part of illuminance_lx [lx]")
    cylindrical_illuminance_direct_lx: float | None = Field(
        None, description="direct cylindrical illuminance [lx] (with lighting.cylindrical)"
    )
    snr_db: float | None = Field(None, description="electrical SNR [dB] (with `link_budget`)")
    ber: float | None = Field(None, description="bit-error rate of OOK-NRZ (with `link_budget`)")
    max_bit_rate_bps: float | None = Field(
        None, description="bit rate the delay spread allows, 1/(10 tau_rms) [bit/s] (with `link_budget`)"
    )


class LinkPublic(LightingPublic):
    """One transmitter-receiver link. Quantities of a masked receiver (a grid point in furniture or outside
    the room) are null. The CIR, the figures computed from it and the order split are null when not asked
    (`outputs`)."""

    transmitter: str
    receiver: str
    transmitter_index: int
    receiver_index: int
    receiver_position: tuple[float, float, float] = Field(description="position of the receiver [m]")
    direction: Direction
    paths: int = Field(
        description="paths traced for this link; with direction both, the sum of the two devices' runs "
        "(each runs simulation.paths)"
    )
    dc_gain: float | None
    dc_gain_stderr: float | None
    path_loss_db: float | None
    received_power_w: float | None = Field(description="P_t H0 [W]")
    mean_delay_s: float | None
    mean_delay_s_stderr: float | None
    rms_delay_spread_s: float | None
    rms_delay_spread_s_stderr: float | None
    mean_delay_h2_s: float | None
    rms_delay_spread_h2_s: float | None
    rms_delay_spread_h2_s_stderr: float | None
    bandwidth_3db_hz: float | None
    bandwidth_3db_hz_stderr: float | None
    truncated_gain_estimate: float | None = Field(
        None,
        description="estimated power per watt of the reflection (and scattering) orders beyond K (and S), "
        "not in dc_gain: the last order's gain times rho_max / (1 - rho_max) (albedo for S)",
    )
    los_gain: float | None
    los_delay_s: float
    dc_gain_by_reflection_order: list[float] | None = None
    dc_gain_by_reflection_order_stderr: list[float | None] | None = None
    dc_gain_by_scattering_order: list[float] | None = None
    dc_gain_by_scattering_order_stderr: list[float | None] | None = None
    early_gain: float | None = Field(None, description="power per watt arriving before t_min_s (not in the CIR)")
    late_gain: float | None = Field(
        None,
        description="power per watt arriving after the window's end t_min_s + n_bins time_bin_s (t_max_s rounded "
        "up to whole bins; not in the CIR)",
    )
    cir: CirPublic | None = None


class ChannelPublic(LightingPublic):
    """A transmitter group's channel at one receiver: h_g = sum_i P_i h_i / sum_i P_i over its members
    (per watt of the group's total power); received power sum_i P_i H0_i [W]."""

    group: str = Field(description="the transmitter group's name")
    receiver: str = Field(description="receiver id")
    receiver_index: int = Field(description="index of the receiver in `receivers`")
    paths: int | None = Field(None, description="paths traced for this channel: the most of its member links'")
    dc_gain: float | None = Field(description="H0 of the summed channel, per watt of the group's power [-]")
    dc_gain_stderr: float | None = Field(description="standard error of dc_gain")
    path_loss_db: float | None = Field(description="-10 log10 H0 [dB]")
    received_power_w: float | None = Field(description="sum_i P_i H0_i over the members [W]")
    mean_delay_s: float | None = Field(description="power-weighted mean delay of the summed channel [s]")
    mean_delay_s_stderr: float | None = Field(description="standard error of mean_delay_s [s]")
    rms_delay_spread_s: float | None = Field(description="RMS delay spread of the summed channel [s]")
    rms_delay_spread_s_stderr: float | None = Field(description="standard error of rms_delay_spread_s [s]")
    bandwidth_3db_hz: float | None = Field(
        None,
        description="3 dB bandwidth of the summed channel [Hz], the line of sight as exact delays "
        "(engine/results/channel_spectrum.py); null without a binned CIR at this receiver (ask `outputs.cir` for "
        "grid points) or when |H| stays above 1/sqrt(2) up to 1/(2 time_bin_s)",
    )
    bandwidth_3db_hz_stderr: float | None = Field(
        None, description="standard error of bandwidth_3db_hz [Hz] (delta method over the CIR's path groups)"
    )
    cir: CirPublic | None = None


class ReceiverPublic(PublicModel):
    """A receiver of the job; grid points name their grid and (i, j), masked ones say why."""

    id: str = Field(description="receiver id (`{id_prefix}[i,j]` for grid points)")
    position: tuple[float, float, float] = Field(description="[m]")
    normal: tuple[float, float, float] = Field(description="unit normal")
    grid: str | None = Field(None, description="the grid's id_prefix, for grid points")
    i: int | None = Field(None, description="index along the grid's u axis")
    j: int | None = Field(None, description="index along the grid's v axis")
    masked: str | None = Field(None, description="why this grid point was not simulated (its values are null)")


class MapPublic(PublicModel):
    """Quantities over one receiver grid for one channel (a transmitter group, or a transmitter when the
    scene has no groups): `values[name][i][j]`, null where masked. Point (i, j) is at origin + i s_u u +
    j s_v v, (s_u, s_v) = `spacing_uv`."""

    grid: str = Field(description="the grid's id_prefix")
    channel: str = Field(description="transmitter group name, or transmitter id when the scene has no group")
    shape: tuple[int, int] = Field(description="(nu, nv) points along u and v")
    origin: tuple[float, float, float] = Field(description="point (0, 0) [m]")
    u: tuple[float, float, float] = Field(description="unit vector of the first index")
    v: tuple[float, float, float] = Field(description="unit vector of the second index")
    spacing: float | None = Field(
        None, description="distance between neighbouring points [m] when the same along u and v, else null"
    )
    spacing_uv: tuple[float, float] | None = Field(
        None,
        description="(s_u, s_v): distance between neighbouring points along u and along v [m] (0 along an "
        "axis of one point); null in documents of engines before rectangular grids: then (spacing, spacing)",
    )
    normal: tuple[float, float, float] | None = Field(None, description="unit normal of the grid's receivers")
    units: dict[str, str] = Field(description="unit of each quantity")
    values: dict[str, list[list[float | None]]] = Field(description="quantity -> [i][j] values, null where masked")
    stderr: dict[str, list[list[float | None]]] = Field(
        default_factory=dict, description="quantity -> [i][j] standard errors"
    )

    @property
    def steps(self) -> tuple[float, float]:
        """(s_u, s_v) [m]: `spacing_uv`, or (spacing, spacing) in an older document."""
        if self.spacing_uv is not None:
            return self.spacing_uv
        assert self.spacing is not None  # an older document always has it
        return (self.spacing, self.spacing)


class TimeBinsPublic(PublicModel):
    t_min_s: float
    time_bin_s: float
    n_bins: int


class DirectionChoicePublic(PublicModel):
    """How the links' directions were chosen: the rule, and the direction pilot's measurements when one ran.
    Keys a newer engine adds are kept."""

    model_config = ConfigDict(extra="allow")

    rule: str = Field(description="the rule that chose the directions")
    paths_per_direction: int | None = Field(None, description="paths per source of the direction pilot, each way")
    rel_std_per_path_forward: list[float | None] | None = Field(
        None, description="per link: relative standard deviation of H0 per forward path (pilot)"
    )
    rel_std_per_path_backward: list[float | None] | None = Field(
        None, description="per link: relative standard deviation of H0 per backward path (pilot)"
    )
    rays_per_path_forward: float | None = Field(None, description="rays cast per forward path (pilot)")
    rays_per_path_backward: float | None = Field(None, description="rays cast per backward path (pilot)")


class RunPublic(PublicModel):
    stop_reason: StopReason
    target_rel_error: float | None
    max_dc_gain_rel_stderr: float | None
    wall_time_s: float
    workers: int
    batches: int
    paths_total: int
    rays_intersect: int
    rays_occluded: int
    direction_choice: DirectionChoicePublic


class DiagnosticsPublic(PublicModel):
    """Per transmitter (forward paths only): power reaching surfaces and leaving the scene, per watt."""

    power_on_surfaces: dict[str, float]
    escaped_power: dict[str, float]
    medium_evaluations: int


class PilotPublic(PublicModel):
    """The truncation pilot that chose K, S or the time window (docs/modeled.md)."""

    paths: int = Field(description="paths per source device of the pilot")
    receivers: list[str] = Field(description="the receivers it traced (up to 8, evenly chosen)")
    max_reflections: int = Field(description="highest reflection order it measured")
    max_scattering: int | None = Field(None, description="highest scattering order it measured")
    t_max_s: float = Field(description="end of its time window [s]")
    allowed_truncation_per_watt: float = Field(description="power per watt the chosen settings may leave out")
    rho_max: float = Field(description="largest reflectance of the scene's surfaces")


class UnreachablePublic(PublicModel):
    """A receiver no light can reach, not simulated."""

    receiver: str = Field(description="receiver id")
    reason: str = Field(description="why no light reaches it")


class ModeledPublic(PublicModel):
    """What was simulated, what was left out, and why (engine/run/auto.py; docs/modeled.md). Keys a newer engine
    adds are kept."""

    model_config = ConfigDict(extra="allow")

    rules: str | None = Field(None, description="where the rules of the automatic settings are")
    algorithm: int | None = Field(None, description="the algorithm that ran")
    algorithm_reason: str | None = Field(None, description="why this algorithm (requested, or the rule that chose it)")
    families: str | None = Field(None, description="the path families estimated")
    left_out: list[str] = Field(default_factory=list, description="what the estimate leaves out")
    medium: dict | None = Field(
        None,
        description="the medium's derived figures: coefficients, phase function, "
        "visibility (particle smoke: its Mie optics)",
    )
    max_reflections: int | None = Field(None, description="K, the highest reflection order")
    max_reflections_reason: str | None = Field(None, description="why K (when chosen automatically)")
    max_scattering: int | None = Field(None, description="S, the highest scattering order (0 without a medium)")
    max_scattering_reason: str | None = Field(None, description="why S (when chosen automatically)")
    time_window_s: tuple[float, float] | None = Field(None, description="the binned CIR's window [s]")
    time_window_reason: str | None = Field(None, description="why the window ends there (when chosen automatically)")
    pilot: PilotPublic | None = Field(None, description="the truncation pilot, when one ran")
    truncation_estimate_per_watt: float | None = Field(
        None, description="estimated power per watt of the orders left out (from the pilot)"
    )
    truncation_note: str | None = Field(None, description="how the truncation estimate was made")
    truncation_within_allowance: bool | None = Field(
        None,
        description="whether the automatic K and S keep the estimated truncated power within the allowance "
        "(false: the result warns; null: no order was chosen automatically)",
    )
    outputs_reason: str | None = Field(None, description="why an output asked by default was not computed")
    unreachable_receivers: list[UnreachablePublic] = Field(
        default_factory=list, description="receivers no light can reach, not simulated"
    )


class SimulationResultPublic(PublicModel):
    owcsim_version: str
    algorithm: int
    families: str
    time_bins: TimeBinsPublic
    links: list[LinkPublic]
    receivers: list[ReceiverPublic] = Field(default_factory=list)
    channels: list[ChannelPublic] = Field(default_factory=list, description="transmitter groups' channels")
    maps: list[MapPublic] = Field(default_factory=list, description="receiver grids as 2-D arrays")
    orientation: list[OrientationPointPublic] = Field(
        default_factory=list,
        description="per point and channel: statistics over random orientation (docs/orientation.md)",
    )
    angle_diversity: list[CombinedSnrPublic] = Field(
        default_factory=list,
        description="per angle-diversity receiver and channel: combined SNRs (docs/orientation.md)",
    )
    cells: CellsPublic | None = Field(
        None, description="multi-cell LiFi: serving cell, SINR, rates, handover boundaries (schemas/cells.py)"
    )
    run: RunPublic
    diagnostics: DiagnosticsPublic
    warnings: list[str] = Field(default_factory=list, description="what a careful reader of these numbers should know")
    modeled: ModeledPublic = Field(
        default_factory=ModeledPublic, description="what was simulated, what was left out, and why"
    )
    spectral: SpectralResultPublic | None = Field(
        None, description="per wavelength band and combined (scenes with `spectral`; docs/spectra.md)"
    )
    lighting: LightingResultPublic | None = Field(
        None, description="luminous fluxes and EN 12464-1 figures (when a transmitter gives light; docs/lighting.md)"
    )
    timeline: TimelineResultPublic | None = Field(
        None, description="the channel at every time of the scene's `timeline` (schemas/timeline.py)"
    )
    scene: SceneSpec
