"""Single scattering at points on segments (algorithms 2-4): the segment-points event of kernel.trace_batch.

Per target, one point per time stratum plus equiangular points on each segment (segments.py), combined
by the balance heuristic, connect to the target as a scattering event (`segment_scatter`,
`segment_points`; the measurement equation is context.BatchContext.connect).

The branch from the first segment (`first_segment_branch`). The points-on-segments estimators connect a point p of
the source's k-th segment to the target; the target's own side samples the same single-
scattering family by a collision p on its first segment, a phase-sampled branch with k
reflections and next-event estimates at the branch's surface vertices. Run from both
devices (`KernelSettings.mis`), the two share each path by the same partition (k = 0,
where both sides place points on their first segment, keeps the exact balance heuristic of
`_direction_mis`). Algorithm 2 (3) alone is then the backward (forward) points plus
the forward (backward) branch; algorithm 4 runs all of them.

Algorithm 4's double-scattering family (`first_segment_branch(double=True)`, the report's section 9): light
in-scattered from the source at p_in on the source's first ray is carried along a ray
from p_in (its phase-sampled direction, then k <= K reflections) and out-scattered toward
the target at points p_out along every later segment. Both runs sample the family
Tx -> p_in -> (k reflections) -> p_out -> Rx (each from its own side), weighted by
the same partition A / (A + B) with x_1 = p_in, x_n = p_out. Surface vertices of that
branch make no connections: Tx -> p_in -> (k) -> Rx is the s = 1 family of algorithm 2,
estimated elsewhere, so nothing is counted twice.
"""

from __future__ import annotations

from typing import Any, Protocol

import numpy as np

from owcsim.engine.core.arrays import FloatArray, IntArray
from owcsim.engine.integrator.context import BatchContext, Vertices
from owcsim.engine.integrator.lobe import lobe_volume_density
from owcsim.engine.integrator.mirrors import branch_surface, connect_segment_mirrors, specular_first_share
from owcsim.engine.integrator.path import Paths, device_sets, dot3
from owcsim.engine.integrator.segments import (
    EquiangularFrame,
    equiangular,
    first_segment_density,
    time_density,
    time_strata,
)
from owcsim.engine.integrator.weights import first_vertex_factor, side_weight, source_factor, target_factor
from owcsim.schemas.algorithms import Direction


class PointWeight(Protocol):
    """weight_fn(j, pp, points, s, density): a factor per segment point (e.g. a partition of unity)."""

    def __call__(self, j: int, pp: Paths, points: FloatArray, s: FloatArray, density: FloatArray, /) -> Any: ...


# --- the estimators of algorithms 2-4 (the segment-points event of kernel.trace_batch) -----------------
def segment_scatter(
    ctx: BatchContext,
    paths: Paths,
    t_seg: FloatArray,
    rng: np.random.Generator,
    first: bool,
    prim: IntArray | None = None,
) -> None:
    """Single scattering at points of each segment, connected to the targets (algorithms 2-4).

    Per target (the strata are ellipsoids with the target as a focus): one point per
    time stratum plus `equiangular_points` equiangular points (above), combined
    by the balance heuristic: a point at s has weight
        w * T(o -> p) * sigma_s(p) / (n_T(s) + n_E(s)),
    and the connection adds phase, response, 1/d^2, visibility and T(p -> target).
    Points on every segment estimate the family source -> (k) -> p -> target (forward:
    algorithm 3's, backward: algorithm 2's). Run from both devices (`settings.mis`), the
    family both sample on the first segment (k = 0: Tx -> p -> Rx) gets the direction
    balance heuristic (`_direction_mis`); for k >= 1 the other device samples the same
    family by scattering on its own first segment (`first_segment_branch`), and
    the two share each path by the partition of unity of weights.side_weight
    (bounded weights near the devices). Algorithm 4 also starts the double-scattering
    family on the first segment (the same branch).
    """
    settings = ctx.settings
    forward = ctx.item.direction is Direction.FORWARD
    points_everywhere = settings.own_family(forward)  # this side's own family: points on all segments
    if first and settings.mis:
        assert prim is not None  # the first step passes its hits
        paths.first = first_vertex_factor(ctx, paths, prim, t_seg, np.zeros(len(t_seg)), np.zeros(len(t_seg), bool))
        chain = settings.other_family(forward)  # the other side's family, sampled from this side
        if chain or settings.in_then_out:
            first_segment_branch(ctx, paths, t_seg, rng, chain=chain, double=settings.in_then_out)
    if not (points_everywhere or (first and settings.mis)):
        return
    alive = np.flatnonzero((paths.s == 0) & (paths.k <= settings.max_reflections) & np.isfinite(t_seg))
    if len(alive) == 0:
        return
    partition: PointWeight | None = None
    if settings.mis and not first:

        def partition(j: int, pp: Paths, points: FloatArray, s: FloatArray, density: FloatArray) -> Any:
            # after a specular first vertex: mirrors.py
            assert pp.first is not None  # runs from both devices carry the source factor
            return specular_first_share(
                ctx, j, pp, points, s, density, side_weight(pp.first, target_factor(ctx, j, points))
            )

    segment_points(
        ctx,
        paths.keep(alive),
        t_seg.take(alive),
        rng,
        order=1,
        direction_mis=settings.mis and first,
        weight_fn=partition,
    )


