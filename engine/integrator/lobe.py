"""The phase lobe: the source also samples the peak of a tall phase function (physics.md section 4, heavy tails).

With KernelSettings.phase_lobe (`lobe_connections`), for a phase function with a tall peak
(HG g -> +-1) the single-scattering integrand of Tx -> p -> Rx concentrates on the Tx-Rx line, where the
scattering angle theta ~ rho (1/r_1 + 1/r_n) lies inside the lobe of width ~ (1 - |g|): neither device's
emission samples that thin needle, so a run either misses it (most runs, biased low with a small error
bar) or hits it with a huge weight (the bound of weights.py grows with p_max ~ 1/(1 - g)^2). Each device then
also samples the lobe: a direction with density p(cos alpha) about the axis toward the other device
(`phase.sample`), a free-flight collision along it. In the triangle Tx, p, Rx the scattering angle is
the sum of the angles at the two devices, theta = alpha + beta, so for a phase function decreasing in
theta p(theta) <= min(p(alpha), p(beta)). The n = 1 family is then shared among four strategies by the
balance heuristic on their densities (per volume, sigma_t(p) common to all and left out):

    F = R_src / W_src T_src / r_src^2,   L = R_tgt / W_tgt T_tgt / r_tgt^2   (the emissions, as above),
    Lambda = p(cos alpha) T_src / r_src^2 + p(cos beta) T_tgt / r_tgt^2     (the two lobes),

the emission runs weighting by F / (F + L + Lambda) (L / (...) from the other side) and the lobe samples
by their own term over the same sum. Every strategy's estimate is then f / (sigma_t (F + L + Lambda)) and

    contribution <= albedo R_src R_tgt p(theta) T / (r_src^2 r_tgt^2 Lambda)
                 <= albedo R_src,max R_tgt,max min(1 / r_src^2, 1 / r_tgt^2),

at most 4 albedo R_tx,max R_rx,max / D^2 whatever g (for g < 0 the lobe about the axis points away from
the other device, onto the axis beyond the source, where the backward peak lies). The lobe is drawn when
the phase function's peak exceeds LOBE_PEAK times the isotropic 1 / (4 pi) (`phase_lobe_wanted`), in
runs of algorithm 5 (from both devices, or from one: `lobe_connections`) and of algorithms 2-4 from both
devices, in grey scenes; at lower peaks the weights above are already
bounded by a moderate p_max and nothing changes. Algorithms 2-4 place points on the emissions' first
segments (time strata and equiangular points, density n_T + n_E per length) rather than collisions:
their shares (single_scatter._direction_mis) weigh R / W / r^2 (n_T + n_E) of each device against
sigma_t Lambda, the lobes' densities per volume (`lobe_volume_density`), and the bound is the same.
The emissions' share of the same family is weights.connection_weight (with `lobe`), and algorithms 2-4
weigh their segment points against the lobes by `lobe_volume_density` (single_scatter._direction_mis).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from owcsim.engine.core.arrays import FloatArray, IntArray
from owcsim.engine.core.constants import SPEED_OF_LIGHT
from owcsim.engine.integrator.path import BatchState, device_sets, dot3
from owcsim.engine.integrator.segments import first_segment_density
from owcsim.engine.sources.devices import Devices

#: The phase lobe is sampled (KernelSettings.phase_lobe) when the phase function's peak exceeds this multiple of
#: the isotropic 1 / (4 pi): HG |g| >= 0.81 (4 pi p(1) = (1 + g) / (1 - g)^2: 45 at g = 0.8, 56 at 0.82, 190
#: at 0.9). Below it the emissions' weights, bounded with p_max, gave honest error bars (g = 0.7 and 0.9:
#: docs/smoke-error-bars.md) and such scenes keep their bits.
LOBE_PEAK = 50.0


def phase_lobe_wanted(phase: Any) -> bool:
    """True when the phase function's forward or backward peak exceeds LOBE_PEAK / (4 pi) [1/sr]."""
    peak = float(np.max(phase.eval(np.array([1.0, -1.0]))))
    return 4.0 * np.pi * peak > LOBE_PEAK


def lobe_axis(ctx: BatchState, j: int) -> tuple[FloatArray, FloatArray] | None:
    """(source position, unit axis toward the item's j-th target), or None where the two coincide."""
    src, _ = device_sets(ctx.scene, ctx.item.direction)
    x = src.positions[ctx.item.source]
    axis = ctx.t_pos[:, j] - x
    length = float(np.sqrt(axis @ axis))
    return None if length == 0.0 else (x, axis / length)


