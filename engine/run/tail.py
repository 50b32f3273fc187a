"""The order and window mathematics of the automatic settings: where to stop K, S and the time window.

From a pilot's per-order gains (and, per order, the delay moments of its binned CIR), the power
of the orders above n, tail(n) = the pilot's orders above n + the geometric tail past its last
well-measured order (engine/results/truncation.py) + two pilot standard errors, with its delay
moments (`tail_moments`); the smallest n whose tail is within its allowance and whose dropping
shifts tau0 and tau_rms by at most a fraction of tau_rms (`tail_order`, `delay_shift`); the
window end that holds the orders chosen past the pilot (`order_window_end`) and the one past which
less than the allowance arrives (`window_end`, an exponential fit of the late response).
`choose_order` applies these over the pilot's links and says why, for engine/run/auto.py.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Iterator, Sequence
from dataclasses import dataclass
from enum import Enum

import numpy as np

from owcsim.engine.core.arrays import FloatArray
from owcsim.engine.results.truncation import tail_ratio
from owcsim.schemas.results import LinkPublic

#: Highest order K (S) the automatic choice may take: the schema's limit of `max_reflections` (`max_scattering`).
MAX_ORDER = 1000

#: Per-order gains [per watt] as the result holds them.
Gains = Sequence[float] | FloatArray
#: Their standard errors (None: not measured).
Errors = Sequence[float | None] | FloatArray


class OrderKind(Enum):
    """The order split a choice reads: reflection orders (K, bounded by rho_max) or scattering orders (S)."""

    REFLECTION = "reflection"
    SCATTERING = "scattering"

    @property
    def bound_name(self) -> str:
        """The a-priori bound of the per-order ratio, as the reasons name it."""
        return "rho_max" if self is OrderKind.REFLECTION else "albedo_max"


def _measured(gains: Gains, errors: Errors) -> tuple[FloatArray, FloatArray, np.ndarray]:
    """(gains, errors, the orders measured to 30 %) as arrays (a missing error counts as 0)."""
    g = np.asarray(gains, float)
    e = np.asarray([x or 0.0 for x in errors], float)
    return g, e, np.flatnonzero((g > 0) & (e <= 0.3 * np.where(g > 0, g, 1.0)))


def order_moments(cir_by_order, t_mid: FloatArray) -> tuple[FloatArray, FloatArray]:
    """Per order: (mean delay, mean squared delay) of its binned pilot CIR [s, s^2] (0 where it is empty)."""
    h = np.asarray(cir_by_order, float)
    m0 = h.sum(axis=1)
    safe = np.where(m0 > 0, m0, 1.0)
    return np.where(m0 > 0, h @ t_mid / safe, 0.0), np.where(m0 > 0, h @ (t_mid * t_mid) / safe, 0.0)


def tail_moments(
    n: int, gains: Gains, errors: Errors, t1: FloatArray, t2: FloatArray, ratio: float
) -> tuple[float, float, float]:
    """Power P of the orders above n and its delay moments P t, P t^2 [per watt, s, s^2].

    The pilot's orders up to its last well-measured one L (relative error <= 30 %) count as
    measured; past L (or past n, if later) the tail is geometric with the per-order `ratio`
    from g_L, keeping the mean delay step dt = t1[L] - t1[L-1] per order and the spread of
    order L; the pilot's own noisy values past L count instead where they are larger;
    two pilot standard errors of the orders above n are added.
    """
    g, e, good = _measured(gains, errors)
    if not len(good):
        p = g[n + 1 :].sum()
        noise = 2.0 * math.sqrt(float((e[n + 1 :] ** 2).sum()))
        return (0.0, 0.0, 0.0) if p + noise == 0 else (math.inf, math.inf, math.inf)
    L = int(good[-1])
    upto = slice(n + 1, L + 1)
    p = g[upto].sum()
    p1 = (g[upto] * t1[upto]).sum()
    p2 = (g[upto] * t2[upto]).sum()
    start = max(L, n)
    beyond = slice(start + 1, None)
    measured_beyond = (g[beyond].sum(), (g[beyond] * t1[beyond]).sum(), (g[beyond] * t2[beyond]).sum())
    if g[L] > 0:
        if not math.isfinite(ratio) or ratio >= 1.0:
            return math.inf, math.inf, math.inf
        g_start = g[L] * ratio ** (start - L)
        step = max(t1[L] - t1[L - 1], 0.0) if L >= 1 and g[L - 1] > 0 else 0.0
        var_L = max(t2[L] - t1[L] ** 2, 0.0)
        s0 = ratio / (1 - ratio)  # sum r^i, i >= 1
        s1 = ratio / (1 - ratio) ** 2  # sum i r^i
        s2 = ratio * (1 + ratio) / (1 - ratio) ** 3  # sum i^2 r^i
        base = t1[L] + (start - L) * step
        geo = (
            g_start * s0,
            g_start * (base * s0 + step * s1),
            g_start * ((base * base + var_L) * s0 + 2 * base * step * s1 + step * step * s2),
        )
        extra = geo if geo[0] >= measured_beyond[0] else measured_beyond
    else:
        extra = measured_beyond
    p, p1, p2 = p + extra[0], p1 + extra[1], p2 + extra[2]
    noise = 2.0 * math.sqrt(float((e[n + 1 :] ** 2).sum()))
    if p > 0 and noise > 0:  # the pilot's error on the tail, at the tail's delays
        scale = (p + noise) / p
        p, p1, p2 = p * scale, p1 * scale, p2 * scale
    elif noise > 0:
        p, p1, p2 = noise, noise * t1[min(n, len(t1) - 1)], noise * t2[min(n, len(t2) - 1)]
    return p, p1, p2


def delay_shift(h0: float, tau0: float, tau_rms: float, p: float, p1: float, p2: float) -> tuple[float, float]:
    """(|shift of tau0|, |shift of tau_rms|) [s] when power p with delay moments p1, p2 is left out of a link
    whose full response has gain h0, mean delay tau0 and RMS delay spread tau_rms."""
    if not math.isfinite(p) or p >= h0:
        return math.inf, math.inf
    if p <= 0:
        return 0.0, 0.0
    h, m1, m2 = h0 - p, h0 * tau0 - p1, h0 * (tau_rms**2 + tau0**2) - p2  # what the truncated run measures
    t0_cut = m1 / h
    rms_cut = math.sqrt(max(m2 / h - t0_cut**2, 0.0))
    return abs(t0_cut - tau0), abs(rms_cut - tau_rms)


@dataclass(frozen=True)
class LinkDelays:
    """What `tail_order` needs of a link's delays: per order (t1, t2) [s, s^2] of the pilot's binned CIR, the
    link's H0, tau0 [s] and tau_rms [s], and the allowed shift of each as a fraction `rel` of tau_rms."""

    t1: FloatArray
    t2: FloatArray
    h0: float
    tau0: float
    tau_rms: float
    rel: float