def segment_points(
    ctx: BatchContext,
    seg_paths: Paths,
    t_seg: FloatArray,
    rng: np.random.Generator,
    order: int,
    direction_mis: bool = False,
    weight_fn: PointWeight | None = None,
) -> None:
    """Points on the segments [0, t_seg) of `seg_paths` (time strata + equiangular, balance heuristic),
    each connected to every target as a scattering event of order `order`.

    `weight_fn(j, pp, points, s, density)`, if given, multiplies each point's weight (e.g. a partition of unity).
    """
    settings, medium = ctx.settings, ctx.medium
    zeros = np.zeros(len(seg_paths))
    h, n_eq = settings.strata_length, settings.equiangular_points
    for j in range(len(ctx.tgt)):  # strata depend on the target: a loop over devices, not rays
        y = np.repeat(ctx.t_pos[:, j : j + 1], len(seg_paths), axis=1)
        o, d, l0 = seg_paths.origins, seg_paths.directions, seg_paths.lengths
        seg_t, s_t, _ = time_strata(l0, o, d, y, zeros, t_seg, h, lambda m: rng.random(m), settings.max_strata)
        frame = EquiangularFrame(o, d, y, zeros, t_seg)  # once per segment and target
        seg_e, s_e = equiangular(o, d, y, zeros, t_seg, n_eq, lambda m: rng.random(m), frame=frame)
        found = _scattering_points(seg_paths, np.concatenate([seg_t, seg_e]), np.concatenate([s_t, s_e]), medium)
        if found is None:
            continue
        seg, pp, points, s, sigma_s = found
        y_p, end = y.take(seg, axis=1), t_seg.take(seg)
        density = time_density(
            pp.lengths, pp.origins, pp.directions, y_p, np.zeros(len(s)), end, s, h, settings.max_strata
        ) + (frame.density(s, n_eq, seg) if n_eq else 0.0)
        # throughput of a point: w T(o -> p) sigma_s(p) / (n_T + n_E), the balance heuristic of the time
        # strata and the equiangular points in Veach's multi-sample form (segments.py)
        tau = medium.optical_depth(pp.origins.T, pp.directions.T, s)
        throughput = pp.weights * np.exp(-tau) * sigma_s / density  # exp(-tau) = medium.transmittance
        if ctx.ratios is not None:  # bands or frames: sigma_s,b T_b over the carrier's (spectra.py)
            pp.ratio = ctx.ratios.scatter(pp.ratio, tau, (pp.origins.T, pp.directions.T, s))
        if direction_mis and ctx.mirrors:  # source -> p -> mirror -> target, through the image (mirrors.py)
            connect_segment_mirrors(ctx, j, points, throughput, pp, s, order, density)
        mis = _direction_mis(ctx, int(ctx.tgt[j]), pp, points, s, density) if direction_mis else None
        if weight_fn is not None:
            share = weight_fn(j, pp, points, s, density)
            mis = share if mis is None else mis * share
        order_s = np.full(len(pp), order, np.int64)
        v = Vertices.in_medium(points, throughput, pp, pp.directions, mis=mis, scatter_order=order_s, extra_length=s)
        ctx.connect(v, target=j)


