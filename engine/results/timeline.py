"""The `timeline` of a result (schemas/timeline.py): every link's channel over time, its errors, its outages.

Per time the figures are those of the time's run (H0, its standard error, the orders, tau_rms, received
power, SNR, BER). The error of a difference H0(t_{i+1}) - H0(t_i) comes from the path groups the two runs
share (the same sample indices, engine/run/frames.py): with x_g, w_g group g's estimate and paths in each
run, m = sum w x / sum w, a_g = w_g (x_g - m) / sum w, var = G / (G - 1) sum_g (a_g - b_g)^2 over the G
groups filled in both runs (the batch-means variance of a difference of paired means; G = 1: unknown).

Outages: a link is out while its quantity is worse than the threshold. A crossing time is interpolated
linearly between the two evaluation times around it, in log10 of the quantity for dc_gain, received power
and BER (where a Beer-Lambert attenuation whose extinction grows linearly in time is exactly linear) and in
dB for the SNR. An evaluation time is ambiguous when its error bar, k_sigma standard errors of H0 carried
to the quantity (for SNR and BER through the link budget's SNR of the shifted received power), straddles
the threshold; an interval is uncertain when a time next to one of its crossings, or inside it, is.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from owcsim.engine.core.arrays import FloatArray
from owcsim.engine.results.link_budget import LinkBudget, ber_ook, snr
from owcsim.schemas.results import ChannelPublic, LinkPublic
from owcsim.schemas.timeline import (
    OutageIntervalPublic,
    OutageSpec,
    TimelineLinkPublic,
    TimelineResultPublic,
    finite_or_none,
)

#: log10 floor of quantities that reach 0 (no power: an unreachable receiver) [-].
LOG_FLOOR = -300.0


@dataclass
class Series:
    """One link (or channel) over time as the runs gave it: `entries[i]` the figures at time i."""

    tx: str
    rx: str
    kind: str
    entries: list[LinkPublic | ChannelPublic]
    positions: FloatArray  # (T, 3) [m]
    groups: FloatArray | None  # (T, G) path groups' H0 estimates
    paths: FloatArray | None  # (T, G) their paths (0 = empty)
    area: float  # receiver area [m^2] (the SNR's noise)


def diff_stderr(groups: FloatArray, paths: FloatArray) -> FloatArray:
    """(T - 1,) standard error of H0[i + 1] - H0[i] from paired path groups (NaN: fewer than 2 shared groups)."""
    x, w = np.asarray(groups, float), np.asarray(paths, float)
    wsum = np.maximum(w.sum(axis=1, keepdims=True), 1e-300)
    m = (w * x).sum(axis=1, keepdims=True) / wsum
    a = w * (x - m) / wsum  # (T, G) each group's share of the mean's deviation
    both = (w[1:] > 0) & (w[:-1] > 0)
    g = both.sum(axis=1)
    var = np.where(both, (a[1:] - a[:-1]) ** 2, 0.0).sum(axis=1) * g / np.maximum(g - 1, 1)
    return np.where(g >= 2, np.sqrt(var), np.nan)


def outage_intervals(
    times: FloatArray, y: FloatArray, y_lo: FloatArray, y_hi: FloatArray, threshold: float
) -> list[OutageIntervalPublic]:
    """Intervals where y < threshold (y already in its interpolation scale, larger = better); y_lo, y_hi the
    error bar's ends. NaN counts as out (no signal)."""
    t = np.asarray(times, float)
    y = np.where(np.isnan(y), -np.inf, y)  # +inf (a BER of 0) is perfect
    out = y < threshold
    amb = (np.nan_to_num(y_lo, nan=-np.inf) < threshold) != (np.nan_to_num(y_hi, nan=-np.inf) < threshold)
    floor = min(LOG_FLOOR, threshold - 1.0)
    yc = np.clip(y, floor, max(-LOG_FLOOR, threshold + 1.0))
    change = np.flatnonzero(out[1:] != out[:-1])  # crossing between times i and i + 1
    with np.errstate(divide="ignore", invalid="ignore"):
        w = np.clip((threshold - yc[change]) / (yc[change + 1] - yc[change]), 0.0, 1.0)
    cross = t[change] + w * (t[change + 1] - t[change])
    starts = ([(float(t[0]), 0)] if out[0] else []) + [(float(c), int(i)) for c, i in zip(cross, change) if out[i + 1]]
    ends = [(float(c), int(i)) for c, i in zip(cross, change) if out[i]] + ([(None, len(t) - 1)] if out[-1] else [])
    return [
        OutageIntervalPublic(start_s=s, end_s=e, uncertain=bool(amb[i0 : min(i1 + 2, len(t))].any()))
        for (s, i0), (e, i1) in zip(starts, ends)
    ]