@dataclass(frozen=True)
class TailCut:
    """An order n and what dropping the orders above it leaves out: their power [per watt], the shifts of tau0
    and tau_rms [s], the power allowance at n [per watt] and whether the delay shifts are within theirs."""

    order: int
    power: float
    shift_tau0: float
    shift_rms: float
    allowed: float
    delays_within: bool


class _Beyond:
    """The orders past the pilot's last one (when the power there is over the allowance): the full response's
    moments (the pilot's and the geometric tail past it) and the allowance relative to its H0."""

    def __init__(self, gains: Gains, errors: Errors, t1: FloatArray, t2: FloatArray, ratio: float, allowed: float):
        n_orders = len(gains)
        self.full = tail_moments(n_orders - 1, gains, errors, t1, t2, ratio)
        measured = float(np.sum(gains))
        self.allowed = allowed * (1.0 + self.full[0] / measured) if measured > 0 else allowed
        self.first = n_orders
        if self.full[0] > self.allowed > 0:  # tail(n) = full r^(n - n_orders + 1): skip the orders that cannot do
            self.first = n_orders - 2 + math.ceil(math.log(self.allowed / self.full[0]) / math.log(ratio))


def _full_response(d: LinkDelays, full: tuple[float, float, float]) -> tuple[float, float, float]:
    """(H0, tau0, tau_rms) of the full response: the pilot's orders and the geometric tail past them."""
    m1, m2 = d.h0 * d.tau0 + full[1], d.h0 * (d.tau_rms**2 + d.tau0**2) + full[2]
    h0 = d.h0 + full[0]
    tau0 = m1 / h0
    return h0, tau0, math.sqrt(max(m2 / h0 - tau0**2, 0.0))