def _scattering_points(paths: Paths, seg: IntArray, s: FloatArray, medium: Any) -> tuple[Any, ...] | None:
    """Points at distance s along the segments `seg` of `paths`, keeping those where sigma_s > 0.

    Returns (seg, their paths, points (3, m), s, sigma_s), or None when no point scatters.
    """
    if len(seg) == 0:
        return None
    pp = paths.keep(seg)
    points = pp.origins + s * pp.directions
    sigma_s = medium.sigma_s_at(points.T)
    inside = np.flatnonzero(sigma_s > 0)
    if len(inside) == 0:
        return None
    return (seg.take(inside), pp.keep(inside), points.take(inside, axis=1), s.take(inside), sigma_s.take(inside))


def _direction_mis(
    ctx: BatchContext, j: int, pp: Paths, points: FloatArray, s: FloatArray, density: FloatArray
) -> FloatArray:
    """Balance heuristic for Tx -> p -> Rx, sampled from both devices (algorithm 4).

    Per-path density of p in volume measure for the side that starts at device X:
        q_X(p) = R_X(cos_X) / W_X / r_X^2 * (n_T + n_E)_X(p),
    direction pdf times the point density along X's first segment. This run is one
    side (its density is given); the other side's first segment is cast from the
    other device through p. Both sides run the same number of paths (the plan
    guarantees it), so the weight is q_self / (q_self + q_other). `j`: the target's index in
    its device set. With KernelSettings.phase_lobe the two phase-lobe strategies join the
    denominator (lobe.lobe_volume_density).
    """
    scene = ctx.scene
    src_set, dst_set = device_sets(scene, ctx.item.direction)
    i, n = ctx.item.source, len(s)
    cos_src = dot3(pp.directions, src_set.normals[i][:, None])
    q_self = src_set.response(np.full(n, i), cos_src, pp.directions.T) / src_set.total_response(i) / (s * s) * density
    q_other = first_segment_density(ctx, dst_set, j, src_set.positions[i], points)
    total = q_self + q_other
    if ctx.settings.phase_lobe:  # the two phase-lobe strategies of lobe.lobe_connections
        total = total + lobe_volume_density(ctx, dst_set.positions[j], points)
    return np.where(total > 0, q_self / np.where(total > 0, total, 1.0), 1.0)


def _scatter_on_first_segment(
    ctx: BatchContext, paths: Paths, t_seg: FloatArray, rng: np.random.Generator
) -> Paths | None:
    """Branches from a free-flight collision p on the source's first segment (weight x albedo), leaving p
    in a phase-sampled direction, with `first` = the source factor at p and s = 1; None if none collide."""
    medium = ctx.medium
    ok = (np.isfinite(t_seg) & (paths.k + paths.s == 0)).nonzero()[0]
    if len(ok) == 0:
        return None
    base = paths.keep(ok)
    t_in, col = medium.sample_distance(base.origins.T, base.directions.T, t_seg.take(ok), rng.random(len(ok)))
    sel = col.nonzero()[0]
    if len(sel) == 0:
        return None
    br = base.keep(sel)
    t_in = t_in.take(sel)
    p_in = br.origins + t_in * br.directions
    br.weights = br.weights * medium.albedo_at(p_in.T)
    br.first = source_factor(ctx, p_in)
    if ctx.ratios is not None:  # bands or frames: sigma_s,b T_b over the carrier's (engine/spectral/spectra.py)
        flight = (br.origins.T, br.directions.T, t_in)
        br.ratio = ctx.ratios.scatter(br.ratio, medium.optical_depth(*flight), flight)
    u = rng.random((2, len(br)))
    arriving = br.directions
    br.directions = ctx.phase.sample(br.directions, u[0], u[1])
    if ctx.ratios is not None and ctx.ratios.phase_bands is not None:  # p_b / p_c of the sampled direction
        br.ratio = ctx.ratios.turn(br.ratio, dot3(arriving, br.directions))
    br.origins, br.lengths, br.s = p_in, br.lengths + t_in, br.s + 1
    return br.keep_where(br.weights > 0)