def lobe_source_density(ctx: BatchState, j: int, points: FloatArray, transmittance: Any) -> FloatArray:
    """The source's lobe density p(cos alpha) T(source -> p) / r^2 at medium points (3, n) [1/(sr m^2)] for
    the item's j-th target (alpha between p - source and the axis toward the target); 0 without an axis."""
    frame = lobe_axis(ctx, j)
    if frame is None:
        return np.zeros(points.shape[1])
    x, axis = frame
    v = points - x[:, None]
    r2 = dot3(v, v)
    cos = dot3(v, axis[:, None]) / np.sqrt(r2)
    return ctx.phase.eval(cos) * transmittance / r2


def lobe_volume_density(ctx: BatchState, y: Any, points: FloatArray) -> FloatArray:
    """sigma_t(p) Lambda(p) [1/m^3]: the two lobe strategies' densities per volume at medium points (3, n)
    between the item's source and the target at `y` (3,) (algorithms 2-4, whose point densities
    segments.first_segment_density are per volume); 0 where the devices coincide."""
    scene = ctx.scene
    medium, phase = ctx.medium, ctx.phase
    src, _ = device_sets(scene, ctx.item.direction)
    x = src.positions[ctx.item.source]
    axis = np.asarray(y, float) - x
    length = float(np.sqrt(axis @ axis))
    if length == 0.0:
        return np.zeros(points.shape[1])
    axis = axis / length
    uniform = medium.uniform_coefficients  # (sigma_t, sigma_s) of a medium the same everywhere, else None
    out = np.zeros(points.shape[1])
    for pos, a in ((x, axis), (np.asarray(y, float), -axis)):  # the source's lobe, then the target's
        v = points - pos[:, None]
        r2 = dot3(v, v)
        r = np.sqrt(r2)
        if uniform is not None:
            tr = np.exp(-uniform[0] * r)  # = medium.transmittance
        else:
            tr = medium.transmittance(np.broadcast_to(pos, (len(r), 3)), (v / r).T, r)
        cos = v[0] * a[0] + v[1] * a[1] + v[2] * a[2]
        cos /= r
        tr *= phase.eval(cos)
        tr /= r2
        out += tr
    return out * (uniform[0] if uniform is not None else medium.sigma_t_at(points.T))


@dataclass(frozen=True)
class _LobeHits:
    """The lobe samples of one target that scatter and see it: collisions `points` (3, m) at t_col along
    `dirs` from `origins` (3, m), the path index `live`, the source's response `r_src` toward them, the
    unit directions `out` toward the target at distance d (d2 = d^2) [m], sigma_t [1/m] and the albedo there."""

    live: IntArray
    dirs: FloatArray
    r_src: FloatArray
    t_col: FloatArray
    points: FloatArray
    out: FloatArray
    d2: FloatArray
    d: FloatArray
    sigma_t: FloatArray
    albedo: FloatArray
    origins: FloatArray


def _lobe_hits(
    ctx: BatchState, src: Devices, i: int, j: int, x: FloatArray, axis: FloatArray, u: FloatArray
) -> _LobeHits | None:
    """Directions with density p(w . axis) from the source x, their free-flight collisions and the
    targets' visibility (`lobe_connections`); None when no sample scatters toward target j."""
    scene = ctx.scene
    medium, isect, phase = ctx.medium, scene.intersector, ctx.phase
    n = u.shape[1]
    n_src = src.normals[i]
    dirs = phase.sample(np.repeat(axis[:, None], n, axis=1), u[0], u[1])
    r_src = src.response_one(i, dot3(dirs, n_src[:, None]), dirs.T if src.directional else None)
    live = (r_src > 0).nonzero()[0]
    if len(live) == 0:
        return None
    dirs, r_src = dirs.take(live, axis=1), r_src.take(live)
    origins = np.repeat((x + isect.offset * n_src)[:, None], len(live), axis=1)
    prim, t_hit = isect.intersect(origins.T, dirs.T)
    seg = np.where(prim >= 0, t_hit, scene.medium_far_distance)
    t_col, collided = medium.sample_distance(origins.T, dirs.T, seg, u[2].take(live))
    sel = collided.nonzero()[0]
    if len(sel) == 0:
        return None
    live, dirs, r_src, t_col = live.take(sel), dirs.take(sel, axis=1), r_src.take(sel), t_col.take(sel)
    origins = origins[:, : len(sel)]
    points = origins + t_col * dirs
    sigma_t, sigma_s = medium.coefficients_at(points.T)
    y = ctx.t_pos[:, j : j + 1]
    out = y - points
    d2 = dot3(out, out)
    d = np.sqrt(d2)
    out /= d
    keep = (sigma_s > 0).nonzero()[0]
    if not scene.all_visible and len(keep):
        o_k, w_k = points.take(keep, axis=1), out.take(keep, axis=1)
        keep = keep[~isect.occluded(o_k.T, w_k.T, d.take(keep) - 2.0 * isect.offset)]
    if len(keep) == 0:
        return None
    return _LobeHits(
        live=live.take(keep),
        dirs=dirs.take(keep, axis=1),
        r_src=r_src.take(keep),
        t_col=t_col.take(keep),
        points=points.take(keep, axis=1),
        out=out.take(keep, axis=1),
        d2=d2.take(keep),
        d=d.take(keep),
        sigma_t=sigma_t.take(keep),
        albedo=sigma_s.take(keep) / sigma_t.take(keep),
        origins=origins[:, : len(keep)],
    )