def tail_order(
    gains: Gains,
    errors: Errors,
    ratio: float,
    allowed: float,
    cap: int,
    delays: LinkDelays | None = None,
    limit: int | None = None,
) -> TailCut:
    """Smallest order n whose tail is within its allowance (else the cap), and that tail [per watt].

    tail(n) = the pilot's orders above n + the geometric tail past its last measured
    order (`truncation.tail_ratio`) + 2 pilot standard errors. With `delays` (per-order delay
    moments, the link's H0 and delays, the relative allowance), the order must also keep the
    shifts of tau0 and tau_rms that dropping the tail causes (`delay_shift`, a late tail
    weighted by its delay) under rel x tau_rms each. With `limit` (> the pilot's orders), a
    finite ratio < 1 and a power past the pilot's last order over the allowance, the search
    goes on past the pilot along the geometric tail, tail(n) = g_L r^(n - L + 1) / (1 - r),
    up to n = limit (returned when even that is not enough), with the allowance and the delays
    of the full response (the pilot's and the tail past it).
    """
    n_orders = len(gains)
    zeros = np.zeros(n_orders)
    t1, t2 = (delays.t1, delays.t2) if delays is not None else (zeros, zeros)
    last = TailCut(cap, math.inf, math.inf, math.inf, allowed, True)
    can_go_on = limit is not None and limit >= n_orders and math.isfinite(ratio) and ratio < 1.0
    beyond: _Beyond | None = None

    def orders() -> Iterator[int]:
        """The pilot's orders, then (when the power of the orders past the pilot's last one is over the
        allowance) the orders past it that may meet it."""
        nonlocal beyond
        yield from range(n_orders)
        if not can_go_on or last.power <= allowed:  # the pilot's orders meet the power allowance: as they are
            return
        assert limit is not None
        beyond = _Beyond(gains, errors, t1, t2, ratio, allowed)
        yield from range(min(max(beyond.first, n_orders), limit), limit + 1)

    extended = False
    for n in orders():
        p, p1, p2 = tail_moments(n, gains, errors, t1, t2, ratio)
        extended = n >= n_orders
        allow = beyond.allowed if extended and beyond is not None else allowed
        d0 = d_rms = 0.0
        ok_delay = True
        if delays is not None:
            h0, tau0, tau_rms = delays.h0, delays.tau0, delays.tau_rms
            if extended and beyond is not None:  # the full response: the pilot's orders and the tail past them
                h0, tau0, tau_rms = _full_response(delays, beyond.full)
            d0, d_rms = delay_shift(h0, tau0, tau_rms, p, p1, p2)  # the pilot holds every order it reached
            ok_delay = d0 <= delays.rel * tau_rms and d_rms <= delays.rel * tau_rms
        last = TailCut(n, p, d0, d_rms, allow, ok_delay)
        if p <= allow and ok_delay:
            return last
    return dataclasses.replace(last, order=limit if extended and limit is not None else cap)