def _arr(values) -> FloatArray:
    return np.array([np.nan if v is None else v for v in values], float)


def _bands(series: Series, outage: OutageSpec, budget: LinkBudget | None) -> tuple[FloatArray, FloatArray, FloatArray]:
    """(y, y_lo, y_hi): the outage quantity per time in its interpolation scale (larger = better)."""
    h0 = _arr([e.dc_gain for e in series.entries])
    se = np.nan_to_num(_arr([e.dc_gain_stderr for e in series.entries]))
    k = outage.k_sigma
    with np.errstate(divide="ignore", invalid="ignore"):
        lo, hi = np.maximum(h0 - k * se, 0.0) / h0, (h0 + k * se) / h0  # H0 scale factors of the error bar
        if outage.quantity in ("dc_gain", "received_power_w"):
            q = h0 if outage.quantity == "dc_gain" else _arr([e.received_power_w for e in series.entries])
            return np.log10(q), np.log10(q * lo), np.log10(q * hi)
        if budget is None:
            raise ValueError(f"an outage on {outage.quantity} needs the scene's `link_budget`")
        p = _arr([e.received_power_w for e in series.entries])
        snr0 = 10 ** (_arr([e.snr_db for e in series.entries]) / 10)
        ratio = [snr(budget, series.area, p * s) / snr(budget, series.area, p) for s in (lo, hi)]
        if outage.quantity == "snr_db":
            return 10 * np.log10(snr0), 10 * np.log10(snr0 * ratio[0]), 10 * np.log10(snr0 * ratio[1])
        q = _arr([e.ber for e in series.entries])
        return -np.log10(q), -np.log10(ber_ook(snr0 * ratio[0])), -np.log10(ber_ook(snr0 * ratio[1]))


def _threshold(outage: OutageSpec) -> float:
    """The threshold in the interpolation scale of `_bands`."""
    if outage.quantity == "snr_db":
        return outage.threshold
    return float(np.log10(outage.threshold)) * (-1.0 if outage.quantity == "ber" else 1.0)


def _none(values: FloatArray) -> list[float | None]:
    return [finite_or_none(float(v)) for v in values]


def timeline_link(
    times: FloatArray, series: Series, outage: OutageSpec | None, budget: LinkBudget | None, cir: bool
) -> TimelineLinkPublic:
    """One link's (or channel's) figures over time, its difference errors and outages."""
    entries = series.entries
    diff = (
        diff_stderr(series.groups, series.paths)
        if series.groups is not None and series.paths is not None
        else np.full(len(times) - 1, np.nan)
    )
    budgeted = any(e.snr_db is not None for e in entries)
    link = TimelineLinkPublic(
        tx=series.tx,
        rx=series.rx,
        kind="channel" if series.kind == "channel" else "link",
        receiver_position=[tuple(p) for p in np.asarray(series.positions, float).tolist()],
        dc_gain=[e.dc_gain for e in entries],
        dc_gain_stderr=[e.dc_gain_stderr for e in entries],
        dc_gain_diff_stderr=_none(diff),
        los_gain=[e.los_gain if isinstance(e, LinkPublic) else None for e in entries],
        dc_gain_by_reflection_order=[getattr(e, "dc_gain_by_reflection_order", None) for e in entries] or None,
        dc_gain_by_scattering_order=[getattr(e, "dc_gain_by_scattering_order", None) for e in entries] or None,
        rms_delay_spread_s=[e.rms_delay_spread_s for e in entries],
        received_power_w=[e.received_power_w for e in entries],
        snr_db=[e.snr_db for e in entries] if budgeted else None,
        ber=[e.ber for e in entries] if any(e.ber is not None for e in entries) else None,
        max_bit_rate_bps=[e.max_bit_rate_bps for e in entries] if budgeted else None,
        cir=[e.cir.total if e.cir is not None else [] for e in entries] if cir else None,
    )
    if outage is None:
        return link
    intervals = outage_intervals(times, *_bands(series, outage, budget), _threshold(outage))
    first = intervals[0].start_s - float(times[0]) if intervals else None
    return link.model_copy(update={"outages": intervals, "time_to_first_outage_s": first})


def build_timeline(
    times: FloatArray,
    series: list[Series],
    *,
    outage: OutageSpec | None,
    budget: LinkBudget | None,
    method: str,
    frames_source: str | None,
    medium_in_time: str,
    cir: bool = False,
    notes: list[str] | None = None,
) -> TimelineResultPublic:
    """The result's `timeline` section."""
    return TimelineResultPublic(
        times_s=[float(t) for t in times],
        method=method,
        frames_source=frames_source,
        medium_in_time=medium_in_time,
        outage=outage,
        links=[timeline_link(times, s, outage, budget, cir) for s in series],
        notes=notes or [],
    )
