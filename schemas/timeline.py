"""Channels over time (issue 26): the `timeline` section of a scene document and the `timeline` of its result.

A timeline evaluates the channel at a list of times `times_s` [s]. The smoke over time comes from
`frames` (schemas/frames.py; the document's static `medium` must then be absent); the medium at a
time t between two frames is the frames interpolated linearly in time, cell by cell
(sigma(t) = (1 - w) sigma_i + w sigma_{i+1}, w = (t - t_i) / (t_{i+1} - t_i)), so at a frame's
own time it is that frame exactly. Receivers move along `trajectories` (a table of times and
positions, or waypoints walked at a speed). Outage intervals are found against `outage`.
"""

from __future__ import annotations

import math
from enum import StrEnum
from typing import Any, Literal

from pydantic import BaseModel, ConfigDict, Field, model_validator

from .base import Direction, Point, SpecModel
from .frames import MAX_FRAMES, FramesReportPublic, FramesSpec

#: Most evaluation times and trajectory table rows.
MAX_TIMES = MAX_FRAMES


class TimelineMethod(StrEnum):
    """How the frames are run: each its own run with the same random numbers (independent), one set of paths
    reweighted per frame (reweighted), or the engine's choice (auto: reweighted from 3 times on when no device moves
    and there is no receiver grid, else independent; engine/run/timeline.py `frames_method`)."""

    INDEPENDENT = "independent"
    REWEIGHTED = "reweighted"
    AUTO = "auto"


class TrajectoryOrientation(StrEnum):
    """fixed: the device keeps its document `normal`; heading: the normal is given in the walker's frame
    (+x forward, +z up) and turns about the vertical with the walking direction."""

    FIXED = "fixed"
    HEADING = "heading"


class TrajectorySpec(SpecModel):
    """Where a receiver is over time: a table (`times_s`, `positions`, optional `normals`) or `waypoints`
    walked at `speed_m_s` from `start_s`, pausing `pause_s` at every inner waypoint.

    Between table rows the position (and normal) is interpolated linearly; before the first time the device
    is at the first position, after the last at the last (it stands still)."""

    device: str = Field(min_length=1, description="id of the receiver that moves")
    times_s: list[float] | None = Field(None, max_length=MAX_TIMES, description="table: times [s], increasing")
    positions: list[Point] | None = Field(None, max_length=MAX_TIMES, description="table: positions [m]")
    normals: list[Direction] | None = Field(None, max_length=MAX_TIMES, description="table: normals (optional)")
    waypoints: list[Point] | None = Field(None, min_length=2, max_length=MAX_TIMES, description="points walked [m]")
    speed_m_s: float | None = Field(None, gt=0.0, le=100.0, description="walking speed [m/s]")
    start_s: float = Field(0.0, description="time the walk starts [s] (waypoints)")
    pause_s: float = Field(0.0, ge=0.0, description="stop at every inner waypoint [s]")
    orientation: TrajectoryOrientation = TrajectoryOrientation.FIXED

    @model_validator(mode="after")
    def _one_form(self) -> "TrajectorySpec":
        table = self.times_s is not None or self.positions is not None
        walk = self.waypoints is not None
        if table == walk:
            raise ValueError("give either a table (`times_s` and `positions`) or `waypoints` with `speed_m_s`")
        if walk:
            if self.speed_m_s is None:
                raise ValueError("`waypoints` need `speed_m_s` [m/s]")
            if self.normals is not None:
                raise ValueError("`normals` belong to a table; waypoints use `orientation`")
            return self
        if self.times_s is None or self.positions is None or len(self.times_s) != len(self.positions):
            raise ValueError("a table needs `times_s` and `positions` of the same length")
        if not self.times_s:
            raise ValueError("a table needs at least one row")
        if any(b <= a for a, b in zip(self.times_s, self.times_s[1:])):
            raise ValueError("`times_s` must be strictly increasing [s]")
        if self.normals is not None and len(self.normals) != len(self.times_s):
            raise ValueError("`normals` needs one normal per row of `times_s`")
        if self.normals is not None and self.orientation is not TrajectoryOrientation.FIXED:
            raise ValueError("a table with `normals` gives the orientation: leave `orientation` fixed")
        if self.normals is not None:
            unit = [[c / (math.hypot(*n) or 1.0) for c in n] for n in self.normals]
            for i, (a, b) in enumerate(zip(unit, unit[1:])):
                if sum(x * y for x, y in zip(a, b)) <= -1.0 + 1e-12:
                    raise ValueError(
                        f"`normals` rows {i} and {i + 1} are opposite: the turn between them has no defined "
                        "plane (the normals are interpolated linearly); add a row in between"
                    )
        return self

    def points(self) -> list[tuple[float, float, float]]:
        """Every position the trajectory passes through (to check them against the room)."""
        return list(self.waypoints if self.waypoints is not None else self.positions or [])