def order_window_end(gains: Gains, errors: Errors, t1: FloatArray, t2: FloatArray, n: int) -> float:
    """End of a window that holds reflection (scattering) orders up to n past the pilot [s].

    Order j > L (the pilot's last order measured to 30 %) arrives on average at t1[L] + (j - L) dt, dt
    = t1[L] - t1[L - 1] the pilot's per-order step, with a variance growing like the order's number
    of segments, var_L j / L; the end is order n's mean plus 4 of its standard deviations.
    """
    g, _, good = _measured(gains, errors)
    if not len(good) or good[-1] < 1:
        return 0.0
    L = int(good[-1])
    step = max(t1[L] - t1[L - 1], 0.0) if g[L - 1] > 0 else 0.0
    var = max(t2[L] - t1[L] ** 2, 0.0) * n / L
    return float(t1[L] + (n - L) * step + 4.0 * math.sqrt(var))


def window_end(edges: FloatArray, link: LinkPublic, allowed: float) -> float:
    """Time [s] after which less than `allowed` power [per watt] arrives, for one pilot link.

    The pilot measures the power arriving after each time well while it is a sizeable
    fraction of H0, but too few of its paths live long enough to measure the far tail.
    A room's late response decays exponentially (diffuse field), so the tail is
    extrapolated from a fit of log(power after t) over the well-measured range
    (3e-2 .. 1e-3 of H0), aiming at a third of `allowed`.
    """
    assert link.cir is not None and link.dc_gain is not None  # the pilot asks for the CIR of every link
    after = np.cumsum(np.asarray(link.cir.total)[::-1])[::-1] + (link.late_gain or 0.0)  # after each left edge
    h0 = link.dc_gain
    if h0 <= 0:
        return float(edges[0])
    direct = np.flatnonzero(after <= allowed)
    fit = np.flatnonzero((after <= 0.03 * h0) & (after >= 1e-3 * h0))
    if len(fit) >= 3:
        slope, icept = np.polyfit(edges[fit], np.log(after[fit]), 1)
        if slope < 0:  # aim at a third of the allowance: the decay slows down as the slowest mode takes over
            return float(max(edges[fit[-1]], (np.log(allowed / 3.0) - icept) / slope))
    return float(edges[direct[0]] if len(direct) else edges[-1])


@dataclass(frozen=True)
class OrderChoice:
    """The order chosen for K (or S) over the pilot's links, and why.

    `tail`: estimated power of the higher orders [per watt]; `within`: that tail is within its allowance;
    `note`: how the tail past the pilot's orders was estimated; `window_ends`: ends of windows that hold
    the orders chosen past the pilot [s] (one per link whose order goes past it).
    """

    order: int
    tail: float
    reason: str
    within: bool
    note: str
    window_ends: tuple[float, ...]


def _order_split(kind: OrderKind, link: LinkPublic) -> tuple[Gains, Errors]:
    """(H0 per order, its standard errors) of a pilot link (the pilot asks for the order split of every link)."""
    if kind is OrderKind.REFLECTION:
        gains, errors = link.dc_gain_by_reflection_order, link.dc_gain_by_reflection_order_stderr
    else:
        gains, errors = link.dc_gain_by_scattering_order, link.dc_gain_by_scattering_order_stderr
    assert gains is not None and errors is not None
    return gains, errors


def _link_delays(kind: OrderKind, link: LinkPublic, t_mid: FloatArray, rel: float) -> LinkDelays | None:
    """The delays of a pilot link for `tail_order` (None when it has no delay spread)."""
    if link.mean_delay_s is None or not link.rms_delay_spread_s:
        return None
    assert link.cir is not None and link.dc_gain is not None
    by_order = link.cir.by_reflection_order if kind is OrderKind.REFLECTION else link.cir.by_scattering_order
    t1, t2 = order_moments(by_order, t_mid)
    return LinkDelays(t1, t2, link.dc_gain, link.mean_delay_s, link.rms_delay_spread_s, rel)


