"""The result document: what `owcsim run` writes as result.json and the API returns.

Every Monte Carlo figure has a `_stderr` twin (one standard error). Delays are
absolute (from emission), not relative to the line-of-sight arrival; `los_delay_s`
gives the offset for a LOS-relative view. Figures that do not exist (an unreachable
link's delays, a bandwidth above the binning's Nyquist frequency, an error bar
from fewer than two batch groups) are null.
"""
from __future__ import annotations

from typing import Literal

from pydantic import BaseModel, ConfigDict, Field

from .scene import SceneSpec


class PublicModel(BaseModel):
    """Output model: tolerant of fields added by newer engines."""

    model_config = ConfigDict(extra="ignore")


class CirPublic(PublicModel):
    """Binned impulse response of one link: power per bin per watt (h(t) = power / dt [1/s])."""

    total: list[float]
    total_stderr: list[float | None]
    by_reflection_order: list[list[float]] = Field(description="[k][bin], k = 0..max_reflections")
    by_scattering_order: list[list[float]] = Field(description="[s][bin], s = 0..S of the algorithm")


class LinkPublic(PublicModel):
    transmitter: str
    receiver: str
    transmitter_index: int
    receiver_index: int
    direction: Literal["forward", "backward", "both", "none"]
    paths: int
    dc_gain: float
    dc_gain_stderr: float | None
    path_loss_db: float | None
    received_power_w: float
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
        None, description="estimated power per watt of the reflection (and scattering) orders beyond K (and S), "
                          "not in dc_gain: the last order's gain times rho_max / (1 - rho_max) (albedo for S)")
    los_gain: float
    los_delay_s: float
    dc_gain_by_reflection_order: list[float]
    dc_gain_by_reflection_order_stderr: list[float | None]
    dc_gain_by_scattering_order: list[float]
    dc_gain_by_scattering_order_stderr: list[float | None]
    early_gain: float = Field(description="power per watt arriving before t_min_s (not in the CIR)")
    late_gain: float = Field(description="power per watt arriving after t_max_s (not in the CIR)")
    cir: CirPublic


class TimeBinsPublic(PublicModel):
    t_min_s: float
    time_bin_s: float
    n_bins: int


class RunPublic(PublicModel):
    stop_reason: Literal["paths", "target_reached", "time_budget", "cancelled", "nothing_to_simulate"]
    target_rel_error: float | None
    max_dc_gain_rel_stderr: float | None
    wall_time_s: float
    workers: int
    batches: int
    paths_total: int
    rays_intersect: int
    rays_occluded: int
    direction_choice: dict


class DiagnosticsPublic(PublicModel):
    """Per transmitter (forward paths only): power reaching surfaces and leaving the scene, per watt."""

    power_on_surfaces: dict[str, float]
    escaped_power: dict[str, float]
    medium_evaluations: int


class SimulationResultPublic(PublicModel):
    owcsim_version: str
    algorithm: int
    families: str
    time_bins: TimeBinsPublic
    links: list[LinkPublic]
    run: RunPublic
    diagnostics: DiagnosticsPublic
    warnings: list[str] = Field(default_factory=list, description="what a careful reader of these numbers should know")
    modeled: dict = Field(default_factory=dict, description="what was simulated, what was left out, and why")
    scene: SceneSpec
