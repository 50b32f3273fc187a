"""Points along ray segments for the single-scattering estimators (algorithms 2-4).

A segment o + s w, a <= s <= b, is connected to a target y through points p(s).
The estimate of the integral  I = int_a^b g(s) ds  must be unbiased, so every
placement below is a partition of [a, b] into strata with one uniformly jittered
point per stratum, each point weighted by its stratum's length (stratified
sampling: E[sum_j g(s_j) |stratum_j|] = I exactly).

Time strata (the report's ellipse construction, section 7.3, made unbiased): the
total path length l(s) = l0 + s + |y - p(s)| grows monotonically with s, and its
level sets are ellipsoids with foci o and y. Cutting [a, b] where l(s) crosses a
multiple of h = c dt puts every point in its own time bin of width dt. The cut for
a path length L solves s + |v - s w| = D, D = L - l0, v = y - o:

    s = (D^2 - |v|^2) / (2 (D - v.w)).

Segments crossing more than `max_strata` bins get wider strata (still a partition).

Equiangular points (Kulla & Fajardo 2012) are drawn with pdf proportional to
1 / |y - p(s)|^2 along the segment, which cancels the 1/d^2 of the connection
near the device: s = D + h tan(theta_a + u (theta_b - theta_a)), D = (y - o).w,
h = |y - o - D w|, theta = atan((s - D) / h). The two placements are combined by
the balance heuristic on sample densities: a point from either set is weighted by
1 / (n_T(s) + n_E(s)), with n_T = 1 / |time stratum containing s| and
n_E = N_E pdf_E(s); the sum over both sets is an unbiased estimate of the integral.

The estimators of algorithms 2-4 built on them (the segment-points event of kernel.trace_batch) are
in single_scatter.py. Also here: the densities with which a device's run puts points on its first
segments (`first_segment_density`) and algorithm 5's balance heuristic of the free-flight collision
and the equiangular points (`scattering_point_throughput`).
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np

from owcsim.engine.core.arrays import FloatArray, IntArray
from owcsim.engine.core.sampling import column_norms
from owcsim.engine.integrator.path import BatchState, dot3
from owcsim.engine.sources.devices import Devices


def _cut(D: FloatArray, vv: FloatArray, vw: FloatArray) -> FloatArray:
    """s where s + |v - s w| = D (see module docstring); D - v.w > 0 for cuts inside a segment."""
    den = 2.0 * (D - vw)
    return (D * D - vv) / np.where(den > 0, den, 1.0)


def path_length(l0: Any, origins: FloatArray, directions: FloatArray, targets: FloatArray, s: Any) -> FloatArray:
    """l(s) = l0 + s + |target - (origin + s direction)| for (3, n) arrays [m]."""
    r = targets - (origins + s * directions)
    return l0 + s + np.sqrt(r[0] * r[0] + r[1] * r[1] + r[2] * r[2])


def _strata_plan(
    la: FloatArray, lb: FloatArray, h: float, max_strata: int
) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray]:
    """Per segment: (first cut index, cut spacing, cut origin, number of cuts) in path length."""
    first = np.floor(la / h) + 1.0
    n_cuts = np.maximum(np.ceil(lb / h) - first, 0.0)
    coarse = n_cuts > max_strata - 1
    step = np.where(coarse, (lb - la) / max_strata, h)
    first = np.where(coarse, 1.0, first)
    origin_l = np.where(coarse, la, 0.0)
    n_cuts = np.where(coarse, max_strata - 1, n_cuts)
    return first, step, origin_l, n_cuts


def time_density(
    l0: FloatArray,
    origins: FloatArray,
    directions: FloatArray,
    targets: FloatArray,
    a: Any,
    b: FloatArray,
    s: FloatArray,
    h: float,
    max_strata: int = 64,
) -> FloatArray:
    """n_T(s) = 1 / length of the time stratum of `time_strata` containing s (one point per segment)."""
    la = path_length(l0, origins, directions, targets, a)
    lb = path_length(l0, origins, directions, targets, b)
    first, step, origin_l, n_cuts = _strata_plan(la, lb, h, max_strata)
    l = path_length(l0, origins, directions, targets, s)
    j = np.clip(np.floor((l - origin_l) / step) - first + 1, 0, n_cuts)  # stratum index 0..n_cuts
    v = targets - origins
    vv = v[0] * v[0] + v[1] * v[1] + v[2] * v[2]
    vw = v[0] * directions[0] + v[1] * directions[1] + v[2] * directions[2]
    lo = np.where(j == 0, a, _cut(origin_l + (first + j - 1) * step - l0, vv, vw))
    hi = np.where(j == n_cuts, b, _cut(origin_l + (first + j) * step - l0, vv, vw))
    length = np.clip(hi, a, b) - np.clip(lo, a, b)
    return np.where(length > 0, 1.0 / np.where(length > 0, length, 1.0), 0.0)


class EquiangularFrame:
    """The equiangular geometry of segments o + s w, a <= s <= b, toward a target y, computed once.

    D = (y - o).w, h = |y - o - D w| (kept >= 1e-9 (1 + |D|): a target on the ray's line keeps a
    finite pdf), c = D - a, r2 = h^2 + c^2 (the squared distance from the start o + a w to y),
    theta_a, theta_b = atan((a - D) / h), atan((b - D) / h). `targets` may be (3, 1) (one target for
    every segment); `a` may be a number. Sampling and densities reuse the frame.

    One arctangent per segment, none per point (issue 13): with tan theta_a = -c / h and L = b - a,
        span = theta_b - theta_a = atan2(L h, r2 - c L)   (tan of a difference; span in [0, pi)),
    and for theta = theta_a + phi (tan of a sum, t = tan phi)
        s - a = h (tan theta - tan theta_a) = r2 t / (h + c t),
    exact, and free of the cancellation of D + h tan(theta) near s = a (tests/engine/test_segments.py).
    """

    __slots__ = ("a", "D", "c", "h", "h2", "r2", "span", "scale")

    def __init__(self, origins: FloatArray, directions: FloatArray, targets: FloatArray, a: Any, b: FloatArray):
        v = targets - origins
        D = v[0] * directions[0] + v[1] * directions[1] + v[2] * directions[2]
        r = v - D * directions
        h = column_norms(r)
        np.maximum(h, 1e-9 * (1.0 + np.abs(D)), out=h)
        zero_a = np.ndim(a) == 0 and a == 0.0
        c, length = (D, b) if zero_a else (D - a, b - a)
        h2 = h * h
        r2 = c * c
        r2 += h2
        span = np.arctan2(length * h, r2 - c * length)
        self.a, self.D, self.c, self.h, self.h2, self.r2, self.span = 0.0 if zero_a else a, D, c, h, h2, r2, span
        #: h / span (0 where the segment is empty): n_E(s) = n_per scale / (h^2 + (s - D)^2)
        self.scale = (
            np.divide(h, span)
            if span.min(initial=1.0) > 0
            else np.divide(h, span, out=np.zeros_like(span), where=span > 0)
        )

    @staticmethod
    def _at(x: Any, seg: IntArray | None) -> Any:
        return x if seg is None or np.ndim(x) == 0 else x.take(seg)

    def sample(self, seg: IntArray | None, xi: FloatArray) -> FloatArray:
        """s of the points with stratified uniforms `xi` on the segments `seg` (not clipped to [a, b]).

        `seg` None: every segment, `xi` of shape (n,) or (k, n) (k points per segment, broadcast)."""
        at = self._at
        t = np.tan(xi * at(self.span, seg))
        num = t * at(self.r2, seg)
        t *= at(self.c, seg)
        t += at(self.h, seg)
        num /= t
        a = at(self.a, seg)
        if np.ndim(a) or a != 0.0:
            num += a
        return num

    def density(self, s: FloatArray, n_per: int, seg: IntArray | None = None) -> FloatArray:
        """n_E(s) = n_per h / ((theta_b - theta_a) (h^2 + (s - D)^2)) on the segments `seg` (all if None;
        `s` may then be (k, n): k points per segment)."""
        at = self._at
        x = s - at(self.D, seg)
        x *= x
        x += at(self.h2, seg)
        return np.divide(n_per * at(self.scale, seg), x, out=x)


def equiangular(
    origins: FloatArray,
    directions: FloatArray,
    targets: FloatArray,
    a: FloatArray,
    b: FloatArray,
    n_per: int,
    u: Callable[[int], FloatArray],
    frame: EquiangularFrame | None = None,
) -> tuple[IntArray, FloatArray]:
    """`n_per` stratified equiangular points per segment [a, b] with respect to its target.

    Returns (segment index (m,), s (m,)); `u(m)` gives the uniforms. `frame` reuses a computed
    EquiangularFrame of these segments.
    """
    ok = np.flatnonzero(b > a)
    seg = np.repeat(ok, n_per)
    if len(seg) == 0:
        return seg, np.zeros(0)
    frame = frame or EquiangularFrame(origins, directions, targets, a, b)
    xi = (np.tile(np.arange(n_per), len(ok)) + u(len(seg))) / n_per
    s = frame.sample(seg, xi)
    return seg, np.clip(s, a.take(seg), b.take(seg))


def equiangular_density(
    origins: FloatArray, directions: FloatArray, targets: FloatArray, a: Any, b: FloatArray, s: FloatArray, n_per: int
) -> FloatArray:
    """n_E(s) = n_per * pdf_E(s) (one point per segment, arrays as `equiangular`)."""
    if n_per == 0:
        return np.zeros(len(s))
    return EquiangularFrame(origins, directions, targets, a, b).density(s, n_per)


def time_strata(
    l0: FloatArray,
    origins: FloatArray,
    directions: FloatArray,
    targets: FloatArray,
    a: FloatArray,
    b: FloatArray,
    h: float,
    u: Callable[[int], FloatArray],
    max_strata: int = 64,
) -> tuple[IntArray, FloatArray, FloatArray]:
    """Stratify segments [a, b] in total path length (time bins of length h = c dt [m]).

    Arrays: l0, a, b (n,) [m]; origins, directions, targets (3, n). `u` is a
    callable u(m) -> m uniforms (the jitter). Returns (segment index (m,), s (m,),
    stratum length (m,)) for every point, segments with b <= a giving none.
    """
    n = len(a)
    la = path_length(l0, origins, directions, targets, a)
    lb = path_length(l0, origins, directions, targets, b)
    ok = b > a
    # Cuts at multiples of h strictly inside (la, lb); a segment crossing more than
    # max_strata bins is cut evenly in path length instead (a coarser partition).
    first, step, origin_l, n_cuts = _strata_plan(la, lb, h, max_strata)
    counts = np.where(ok, n_cuts.astype(np.int64) + 1, 0)
    m = int(counts.sum())
    seg = np.repeat(np.arange(n), counts)
    start = np.cumsum(counts) - counts
    j = np.arange(m) - start.take(seg)  # stratum index within its segment
    cnt = counts.take(seg)
    v = targets.take(seg, axis=1) - origins.take(seg, axis=1)
    w = directions.take(seg, axis=1)
    vv = v[0] * v[0] + v[1] * v[1] + v[2] * v[2]
    vw = v[0] * w[0] + v[1] * w[1] + v[2] * w[2]
    l0s, st, f, ol = l0.take(seg), step.take(seg), first.take(seg), origin_l.take(seg)
    s_lo = np.where(j == 0, a.take(seg), _cut(ol + (f + j - 1) * st - l0s, vv, vw))
    s_hi = np.where(j == cnt - 1, b.take(seg), _cut(ol + (f + j) * st - l0s, vv, vw))
    s_lo = np.clip(s_lo, a.take(seg), b.take(seg))
    s_hi = np.clip(s_hi, s_lo, b.take(seg))
    length = s_hi - s_lo
    return seg, s_lo + u(m) * length, length


def first_segment_density(ctx: BatchState, devices: Devices, d: int, other: Any, points: FloatArray) -> FloatArray:
    """q_X(p) = R_X(cos) / W_X / r^2 (n_T + n_E)(p) [1/m^3]: the density of points at `points` (3, n) placed
    on device d's first segments (cast from it through them; time strata and equiangular points toward
    the device at `other` (3,)), per path of that device (`_direction_mis`)."""
    scene, settings = ctx.scene, ctx.settings
    isect = scene.intersector
    n = points.shape[1]
    o = devices.positions[d] + isect.offset * devices.normals[d]
    to_p = points - o[:, None]
    r = np.sqrt(dot3(to_p, to_p))
    w_dir = to_p / r
    q = devices.response(np.full(n, d), dot3(w_dir, devices.normals[d][:, None]), w_dir.T) / devices.total_response(d)
    live = np.flatnonzero(q > 0)
    if len(live):
        origins = np.repeat(o[:, None], len(live), axis=1)
        dirs = w_dir.take(live, axis=1)
        _, t_hit = isect.intersect(origins.T, dirs.T)
        t_hit = np.where(np.isfinite(t_hit), t_hit, scene.medium_far_distance)
        tgt = np.repeat(np.asarray(other, float)[:, None], len(live), axis=1)
        zeros, rl = np.zeros(len(live)), r.take(live)
        dens = time_density(
            zeros, origins, dirs, tgt, zeros, t_hit, rl, settings.strata_length, settings.max_strata
        ) + equiangular_density(origins, dirs, tgt, zeros, t_hit, rl, settings.equiangular_points)
        q[live] = q.take(live) / (rl * rl) * dens
    return q


def scattering_point_throughput(
    weights: FloatArray, transmittance: FloatArray, sigma_t: Any, sigma_s: Any, n_e: Any
) -> FloatArray:
    """Algorithm 5's balance heuristic (Veach 1997, ch. 9) in one place: the throughput of a scattering point.

    Two techniques place scattering points at distance s on a segment o + s w: the free-flight
    collision, density p_ff(s) = sigma_t(s) T(o -> s), and `equiangular_points` equiangular points per
    target, density n_E(s) (segments.EquiangularFrame.density). Every point of either set makes a
    next-event estimate with MIS weight p / (p_ff + n_E) over its own density p, i.e. throughput
        w T(o -> s) sigma_s(s) / (p_ff(s) + n_E(s)),
    the same formula for both (for the collision it is w x albedo x p_ff / (p_ff + n_E)); without
    equiangular points (n_E = 0) it is the collision's w x albedo.
    """
    total = sigma_t * transmittance  # p_ff
    total += n_e
    num = weights * transmittance
    num *= sigma_s
    # total = 0 only where T = 0 or sigma_t = 0 (then sigma_s = 0): num is 0 there and stays
    # (a division masked by `where` is ~2.5x slower than a plain one: only when needed)
    return (
        np.divide(num, total, out=num)
        if total.min(initial=1.0) > 0
        else np.divide(num, total, out=num, where=total > 0)
    )