def choose_order(
    kind: OrderKind,
    links: Sequence[LinkPublic],
    bound: float,
    cap: int,
    *,
    allowed: float,
    rel: float,
    t_mid: FloatArray,
    enclosed: bool,
    extra: int = 0,
) -> OrderChoice:
    """The largest order any pilot link needs (`tail_order` per link, at least `extra`), and why.

    `bound`: the a-priori per-order ratio (rho_max or albedo_max); `cap`: the pilot's highest order;
    `allowed`: the power allowance of this order's tail [per watt]; `rel`: the allowed delay shifts as
    a fraction of tau_rms; `t_mid`: the pilot's bin centres [s]; `enclosed`: surfaces close the scene.
    """
    best: tuple[int, float, float, float, str, float, bool] | None = None
    ends: list[float] = []
    for lk in links:
        gains, errors = _order_split(kind, lk)
        ratio, how = tail_ratio(gains, errors, bound)
        if kind is OrderKind.SCATTERING and bound >= 1.0 and not enclosed:
            ratio, how = (
                math.inf,
                (
                    "unbounded: {what} is 1 and no surface closes the medium: light diffuses "
                    "without loss and the orders decay algebraically, not geometrically"
                ),
            )
        delays = _link_delays(kind, lk, t_mid, rel)
        cut = tail_order(gains, errors, ratio, allowed, cap, delays, limit=MAX_ORDER)
        n = max(cut.order, extra)
        how = how.format(what=kind.bound_name)
        cand = (n, cut.power, cut.shift_tau0, cut.shift_rms, how, cut.allowed, cut.delays_within)
        if best is None or (cand[0], cand[1]) > (best[0], best[1]):
            best = cand
        if n > cap and delays is not None:  # past the pilot: the window must hold the orders up to n
            ends.append(order_window_end(gains, errors, delays.t1, delays.t2, n))
    assert best is not None  # the pilot has at least one link
    n, tail, d0, d_rms, how, allow, ok_delay = best
    reason = _order_reason(kind, TailCut(n, tail, d0, d_rms, allow, ok_delay), cap, rel, how)
    within = math.isfinite(tail) and tail <= allow
    return OrderChoice(n, tail, reason, within, f"{kind.bound_name}: {how}", tuple(ends))


def _order_reason(kind: OrderKind, cut: TailCut, cap: int, rel: float, how: str) -> str:
    """Why the order `cut.order` was chosen (the `modeled` section's max_reflections / max_scattering reason)."""
    n, tail, d0, d_rms, allow = cut.order, cut.power, cut.shift_tau0, cut.shift_rms, cut.allowed
    name = f"{kind.value} order"
    past = (
        f", past the pilot's {cap} orders along the geometric tail (Russian roulette ends the paths, so "
        "the cost per path stays near that of the orders that carry the power)"
        if n > cap
        else ""
    )
    highest = "the highest allowed" if n >= MAX_ORDER else "the pilot's highest"
    shifts = (
        f"dropping them shifts the mean delay by {d0:.2e} s and the RMS delay spread by {d_rms:.2e} s"
        if math.isfinite(d0) and math.isfinite(d_rms)
        else "that is at least the pilot's whole H0: the delay shifts cannot be stated"
    )
    if math.isfinite(tail) and tail <= allow and cut.delays_within:
        return (
            f"{name} capped at {n}{past}: estimated power of higher orders {tail:.2e} per watt <= "
            f"{allow:.2e} (half the allowed truncation); dropping them shifts the mean delay by "
            f"{d0:.2e} s and the RMS delay spread by {d_rms:.2e} s (each <= {rel:g} x tau_rms); "
            f"tail past the pilot's orders: {how}"
        )
    if math.isfinite(tail) and tail <= allow:
        return (
            f"{name} capped at {n}, {highest}{past}: estimated power of higher orders {tail:.2e} per watt "
            f"<= {allow:.2e} (half the allowed truncation), but {shifts}, more than "
            f"{rel:g} x tau_rms; tail past the pilot's orders: {how}"
        )
    if math.isfinite(tail):
        return (
            f"{name} capped at {n}, {highest}: the tail could not be brought under the "
            f"allowance (estimated {tail:.2e} per watt against {allow:.2e}; {shifts}); tail: {how}"
        )
    return (
        f"{name} capped at {n}, the pilot's highest: no finite bound on the power of higher orders "
        f"can be stated ({how}); set it explicitly and compare runs"
    )