class OutageSpec(SpecModel):
    """A link is in outage while `quantity` is worse than `threshold`: below it for dc_gain [-],
    received_power_w [W] and snr_db [dB], above it for ber [-]. A time is uncertain when the error bar
    (`k_sigma` standard errors of H0, carried to the quantity) straddles the threshold."""

    quantity: Literal["dc_gain", "received_power_w", "snr_db", "ber"] = "dc_gain"
    threshold: float = Field(description="the limit, in the quantity's unit")
    k_sigma: float = Field(2.0, gt=0.0, le=10.0, description="error bar half-width in standard errors")

    @model_validator(mode="after")
    def _positive(self) -> "OutageSpec":
        if self.quantity != "snr_db" and not self.threshold > 0:
            raise ValueError(f"the {self.quantity} threshold must be > 0")
        if self.quantity == "ber" and not self.threshold < 0.5:
            raise ValueError("the ber threshold must be < 0.5")
        return self


class TimelineSpec(SpecModel):
    """The channel at several times: time-varying smoke (`frames`), moving receivers (`trajectories`)."""

    frames: FramesSpec | None = Field(
        None, description="the smoke over time; the document's static `medium` must then be absent"
    )
    times_s: list[float] | None = Field(
        None,
        min_length=1,
        max_length=MAX_TIMES,
        description="evaluation times [s], increasing; default the frames' times. Between frames the medium is "
        "the frames interpolated linearly in time",
    )
    trajectories: list[TrajectorySpec] = Field(default_factory=list, description="moving receivers")
    outage: OutageSpec | None = None
    method: TimelineMethod = TimelineMethod.AUTO
    cir: bool = Field(False, description="keep every time's binned CIR in the result")

    @model_validator(mode="after")
    def _times(self) -> "TimelineSpec":
        if self.times_s is not None and any(b <= a for a, b in zip(self.times_s, self.times_s[1:])):
            raise ValueError("`times_s` must be strictly increasing [s]")
        if self.frames is None and self.times_s is None:
            raise ValueError("without `frames`, give the evaluation times `times_s` [s]")
        frame_times = getattr(self.frames, "times", None)  # in the document (inline); file kinds: checked when read
        if frame_times and self.times_s is not None:
            t0, t1 = frame_times[0], frame_times[-1]
            out = [t for t in self.times_s if t < t0 or t > t1]
            if out:
                raise ValueError(
                    f"`times_s` {out[:5]} lie outside the frames' times {t0:g}..{t1:g} s: the medium is known only "
                    "between the first and the last frame"
                )
        if self.frames is None and not self.trajectories:
            raise ValueError("a timeline needs `frames` (smoke over time) or `trajectories` (moving receivers)")
        devices = [t.device for t in self.trajectories]
        if len(set(devices)) != len(devices):
            raise ValueError("`trajectories`: a device has two trajectories")
        return self


def check_timeline(scene: Any) -> None:
    """ValueError (located) when the scene's `timeline` does not fit the rest of the document."""
    tl: TimelineSpec | None = scene.timeline
    if tl is None:
        return
    if tl.frames is not None and scene.medium is not None:
        raise ValueError(
            "timeline.frames gives the medium over time: remove the static `medium` (a scene has one or the other)"
        )
    if scene.spectral is not None:
        raise ValueError("timeline: spectral scenes are not supported over time yet (remove `spectral`)")
    explicit = {r.id or f"rx{i}": r for i, r in enumerate(scene.receivers)}
    tx_ids = set(scene.transmitter_ids())
    for k, traj in enumerate(tl.trajectories):
        where = f"timeline.trajectories[{k}] ({traj.device})"
        if traj.device in tx_ids:
            raise ValueError(f"{where}: moving transmitters are not supported yet: only receivers move")
        if traj.device not in explicit:
            raise ValueError(
                f"{where}: no receiver with this id; a trajectory moves one of `receivers` "
                f"(ids {sorted(explicit)[:10]})"
            )
        if explicit[traj.device].orientation is not None:
            raise ValueError(f"{where}: a receiver with `orientation` statistics cannot move yet")
        if scene.room is not None:
            lo, hi = scene.room.lo, scene.room.hi
            for p in traj.points():
                if any(c < a or c > b for a, b, c in zip(lo, hi, p)):
                    raise ValueError(f"{where}: the point {tuple(p)} is outside the room {lo}..{hi}")
        points = traj.points()
        legs = list(zip(points[:-1], points[1:])) if len(points) > 1 else [(q, q) for q in points]
        for j, box in enumerate(scene.furniture):
            for a, b in legs:
                if _through_box(a, b, box.min, box.max):
                    name = f" ({box.name})" if box.name else ""
                    raise ValueError(
                        f"{where}: the leg {tuple(a)} -> {tuple(b)} passes through furniture[{j}]{name}: a receiver "
                        "cannot move inside a solid box (go around it, or over it: its faces are allowed)"
                    )


