"""The events of one step of a path: surface vertex, medium next events, medium collision, roulette.

The sections of kernel.trace_batch, named as pbrt-v4's VolPathIntegrator and Mitsuba 3's volpath name them:

- `surface_vertex`: next-event estimation to the targets (the BRDF, or rho / pi), mirror images, then
  reflection (cosine sampling or a material lobe chosen by albedo) and roulette;
- `medium_next_events` (algorithm 5): next-event estimation from the scattering points of the step's
  segments, the free-flight collision and the equiangular points, combined by the balance heuristic
  (segments.scattering_point_throughput);
- `medium_collision` (algorithm 5): the path scatters at its collision (throughput x albedo, a direction
  from the phase function), with the third strategy for Tx -> x_1 -> x_2 -> Rx (`connect_from_target`);
- `roulette`: Russian roulette, folded into each event's one compaction.
Every next-event estimate goes through context.BatchContext.connect (the measurement equation).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from owcsim.engine.core.arrays import FloatArray, IntArray
from owcsim.engine.core.constants import SPEED_OF_LIGHT
from owcsim.engine.core.sampling import cosine_about_soa
from owcsim.engine.integrator.context import BatchContext, Vertices
from owcsim.engine.integrator.lobe import lobe_axis, lobe_source_density
from owcsim.engine.integrator.mirrors import connect_mirrors
from owcsim.engine.integrator.path import Paths, dot, dot3, rows
from owcsim.engine.integrator.segments import scattering_point_throughput
from owcsim.engine.integrator.uniform_medium import EquiangularFrames, connect_on_segments
from owcsim.engine.integrator.weights import first_medium_factor, side_weight
from owcsim.schemas.algorithms import Direction


def surface_vertex(ctx: BatchContext, sp: Paths, prims: IntArray, ts: FloatArray, rng: np.random.Generator) -> Paths:
    """Paths `sp` arriving at surfaces (faces `prims`, distances `ts`): NEE to the targets, then reflection.

    NEE: `connect` evaluates the BRDF (rho / pi, or the material's f(incoming, toward target)) with
    the path throughput; algorithm 4 (`mis`) estimates the unscattered family from both devices, each
    with MIS weight 1/2. Reflection: cosine sampling (throughput x rho), or a material lobe chosen by
    albedo (bsdf.py). Returns the paths that go on.
    """
    settings, scene = ctx.settings, ctx.scene
    isect, geo = scene.intersector, scene.geometry
    points = sp.directions * ts
    points += sp.origins
    normals = isect.normals_soa.take(prims, axis=1)
    np.negative(normals, out=normals, where=dot(normals, sp.directions) > 0)  # two-sided: face the arriving ray
    spawn = normals * isect.offset
    spawn += points
    arriving = sp.directions
    sp = Paths(
        origins=spawn,
        directions=arriving,
        weights=sp.weights,
        lengths=sp.lengths + ts,
        path=sp.path,
        k=sp.k + 1,
        s=sp.s,
        first=sp.first,
        first_rho=sp.first_rho,
        # spectral scenes: rho_b / rho_c of the face, for the NEE from here and the reflected path
        ratio=ctx.ratios.reflect(sp.ratio, prims) if ctx.ratios is not None else sp.ratio,
    )
    # after reflection K a path still matters if it can scatter (5) or host segment points (2-4)
    K, S = settings.max_reflections, settings.max_scattering
    if scene.medium is not None and settings.free_flight:
        goes_on = (sp.k < K) | (sp.s < S)
    elif scene.medium is not None and settings.segment_scatter:
        goes_on = sp.k <= K
    else:
        goes_on = sp.k < K
    last = not goes_on.any()  # every path at its last vertex (e.g. reflection K of algorithm 1): no reflection
    # algorithms 2-4 from both devices: the unscattered surface paths are shared by the partition A / (A + B)
    # (`Vertices.partition`), not by halves: a half from a side that can hardly sample a path (a
    # 1 deg FOV cone seen from the transmitter) keeps a 1/r^2 tail whose runs miss it and report half of H0
    partition = settings.mis and sp.first is not None
    if geo.material is None:  # every surface Lambertian
        rho = geo.reflectance.take(prims)
        ctx.connect(Vertices.on_surface(points, spawn, sp.weights, sp, normals, reflectance=rho, partition=partition))
        if last:
            return sp.gather(np.zeros(0, np.int64))
        sp.weights = sp.weights * rho
        u = ctx.bounce_uniforms(sp, rng)
        sp.directions = cosine_about_soa(normals, u[0], u[1])
    else:
        materials = geo.material.take(prims)
        vertices = Vertices.on_surface(
            points, spawn, sp.weights, sp, normals, materials=(materials, arriving), partition=partition
        )
        ctx.connect(vertices)
        if ctx.mirrors:  # ... -> x -> mirror -> target, through the target's mirror images (mirrors.py)
            connect_mirrors(ctx, vertices)
        if last:
            return sp.gather(np.zeros(0, np.int64))
        u = ctx.bounce_uniforms(sp, rng)
        sp.directions, factor = materials.sample(arriving, normals, u[0], u[1])
        sp.weights = sp.weights * factor
    alive = sp.weights > 0
    alive &= goes_on
    return roulette(ctx, sp, alive, rng)


def medium_next_events(
    ctx: BatchContext,
    paths: Paths,
    eq: EquiangularFrames | None,
    collision_rows: IntArray,
    t_col: FloatArray,
    rng: np.random.Generator,
) -> None:
    """Algorithm 5: next-event estimation from the scattering points of this step's segments.

    The points of a segment are its free-flight collision (paths `collision_rows`, at t_col) and,
    with `equiangular_points`, that many stratified equiangular points per target (segments.py);
    all connect with the phase function at (k, s + 1), with the throughput of
    segments.scattering_point_throughput. The path itself continues from the collision only
    (`medium_collision`). The equiangular points of all segments are drawn as one (n_eq, segments)
    grid, stratum i of every segment in row i (broadcasting, no index arrays). Where
    `uniform_medium.connect_on_segments` applies (a medium the same everywhere, see there) the points connect
    through their segment's frame without gathering the paths; else through `connect`.
    """
    settings, medium = ctx.settings, ctx.medium
    n_eq = settings.equiangular_points if eq is not None else 0
    uniform = medium.uniform_coefficients  # (sigma_t, sigma_s) of a medium the same everywhere, else None
    if uniform is not None and uniform[1] <= 0:  # no point scatters
        return
    for j in range(len(ctx.tgt)):
        if eq is not None and n_eq:
            points = _equiangular_points(ctx, j, paths, eq, collision_rows, t_col, rng)
            if points is None:  # connected on the segments' frames
                continue
            at, s, n_e = points
        else:
            at, s, n_e = collision_rows, t_col, np.zeros(len(collision_rows))
        if len(at) == 0:
            continue
        _connect_points(ctx, j, paths.gather(at), s, n_e, uniform)


def _equiangular_points(
    ctx: BatchContext,
    j: int,
    paths: Paths,
    eq: EquiangularFrames,
    collision_rows: IntArray,
    t_col: FloatArray,
    rng: np.random.Generator,
) -> tuple[IntArray, FloatArray, FloatArray] | None:
    """Target j's equiangular points and the collisions: (path rows, s [m], n_E(s) [1/m]); None when
    `connect_on_segments` connected them."""
    n_eq = ctx.settings.equiangular_points
    frame = eq.frames[j]
    n_seg = len(eq.end)
    # stratum i of [0, 1): (i + u) / n_eq; the uniforms drawn segment by segment (the order of the
    # equiangular points before the grid: the same numbers reach the same points)
    xi = np.add(rng.random((n_seg, n_eq)).T, np.arange(n_eq)[:, None], out=np.empty((n_eq, n_seg)))
    xi *= 1.0 / n_eq
    s_eq = np.clip(frame.sample(None, xi), 0.0, eq.end)
    empty = frame.span <= 0  # (a segment of length 0 has no equiangular points)
    if not empty.any() and connect_on_segments(ctx, j, paths, eq, s_eq, collision_rows, t_col):
        return None
    seg_rows = np.arange(n_seg) if eq.rows is None else eq.rows
    s_eq, n_e_eq, eq_rows = s_eq.ravel(), frame.density(s_eq, n_eq).ravel(), np.tile(seg_rows, n_eq)
    if empty.any():
        keep = np.tile(~empty, n_eq).nonzero()[0]
        s_eq, n_e_eq, eq_rows = s_eq.take(keep), n_e_eq.take(keep), eq_rows.take(keep)
    at = np.concatenate([eq_rows, collision_rows])
    s = np.concatenate([s_eq, t_col])
    # (a collision lies on a finite segment with s < S: its row is in eq.rows, sorted)
    n_e = np.concatenate([n_e_eq, frame.density(t_col, n_eq, eq.segment_of(collision_rows))])
    return at, s, n_e


def _connect_points(
    ctx: BatchContext, j: int, pp: Paths, s: FloatArray, n_e: FloatArray, uniform: tuple[float, float] | None
) -> None:
    """Scattering points at s [m] along the paths `pp` (their own copies) to target j, with the throughput
    w T(o -> p) sigma_s / (p_ff + n_E) and, on first vertices, the two-sided factors (`_first_vertices`)."""
    medium = ctx.medium
    points = pp.origins + s * pp.directions
    sigma_t: Any
    sigma_s: Any
    inside: IntArray | None
    if uniform is not None:  # every point scatters
        sigma_t, sigma_s = uniform
        inside = None
    else:
        sigma_t, sigma_s = medium.coefficients_at(points.T)
        inside = (sigma_s > 0).nonzero()[0]
    if inside is not None and len(inside) < len(s):
        if len(inside) == 0:
            return
        pp, points, s, sigma_t, sigma_s = (
            pp.gather(inside),
            points.take(inside, axis=1),
            s.take(inside),
            sigma_t.take(inside),
            sigma_s.take(inside),
        )
        n_e = n_e.take(inside)
    tau = medium.optical_depth(pp.origins.T, pp.directions.T, s)
    transmittance = np.exp(-tau)  # = medium.transmittance
    if ctx.ratios is not None:  # bands or frames: sigma_s,b T_b over the carrier's at the point (spectra.py)
        pp.ratio = ctx.ratios.scatter(pp.ratio, tau, (pp.origins.T, pp.directions.T, s))
    throughput = scattering_point_throughput(pp.weights, transmittance, sigma_t, sigma_s, n_e)
    mid_g, lobe = _first_vertices(ctx, j, pp, points, s, transmittance, throughput)
    pp.s = pp.s + 1
    ctx.connect(
        Vertices.in_medium(points, throughput, pp, pp.directions, extra_length=s, mid_g=mid_g, lobe=lobe), target=j
    )


def _first_vertices(
    ctx: BatchContext,
    j: int,
    pp: Paths,
    points: FloatArray,
    s: FloatArray,
    transmittance: FloatArray,
    throughput: FloatArray,
) -> tuple[FloatArray | None, tuple[FloatArray, FloatArray] | None]:
    """The weights of points that are their path's first vertex (weights.py, lobe.py): from both devices,
    `Paths.first` there (F) and (mid_g, lobe) for `connect`; from one side with the phase lobe, the
    emission's share F / (F + Lambda_src) multiplied into `throughput`."""
    settings = ctx.settings
    mid_g = lobe = None
    if settings.both_sides:  # a point on the first segment is the path's first vertex (weights.py)
        at_first = (pp.k + pp.s == 0).nonzero()[0]  # only on the first segment (pp's fields are its own copies)
        if len(at_first):
            assert pp.first is not None  # two-sided runs carry it
            pp.first[at_first] = first_medium_factor(ctx, points.take(at_first, axis=1), transmittance.take(at_first))
            lobe_frame = lobe_axis(ctx, j) if settings.phase_lobe else None
            if lobe_frame is not None:  # the source's lobe density at the first vertices (lobe.py)
                lobe_src = np.zeros(len(s))
                lobe_src[at_first] = lobe_source_density(
                    ctx, j, points.take(at_first, axis=1), transmittance.take(at_first)
                )
                lobe = (lobe_src, lobe_frame[1])
        mid_g = transmittance / (s * s)  # edge factor T / r^2 of the edge that reached the point
    elif settings.phase_lobe:  # one side: its emission shares Tx -> p -> Rx with its lobe, F / (F + Lambda_src)
        at_first = (pp.k + pp.s == 0).nonzero()[0]
        if len(at_first) and lobe_axis(ctx, j) is not None:
            first_points, first_t = points.take(at_first, axis=1), transmittance.take(at_first)
            share = side_weight(
                first_medium_factor(ctx, first_points, first_t), lobe_source_density(ctx, j, first_points, first_t)
            )
            throughput[at_first] *= share
    return mid_g, lobe


def medium_collision(
    ctx: BatchContext, paths: Paths, rows: IntArray, t_col: FloatArray, rng: np.random.Generator
) -> Paths:
    """Algorithm 5: paths `rows` collide at t_col (their estimates: `medium_next_events`): throughput x
    albedo, the third strategy (`connect_from_target`) for Tx -> x_1 -> x_2 -> Rx, and a new direction from the
    phase function. Returns the paths that go on."""
    settings = ctx.settings
    medium, phase = ctx.medium, ctx.phase
    K, S = settings.max_reflections, settings.max_scattering
    mp = paths.gather(rows)
    points = mp.origins + t_col * mp.directions
    if ctx.ratios is not None and ctx.ratios.depth_row:  # bands or frames: ratio tracking (spectra.py)
        # the carrier sampled t_col with density sigma_t,c T_c and keeps albedo_c: band b's true sigma_s,b T_b
        # over that is (sigma_s,b / sigma_s,c) exp(-tau_c (sigma_t,b / sigma_t,c - 1)) x albedo_c
        flight = (mp.origins.T, mp.directions.T, t_col)
        mp.ratio = ctx.ratios.scatter(mp.ratio, medium.optical_depth(*flight), flight)
    mp.lengths = mp.lengths + t_col
    uniform = medium.uniform_coefficients
    if uniform is not None and uniform[0] > 0:  # the same albedo everywhere: a number
        mp.weights = mp.weights * (uniform[1] / uniform[0])
    else:
        mp.weights = mp.weights * medium.albedo_at(points.T)
    mp.s = mp.s + 1
    if ctx.mirrors:  # ... -> x -> mirror -> target: only the collision reaches it (mirrors.py)
        connect_mirrors(ctx, Vertices.in_medium(points, mp.weights, mp, mp.directions))
    # the third strategy for Tx -> x1 -> x2 -> Rx (forward runs)
    if settings.both_sides and S >= 2 and ctx.item.direction is Direction.FORWARD:
        connect_from_target(ctx, mp, points, rng)
    u = ctx.bounce_uniforms(mp, rng)
    arriving = mp.directions
    mp.directions = phase.sample(arriving, u[0], u[1])
    if ctx.ratios is not None:  # Mie per band: p_b / p_c of the sampled direction (spectra.py)
        mp.ratio = ctx.ratios.turn(mp.ratio, dot(arriving, mp.directions))
    if settings.both_sides:  # leaving the path's first vertex: its phase density (weights.py)
        at_first = mp.k + mp.s == 1
        if at_first.any():
            assert mp.first_rho is not None  # two-sided runs carry it
            mp.first_rho = np.asarray(np.where(at_first, phase.eval(dot(arriving, mp.directions)), mp.first_rho))
    mp.origins = points
    return roulette(ctx, mp, ((mp.k < K) | (mp.s < S)) & (mp.weights > 0), rng)


def roulette(ctx: BatchContext, paths: Paths, alive: Any, rng: np.random.Generator) -> Paths:
    """Russian roulette on the paths that go on, folded into the step's one compaction.

    From depth k + s >= rr_start_depth a path survives with q = min(1, w / (theta w0)) (theta =
    `rr_threshold`, w0 the source's weight) and its throughput becomes w / q: unbiased. Returns the
    paths where `alive` holds and the roulette spared them, gathered once.
    """
    settings = ctx.settings
    if settings.russian_roulette:
        deep = alive & (paths.k + paths.s >= settings.rr_start_depth)
        at = None if deep.all() else deep.nonzero()[0]  # None: every path plays (the usual step), no index arrays
        if at is None or len(at):
            w = rows(paths.weights, at)
            q = np.minimum(1.0, w * (1.0 / (settings.rr_threshold * ctx.w0)))
            survive = rng.random(len(q)) < q
            w = w / np.where(survive, q, 1.0)
            if at is None:
                paths.weights, alive = w, survive
            else:
                paths.weights[at] = w
                alive[at[~survive]] = False
    return paths.keep_where(alive)


def connect_from_target(ctx: BatchContext, mp: Paths, points: FloatArray, rng: np.random.Generator) -> None:
    """Third strategy for Tx -> x_1 -> x_2 -> Rx (algorithm 5 from both devices, forward runs only).

    x_1 is this path's first vertex (a collision, `mp` just after it: weight
    W_src albedo(x_1), arriving direction mp.directions); x_2 is drawn from the target:
    a direction with pdf R / W_tgt, a free-flight distance along it (density
    sigma_t T(target -> x_2)); the two are joined:
        dH = w * p(cos_1) T(x_1 -> x_2) / r_12^2 * albedo(x_2) * p(cos_2) * W_tgt,
    weighted by F L / (F rho_1 g + L rho_2 g + F L) (weights.connection_weight): where x_1 is near
    the transmitter and x_2 near the receiver, the corner neither unidirectional strategy
    samples well, this one carries the path, and its estimate there is bounded.
    """
    first = ((mp.k == 0) & (mp.s == 1)).nonzero()[0]
    if len(first) == 0:
        return
    for j in range(len(ctx.tgt)):
        _join_from_target(ctx, j, mp, first, points.take(first, axis=1), rng)


def _join_from_target(
    ctx: BatchContext, j: int, mp: Paths, first: IntArray, x1: FloatArray, rng: np.random.Generator
) -> None:
    """`connect_from_target` for the item's j-th target: x_2 drawn from it, joined to the first vertices
    x1 (3, n) of the paths `first` of `mp`."""
    scene, medium, isect = ctx.scene, ctx.medium, ctx.scene.intersector
    arriving = mp.directions.take(first, axis=1)
    assert mp.first is not None  # two-sided runs carry it
    w, F, lengths, path = (mp.weights.take(first), mp.first.take(first), mp.lengths.take(first), mp.path.take(first))
    n = len(first)
    t_idx = int(ctx.tgt[j])
    u = rng.random((3, n))
    dirs = np.ascontiguousarray(ctx.targets.sample_directions(t_idx, u[0], u[1]).T)
    pos = ctx.t_pos[:, j : j + 1]
    origin = pos + isect.offset * ctx.t_nrm[:, j : j + 1]
    origins = np.repeat(origin, n, axis=1)
    prim, t_hit = isect.intersect(origins.T, dirs.T)
    seg = np.where(prim >= 0, t_hit, scene.medium_far_distance)
    t_y, col = medium.sample_distance(origins.T, dirs.T, seg, u[2])
    sel = col.nonzero()[0]
    if len(sel) == 0:
        return
    y = origins.take(sel, axis=1) + t_y.take(sel) * dirs.take(sel, axis=1)
    a = x1.take(sel, axis=1)
    v = y - a
    r12 = np.sqrt(dot3(v, v))
    w12 = v / r12
    keep = (r12 > 0).nonzero()[0]
    if not scene.all_visible and len(keep):
        keep = keep[~isect.occluded(a[:, keep].T, w12[:, keep].T, r12[keep] - 2.0 * isect.offset)]
    if len(keep) == 0:
        return
    sel, y, a, r12, w12 = (
        sel.take(keep),
        y.take(keep, axis=1),
        a.take(keep, axis=1),
        r12.take(keep),
        w12.take(keep, axis=1),
    )
    dj = dirs.take(sel, axis=1)
    p_cos1, p_cos2 = dot3(arriving.take(sel, axis=1), w12), -dot3(w12, dj)
    p1, p2 = ctx.phase.eval(p_cos1), ctx.phase.eval(p_cos2)
    g = medium.transmittance(a.T, w12.T, r12) / (r12 * r12)
    to_dev = pos - y
    r2 = np.sqrt(dot3(to_dev, to_dev))
    resp = ctx.targets.response(np.full(len(sel), t_idx), dot3(dj, ctx.t_nrm[:, j : j + 1]), dj.T) / ctx.t_total[j]
    L = resp * medium.transmittance(y.T, (to_dev / r2).T, r2) / (r2 * r2)
    Fs = F.take(sel)
    q_c = Fs * L
    total = Fs * p1 * g + L * p2 * g + q_c
    share = np.where(total > 0, q_c / np.where(total > 0, total, 1.0), 0.0)
    power = w.take(sel) * p1 * g * medium.albedo_at(y.T) * p2 * ctx.t_total[j] * share
    ok = (power > 0).nonzero()[0]
    if len(ok) == 0:
        return
    ratio = None
    if "ratio" in ctx.out:  # spectral: the ratios at x_1 (k = 0: only smoke per band changes them)
        spectra = ctx.ratios
        assert spectra is not None  # (only parts with ratios carry them)
        ratio = mp.ratio.take(first.take(sel.take(ok)), axis=1)
        if spectra.depth_row:  # sigma_s,b T_b at x_2 over the carrier's, T_b / T_c of x_1 -> x_2
            o_k, d_k = origins.take(sel.take(ok), axis=1), dj.take(ok, axis=1)
            to_y = (o_k.T, d_k.T, t_y.take(sel.take(ok)))
            joint = (a.take(ok, axis=1).T, w12.take(ok, axis=1).T, r12.take(ok))
            scattered = spectra.scatter(ratio, medium.optical_depth(*to_y), to_y)
            ratio = spectra.estimate_ratio(scattered, medium.optical_depth(*joint), joint)
        if spectra.phase_bands is not None:  # p_b / p_c at x_1 and at x_2
            ratio = ratio[: spectra.n_bands] * spectra.phase_ratio(p_cos1.take(ok))
            ratio = ratio * spectra.phase_ratio(p_cos2.take(ok))
    ctx.record(
        np.full(len(ok), j, np.int64),
        np.zeros(len(ok), np.int64),
        np.full(len(ok), 2, np.int64),
        (lengths.take(sel.take(ok)) + r12.take(ok) + r2.take(ok)) / SPEED_OF_LIGHT,
        power.take(ok),
        path.take(sel.take(ok)),  # cell k = 0, s = 2
        ratio,
    )