def first_segment_branch(
    ctx: BatchContext, paths: Paths, t_seg: FloatArray, rng: np.random.Generator, chain: bool, double: bool
) -> None:
    """Scattering at p on the source's first segment, then a branch with k <= K reflections (one traced branch
    serves both families below).

    p is a free-flight collision on the source's own first segment (density
    sigma_t T(o -> p), weight x albedo); the branch leaves p in a phase-sampled direction,
    pays extinction on every segment and reflects (cosine sampling, x rho) up to K times.
    - `chain`: single scattering source -> p -> (k = 1..K) -> target: every surface vertex x
      makes a next-event estimate to the targets at scattering order 1, weighted by
      side_weight(A(p), B(x)). The other device's points-on-segments estimator
      (algorithm 2 backward, 3 forward) samples the same family with the complement
      weight, so its ~1/h tail near this run's source is cut off (module docstring).
    - `double` (algorithm 4's in-then-out family, report section 9): on every branch
      segment `segment_points` places p_out (time strata + equiangular, balance
      heuristic), connected to the targets at scattering order 2, weighted by
      side_weight(A(p), B(p_out)); the other run samples the family from its side.
    """
    scene, settings = ctx.scene, ctx.settings
    medium, isect = ctx.medium, scene.intersector
    br = _scatter_on_first_segment(ctx, paths, t_seg, rng)
    K, far = settings.max_reflections, scene.medium_far_distance

    def partition(j: int, pp: Paths, points: FloatArray, *_: Any) -> Any:
        assert pp.first is not None  # runs from both devices carry the source factor
        return side_weight(pp.first, target_factor(ctx, j, points))

    for _bounce in range(K + 1):
        if br is None or len(br) == 0:
            return
        prim, t = isect.intersect(br.origins.T, br.directions.T)
        hit = prim >= 0
        if double:
            seg = np.where(hit, t, far)
            live = (np.isfinite(seg)).nonzero()[0]
            segment_points(ctx, br.keep(live), seg.take(live), rng, order=2, weight_fn=partition)
        nxt = (hit & (br.k < K)).nonzero()[0]
        if len(nxt) == 0:
            return
        br = br.keep(nxt)
        ts = t.take(nxt)
        tau = medium.optical_depth(br.origins.T, br.directions.T, ts)
        br.weights = br.weights * np.exp(-tau)  # = medium.transmittance
        if ctx.ratios is not None:
            br.ratio = ctx.ratios.transmit(br.ratio, tau, (br.origins.T, br.directions.T, ts))
        points = br.origins + ts * br.directions
        prims = prim.take(nxt)
        normals = isect.normals_soa.take(prims, axis=1)
        normals *= np.where(dot3(normals, br.directions) > 0, -1.0, 1.0)
        spawn = points + isect.offset * normals
        br.lengths = br.lengths + ts
        br.k = br.k + 1
        if ctx.ratios is not None:  # spectral scenes: rho_b / rho_c of the face (engine/spectral/spectra.py)
            br.ratio = ctx.ratios.reflect(br.ratio, prims)
        # NEE (chain; materials and mirror images included), then reflection from the materials (mirrors.py)
        br.directions, br.weights = branch_surface(ctx, br, points, spawn, normals, prims, rng, chain)
        br.origins = spawn
        br = br.keep_where(br.weights > 0)