def _through_box(a: Point, b: Point, lo: Point, hi: Point) -> bool:
    """Whether the segment a -> b (a point when a == b) meets the open interior of the box lo..hi (touching
    or sliding along a face does not count): the slab test with strict inequalities."""
    enter, leave = 0.0, 1.0
    for p, q, l, h in zip(a, b, lo, hi):
        d = q - p
        if d == 0.0:
            if not l < p < h:
                return False
            continue
        s0, s1 = (l - p) / d, (h - p) / d
        enter, leave = max(enter, min(s0, s1)), min(leave, max(s0, s1))
    return enter < leave


# ----------------------------------------------------------------------------------------------- the result


class _Public(BaseModel):
    model_config = ConfigDict(extra="ignore")


class OutageIntervalPublic(_Public):
    """One interval a link spends in outage [s]; the crossing times are interpolated linearly between the
    evaluation times (in log10 of the quantity for dc_gain, received power and BER, where a Beer-Lambert
    attenuation with linearly growing extinction is linear)."""

    start_s: float = Field(description="start [s]: the first time when the link is already out at it")
    end_s: float | None = Field(description="end [s]; null: still in outage at the last time")
    uncertain: bool = Field(
        description="an evaluation time at either crossing has an error bar (k_sigma standard errors) that straddles "
        "the threshold: the crossing may lie one interval earlier or later, or the interval may not exist"
    )


class TimelineLinkPublic(_Public):
    """One link (or a transmitter group's channel) over time: one value per time of `times_s`."""

    tx: str = Field(description="transmitter id, or the transmitter group's name (kind channel)")
    rx: str = Field(description="receiver id (a moving receiver keeps its id)")
    kind: Literal["link", "channel"] = "link"
    receiver_position: list[tuple[float, float, float]] = Field(description="receiver position per time [m]")
    dc_gain: list[float | None] = Field(description="H0 per time [-]")
    dc_gain_stderr: list[float | None] = Field(description="standard error of H0 per time [-]")
    dc_gain_diff_stderr: list[float | None] = Field(
        description="standard error of H0(t_{i+1}) - H0(t_i), from the path groups shared by the two runs (T - 1 "
        "values; null when unknown: a receiver that moved, or fewer than two groups)"
    )
    los_gain: list[float | None] = Field(default_factory=list, description="exact line-of-sight H0 per time [-]")
    dc_gain_by_reflection_order: list[list[float] | None] | None = None
    dc_gain_by_scattering_order: list[list[float] | None] | None = None
    rms_delay_spread_s: list[float | None] = Field(default_factory=list, description="tau_rms per time [s]")
    received_power_w: list[float | None] = Field(default_factory=list, description="P_t H0 per time [W]")
    snr_db: list[float | None] | None = Field(None, description="SNR per time [dB] (with `link_budget`)")
    ber: list[float | None] | None = Field(None, description="BER of OOK-NRZ per time (with a bit rate)")
    max_bit_rate_bps: list[float | None] | None = Field(None, description="bit rate tau_rms allows [bit/s]")
    cir: list[list[float]] | None = Field(None, description="binned CIR per time (timeline.cir)")
    outages: list[OutageIntervalPublic] = Field(default_factory=list)
    time_to_first_outage_s: float | None = Field(
        None, description="start of the first outage minus the first time [s]; null: no outage"
    )


class TimelineResultPublic(_Public):
    """The channel at every time of a timeline (schemas/timeline.py)."""

    times_s: list[float] = Field(description="evaluation times [s]")
    method: str = Field(description="how the frames ran: independent or reweighted")
    frames_source: str | None = Field(None, description="where the frames came from and how they became sigma")
    frames_report: FramesReportPublic | None = Field(
        None, description="the frames' source, file, quantity, K_m, wavelength factor, albedo, grid and mapping"
    )
    medium_in_time: str = Field(description="how the medium at a time is made from the frames")
    outage: OutageSpec | None = None
    links: list[TimelineLinkPublic]
    notes: list[str] = Field(default_factory=list)

    def link(self, tx: str, rx: str) -> TimelineLinkPublic:
        """The link (or channel) from `tx` to `rx`."""
        for entry in self.links:
            if entry.tx == tx and entry.rx == rx:
                return entry
        raise KeyError(f"no timeline link {tx} -> {rx}")


def finite_or_none(x: float) -> float | None:
    """JSON null for NaN / inf."""
    return float(x) if math.isfinite(x) else None