def lobe_connections(ctx: BatchState, n: int, rng: np.random.Generator, segments: bool = False) -> None:
    """The source's phase-lobe strategy for Tx -> p -> Rx (algorithm 5 from both devices; module docstring).

    Per target j and path of the batch: a direction w with density p(w . a) about the unit axis a toward
    the target (`phase.sample`), a free-flight collision p at distance t along it (density sigma_t T), and
    the connection to the target:
        dH = albedo R_src(w) / p(w . a) x p(cos theta) R_tgt T(p -> y) / d^2 x Lambda_src / (F + L + Lambda),
    (Lambda_src = p(cos alpha) T(source -> p) / r^2, the same share as `weights.connection_weight` gives the
    emissions), tallied at (k, s) = (0, 1) with the batch's path of the same index. `segments`
    (algorithms 2-4): the emissions place points on their first segments instead of collisions, so the
    share is sigma_t Lambda_src over the sum of both devices' point densities
    (segments.first_segment_density) and sigma_t Lambda (as single_scatter._direction_mis weighs them).
    Algorithm 5 from one side (no partner run): the source's two strategies share the path,
    Lambda_src / (F + Lambda_src), and its emission F / (F + Lambda_src) (events.medium_next_events); the
    weight then keeps the one-sided 1 / d^2 near the target but no longer grows with the peak.
    """
    scene = ctx.scene
    medium, phase = ctx.medium, ctx.phase
    src, _ = device_sets(scene, ctx.item.direction)
    i = ctx.item.source
    w_src = src.total_response(i)
    for j in range(len(ctx.tgt)):  # a loop over devices
        frame = lobe_axis(ctx, j)
        u = rng.random((3, n))
        if frame is None:
            continue
        x, axis = frame
        hits = _lobe_hits(ctx, src, i, j, x, axis, u)
        if hits is None:
            continue
        live, dirs, r_src, t_col, points, out, d2, d = (
            hits.live,
            hits.dirs,
            hits.r_src,
            hits.t_col,
            hits.points,
            hits.out,
            hits.d2,
            hits.d,
        )
        t_idx = int(ctx.tgt[j])
        r_tgt = ctx.targets.response_one(
            t_idx, dot3(out, ctx.t_nrm_neg[:, j : j + 1]), -out.T if ctx.t_directional else None
        )
        t_src = medium.transmittance(hits.origins.T, dirs.T, t_col)
        t_tgt = medium.transmittance(points.T, out.T, d)
        lam_src = lobe_source_density(ctx, j, points, t_src)
        v = points - x[:, None]
        r2_src = dot3(v, v)
        lam_tgt = phase.eval(dot3(out, axis[:, None])) * t_tgt / d2  # the target's lobe: cos beta = out . a
        if not (segments or ctx.settings.both_sides):  # algorithm 5 from one side: F / (F + Lambda_src) and back
            total = r_src / w_src * t_src / r2_src
        elif segments:  # algorithms 2-4: densities per volume (single_scatter._direction_mis)
            sig = hits.sigma_t
            lam_src, lam_tgt = sig * lam_src, sig * lam_tgt
            total = first_segment_density(ctx, src, i, ctx.t_pos[:, j], points)
            total += first_segment_density(ctx, ctx.targets, t_idx, x, points)
        else:
            total = r_src / w_src * t_src / r2_src  # F (the source's emission, as first_medium_factor)
            total += r_tgt / ctx.t_total[j] * t_tgt / d2  # L
        total += lam_src
        if segments or ctx.settings.both_sides:
            total += lam_tgt
        sampled = phase.eval(dot3(dirs, axis[:, None]))  # p(w . a), this strategy's direction density
        power = hits.albedo * r_src / sampled * phase.eval(dot3(dirs, out)) * r_tgt * t_tgt / d2
        power *= np.where(total > 0, lam_src / np.where(total > 0, total, 1.0), 0.0)
        ok = (power > 0).nonzero()[0]
        if len(ok) == 0:
            continue
        ctx.record(
            np.full(len(ok), j, np.int64),
            np.zeros(len(ok), np.int64),
            np.ones(len(ok), np.int64),
            (t_col.take(ok) + d.take(ok)) / SPEED_OF_LIGHT,
            power.take(ok),
            live.take(ok),
        )
