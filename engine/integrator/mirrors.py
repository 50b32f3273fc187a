"""Perfect-mirror connections by the image method (next-event estimation through one mirror).

A target t seen through a mirror plane is its image t' (position, normal and C-frame
reflected): the connection x -> y -> t has length |t' - x| and adds one reflection at
y with the mirror's reflectance rho_m(y) (Hecht, Optics, sec. 5.4; Barry et al. 1993
treat specular walls the same way). These functions record into the kernel's
per-batch context (`context.BatchContext`).

Vertices x are surface vertices (factor f(incoming, x -> y) cos, or rho / pi folded in by
the caller) or medium vertices (factor phase(cos), `in_dirs`); in a medium both legs pay
their transmittance T(x -> y) T(y -> t).

Runs from both devices (weights.py). A path x_1 ... x_{n-1} y t whose last reflection
is the mirror y is sampled by this run through the image of t, and by the other device's
run as a path whose *first* vertex is y (its ray hits the mirror, reflects specularly, and
reaches x_{n-1}, ...). The two runs share it by the same function of the path as every
other path: the target-side factor is evaluated at the mirror point y,
    B(y) = R_t(cos at t) / W_t |cos th_y| / |y - t|^2     (x T(y -> t) for algorithm 5),
which is exactly the first-vertex factor (`weights.first_vertex_factor`) the other run
stores when its first vertex is y. Hence
- algorithm 5 (`both_sides`): share = F rho_1 / (F rho_1 + B(y) / pi) (the n >= 2 case of
  `weights.connection_weight`; 1/pi is the direction density leaving a surface vertex
  there, rho_1 the phase or 1/pi leaving x_1, F = `Paths.first`);
- algorithms 2-4 (`mis`): image connections are made (i) from points on the source's first
  segment when the other side's family is estimated from here (Tx -> p -> mirror -> Rx is
  algorithm 2's family, reached forward only through the image), shared with the other
  run's points on the segment after its specular reflection by the balance heuristic of
  the two point densities (`connect_segment_mirrors`, `specular_first_share`: the image
  counterpart of single_scatter._direction_mis), and (ii) from the surface vertices of the
  scattering branch (`branch_surface`, which also follows the materials: Phong lobes,
  specular reflection off mirrors), shared by A / (A + B(y)) with A the source factor of
  the branch's scattering point (no transmittances: `weights.side_weight`).
The source's own mirror paths (source -> mirror -> target, no random choice) are computed
identically by both runs, which count half each.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any, NamedTuple

import numpy as np

from owcsim.engine.core.arrays import FloatArray, IntArray
from owcsim.engine.core.constants import SPEED_OF_LIGHT
from owcsim.engine.core.sampling import cosine_about_soa
from owcsim.engine.integrator.context import BatchContext, Vertices
from owcsim.engine.integrator.path import BatchState, Paths, device_sets
from owcsim.engine.integrator.path import dot3 as _dot
from owcsim.engine.integrator.segments import equiangular_density, time_density
from owcsim.engine.integrator.weights import side_weight, surface_target_factor
from owcsim.engine.sources.devices import Devices
from owcsim.schemas.algorithms import Direction

#: share(ok, wdir, B(y), T(y -> t), image): a run's share of image connections (`_record_mirror`)
Share = Callable[[IntArray, FloatArray, FloatArray, Any, "_Image"], Any]


class _Image(NamedTuple):
    """An image connection x -> y -> target being recorded: plane, target index j, mirror points y (3, m)
    and their faces."""

    plane: Any  # bsdf.MirrorPlane
    j: int
    y: FloatArray
    prim: IntArray


class _Vertex(NamedTuple):
    """What a mirror connection records of its vertices: path lengths so far [m] (with the caller's
    `Vertices.extra_length`), the path in the batch, the cell (k, s) (s: `Vertices.scatter_order` if given)."""

    lengths: FloatArray
    path: IntArray
    k: IntArray
    s: IntArray


def connect_mirrors(ctx: BatchState, v: Vertices, only: int | None = None, share: Share | None = None) -> None:
    """NEE from vertices (3, n) to the targets through one perfect-mirror reflection (image method).

    For a mirror plane, the target t seen through it is its image t' (normal and
    C-frame reflected): the connection x -> y -> t has length |t' - x|, leaves x
    toward t', and adds the reflection at y (k + 1) with factor rho_m(y). It counts
    when x and t lie on the same side of the plane, the ray x -> t' first meets a
    mirror face of that plane (at y), and y sees t. The vertices `v` are described as for
    `BatchContext.connect` (surface vertices: `Vertices.materials`, or the BRDF folded into the
    throughput; medium vertices: factor phase(cos)). `only`: the item's target index to
    connect to (default all). Runs from both devices (module docstring): algorithm 5
    (`settings.both_sides`) weights by its partition from `Paths.first`; algorithms 2-4 by
    A / (A + B(y)) with A = `Paths.first` (`Vertices.partition`), or by a `share` of their own.
    Paths with two or more consecutive mirror reflections next to the target are not
    estimated (second-order images).
    """
    scene, targets, tgt = ctx.scene, ctx.targets, ctx.tgt
    isect, geo = scene.intersector, scene.geometry
    points, weights, paths, normals, in_dirs = v.points, v.throughput, v.paths, v.normals, v.in_dirs
    K = ctx.settings.max_reflections
    live = np.flatnonzero(paths.k + 1 <= K)
    if len(live) == 0:
        return
    assert geo.material is not None  # mirror planes are faces of a material
    mat_rho_m = geo.material.rho_m
    if share is None and v.partition:
        assert paths.first is not None  # runs from both devices carry the source factor
        share = _partition_share(paths.first)
    elif share is None and ctx.settings.both_sides:
        share = _both_sides_share(ctx, paths, in_dirs)
    cells = _Vertex(
        lengths=paths.lengths if v.extra_length is None else paths.lengths + v.extra_length,
        path=paths.path,
        k=paths.k,
        s=paths.s if v.scatter_order is None else v.scatter_order,
    )
    for plane in ctx.mirrors:
        side_x = _dot(points.take(live, axis=1) - plane.point[:, None], plane.normal[:, None])
        images = plane.reflect_points(ctx.t_pos)  # (3, T)
        img_nrm = plane.reflect_vectors(ctx.t_nrm)
        side_t = _dot(ctx.t_pos - plane.point[:, None], plane.normal[:, None])
        for j in range(len(tgt)) if only is None else (only,):  # a loop over devices
            # same side as the target, and off the plane (a vertex on the mirror cannot reflect on it)
            ok = live[(side_x * side_t[j] > 0) & (np.abs(side_x) > 4.0 * isect.offset)]
            if len(ok) == 0:
                continue
            to = images[:, j : j + 1] - points.take(ok, axis=1)
            d2 = _dot(to, to)
            d = np.sqrt(d2)
            wdir = to / d
            ct = -_dot(to, img_nrm[:, j : j + 1]) / d
            keep = (ct > 0) | (not targets.front_only)
            if normals is not None:
                cs = _dot(to, normals.take(ok, axis=1)) / d
                keep &= cs > 0
            keep = np.flatnonzero(keep)
            if len(keep) == 0:
                continue
            ok, d, d2, wdir, ct = ok.take(keep), d.take(keep), d2.take(keep), wdir.take(keep, axis=1), ct.take(keep)
            if normals is not None:
                lobe = cs.take(keep)
                if v.materials is not None:
                    mat, arriving = v.materials
                    lobe = lobe * mat.take(ok).eval(arriving.take(ok, axis=1), normals.take(ok, axis=1), wdir)
            else:
                assert in_dirs is not None  # a medium vertex
                lobe = ctx.phase.eval(_dot(in_dirs.take(ok, axis=1), wdir))
            back = -plane.reflect_vectors(wdir)  # from the real target toward y
            resp = targets.response(np.full(len(ok), tgt[j]), ct, back.T)
            f = weights.take(ok) * lobe * resp / d2
            _record_mirror(
                ctx, plane, j, points, v.shadow_origins, ok, f, d, wdir, cells, mat_rho_m, share=share, resp=resp
            )


def _partition_share(first_factor: FloatArray) -> Share:
    """Algorithms 2-4 from both devices: A / (A + B(y)), B without transmittance (weights.side_weight)."""

    def share(ok: IntArray, wdir: FloatArray, last: FloatArray, t_rest: Any, image: _Image) -> Any:
        return side_weight(first_factor.take(ok), last)

    return share


def _both_sides_share(ctx: BatchState, paths: Any, in_dirs: FloatArray | None) -> Share:
    """Algorithm 5 from both devices: F rho_1 / (F rho_1 + B(y) T(y -> t) / pi) (module docstring)."""

    def share(ok: IntArray, wdir: FloatArray, last: FloatArray, t_rest: Any, image: _Image) -> Any:
        at_first = (paths.k.take(ok) + paths.s.take(ok)) == 1  # the connecting vertex is x_1 itself
        rho_f = paths.first_rho.take(ok)  # 1/pi at a surface; set at a medium x_1 once the path leaves it
        if in_dirs is not None and at_first.any():  # leaving a first medium vertex toward y: its phase density
            rho_f = np.where(at_first, ctx.phase.eval(_dot(in_dirs.take(ok, axis=1), wdir)), rho_f)
        return side_weight(paths.first.take(ok) * rho_f, last * t_rest / np.pi)

    return share


def connect_segment_mirrors(
    ctx: BatchState,
    j: int,
    points: FloatArray,
    weights: FloatArray,
    pp: Paths,
    s: FloatArray,
    order: int,
    density: FloatArray,
) -> None:
    """Algorithms 2-4 from both devices: points p on the source's first segment -> mirror -> j-th target.

    `weights` as `single_scatter.segment_points` forms them before its direction weight, `density`
    the points' density along the segment (time strata + equiangular). The family
    source -> p -> mirror -> target belongs to the other side's family (algorithm 2's
    forward, algorithm 3's backward), so the connection is made only where that family is
    estimated (KernelSettings.other_family). The other run samples the same path as a point on the
    second segment of its ray that reflects specularly at y; the two share it by the
    balance heuristic of their point densities (`specular_first_share` there), the image
    counterpart of single_scatter._direction_mis for source -> p -> target.
    """
    if not ctx.settings.other_family(ctx.item.direction is Direction.FORWARD):
        return
    src_set, _ = device_sets(ctx.scene, ctx.item.direction)
    i = ctx.item.source
    cos_src = _dot(pp.directions, src_set.normals[i][:, None])
    q_self = (
        src_set.response(np.full(len(s), i), cos_src, pp.directions.T) / src_set.total_response(i) / (s * s) * density
    )

    def share(ok: IntArray, wdir: FloatArray, last: FloatArray, t_rest: Any, image: _Image) -> Any:
        q_s = q_self.take(ok)
        q_o = _specular_second_density(
            ctx, ctx.targets, int(ctx.tgt[image.j]), image, points.take(ok, axis=1), src_set.positions[i]
        )
        total = q_s + q_o
        return np.where(total > 0, q_s / np.where(total > 0, total, 1.0), 1.0)

    vertices = Vertices.in_medium(
        points, weights, pp, pp.directions, scatter_order=np.full(len(pp), order, np.int64), extra_length=s
    )
    connect_mirrors(ctx, vertices, only=j, share=share)


def _device_origin(ctx: BatchState, devices: Devices, i: int) -> FloatArray:
    """Where device i's rays start: its position moved off along its normal by the ray offset."""
    return devices.positions[i] + ctx.scene.intersector.offset * devices.normals[i]


def _segment_point_density(
    ctx: BatchState, origins: FloatArray, dirs: FloatArray, l0: FloatArray, other: Any, s_p: FloatArray
) -> FloatArray:
    """(n_T + n_E)(s_p): density of the points `single_scatter.segment_points` puts on the segments that leave
    `origins` (3, m) along `dirs` (path length l0 so far) and run to their first hit, toward `other` (3,)."""
    scene, settings = ctx.scene, ctx.settings
    _, t_hit = scene.intersector.intersect(origins.T, dirs.T)
    end = np.where(np.isfinite(t_hit), t_hit, scene.medium_far_distance)
    tgt = np.repeat(np.asarray(other, float)[:, None], len(s_p), axis=1)
    zeros = np.zeros(len(s_p))
    return time_density(
        l0, origins, dirs, tgt, zeros, end, s_p, settings.strata_length, settings.max_strata
    ) + equiangular_density(origins, dirs, tgt, zeros, end, s_p, settings.equiangular_points)


def _specular_second_density(
    ctx: BatchState,
    devices: Devices,
    i: int,
    image: _Image,
    points: FloatArray,
    other: Any,
    density: FloatArray | None = None,
) -> FloatArray:
    """Volume density with which device i's run puts a segment point at `points` (3, m) as the path
    i -> y (mirror lobe) -> p -> other: R_i / W_i / |p - i'|^2 (the direction toward y, in the unfolded
    geometry) x P(mirror lobe at y) x (n_T + n_E) on the reflected segment from y (`density` if the
    caller drew the points itself, else recomputed as that run computes it)."""
    plane, y = image.plane, image.y
    mat = ctx.scene.geometry.material
    assert mat is not None  # mirror planes are faces of a material
    o = _device_origin(ctx, devices, i)
    to_y = y - o[:, None]
    l0 = np.sqrt(_dot(to_y, to_y))
    w_in = to_y / l0
    cos_i = _dot(w_in, devices.normals[i][:, None])
    resp = devices.response(np.full(len(l0), i), cos_i, w_in.T) / devices.total_response(i)
    p_m = mat.rho_m.take(image.prim) / np.maximum(mat.total.take(image.prim), 1e-300)
    side = np.sign(_dot(o[:, None] - plane.point[:, None], plane.normal[:, None]))
    y_off = y + ctx.scene.intersector.offset * side * plane.normal[:, None]
    v = points - y_off
    s_p = np.sqrt(_dot(v, v))
    unfolded = l0 + s_p
    if density is None:
        density = _segment_point_density(ctx, y_off, plane.reflect_vectors(w_in), l0, other, s_p)
    return resp * p_m / (unfolded * unfolded) * density


def _first_segment_density(ctx: BatchState, devices: Devices, i: int, points: FloatArray, other: Any) -> FloatArray:
    """Volume density with which device i's run puts a point of its first segment at `points` (3, m)
    (toward `other`): R_i / W_i / r^2 x (n_T + n_E), as single_scatter._direction_mis computes the other side's."""
    o = _device_origin(ctx, devices, i)
    v = points - o[:, None]
    r = np.sqrt(_dot(v, v))
    w = v / r
    resp = devices.response(np.full(len(r), i), _dot(w, devices.normals[i][:, None]), w.T) / devices.total_response(i)
    live = np.flatnonzero(resp > 0)
    out = np.zeros(len(r))
    if len(live):
        origins = np.repeat(o[:, None], len(live), axis=1)
        rl = r.take(live)
        dens = _segment_point_density(ctx, origins, w.take(live, axis=1), np.zeros(len(live)), other, rl)
        out[live] = resp.take(live) / (rl * rl) * dens
    return out


def specular_first_share(
    ctx: BatchState, j: int, pp: Paths, points: FloatArray, s: FloatArray, density: FloatArray, default: Any
) -> Any:
    """Algorithms 2-4 from both devices, points p on segments after the path's first vertex: the share of
    those whose first vertex y was a specular mirror reflection (source -> y -> p -> target, the family
    the other run reaches from its first segment through the image of this run's source) is the balance
    heuristic q_self / (q_self + q_other) of `connect_segment_mirrors`; other points keep `default`.
    A first vertex is specular when it lies on a mirror plane and the segment leaves it in the mirror
    direction of the ray from the source (to 1e-12: a diffuse sample does so with probability ~1e-12)."""
    if not ctx.mirrors:
        return default
    src_set, _ = device_sets(ctx.scene, ctx.item.direction)
    i = ctx.item.source
    o = _device_origin(ctx, src_set, i)
    cand = np.flatnonzero((pp.k == 1) & (pp.s == 0))
    if len(cand) == 0:
        return default
    out = np.array(default, float, copy=True)
    isect = ctx.scene.intersector
    for plane in ctx.mirrors:
        org = pp.origins.take(cand, axis=1)
        dist = _dot(org - plane.point[:, None], plane.normal[:, None])
        w_in = org - dist * plane.normal[:, None] - o[:, None]
        w_in = w_in / np.sqrt(_dot(w_in, w_in))
        spec = (np.abs(dist) < 8.0 * isect.offset) & (
            _dot(plane.reflect_vectors(w_in), pp.directions.take(cand, axis=1)) > 1.0 - 1e-12
        )
        sel = cand[spec]
        if len(sel) == 0:
            continue
        cand = cand[~spec]
        y = org[:, spec] - dist[spec] * plane.normal[:, None]
        prim, _ = isect.intersect(np.repeat(o[:, None], len(sel), axis=1).T, w_in[:, spec].T)  # y's face
        pts = points.take(sel, axis=1)
        image = _Image(plane, j, y, np.maximum(prim, 0))
        q_self = _specular_second_density(ctx, src_set, i, image, pts, ctx.t_pos[:, j], density=density.take(sel))
        q_other = _first_segment_density(ctx, ctx.targets, int(ctx.tgt[j]), pts, src_set.positions[i])
        total = q_self + q_other
        out[sel] = np.where(total > 0, q_self / np.where(total > 0, total, 1.0), 1.0)
        if len(cand) == 0:
            break
    return out


def branch_surface(
    ctx: BatchContext,
    br: Paths,
    points: FloatArray,
    spawn: FloatArray,
    normals: FloatArray,
    prims: IntArray,
    rng: np.random.Generator,
    chain: bool,
) -> tuple[FloatArray, FloatArray]:
    """A surface vertex of the scattering branch of algorithms 2-4 (single_scatter.first_segment_branch).

    `chain`: next-event estimates to the targets at scattering order 1 (f cos from the
    materials, or rho / pi), directly and through mirror images, each weighted by
    side_weight(A(p), B) (B at the vertex, or at the mirror point), target by target (the share
    depends on the target). Then the branch reflects: Lambertian scenes by cosine sampling (x rho),
    others from their materials (bsdf.Materials.sample: Phong lobes, specular reflection off mirrors).
    Returns the branch's new directions and weights.
    """
    geo = ctx.scene.geometry
    mat = geo.material.take(prims) if geo.material is not None else None
    rho = geo.reflectance.take(prims) if mat is None else None
    if chain:
        assert br.first is not None  # runs from both devices carry the source factor
        for j in range(len(ctx.tgt)):
            part = side_weight(br.first, surface_target_factor(ctx, j, points, normals))
            if mat is None:  # the BRDF rho / pi folded into the throughput
                assert rho is not None
                ctx.connect(Vertices.on_surface(points, spawn, br.weights * rho / np.pi * part, br, normals), target=j)
            else:
                materials = (mat, br.directions)
                ctx.connect(Vertices.on_surface(points, spawn, br.weights * part, br, normals, materials=materials), j)
            if ctx.mirrors:  # (mirror planes are faces of a material)
                assert mat is not None
                materials = (mat, br.directions)
                connect_mirrors(
                    ctx,
                    Vertices.on_surface(points, spawn, br.weights, br, normals, materials=materials, partition=True),
                    j,
                )
    u = rng.random((2, len(br)))
    if mat is None:
        assert rho is not None
        return cosine_about_soa(normals, u[0], u[1]), br.weights * rho
    directions, factor = mat.sample(br.directions, normals, u[0], u[1])
    return directions, br.weights * factor


def connect_source_mirrors(ctx: BatchState, sources: Devices, i: int, w0: float, n_paths: int) -> None:
    """Source -> one mirror reflection -> target: a constant every path of the batch adds."""
    isect = ctx.scene.intersector
    pos = sources.positions[i][:, None]
    nrm = sources.normals[i][:, None]
    one = _Vertex(lengths=np.zeros(1), path=np.zeros(1, np.int64), k=np.zeros(1, np.int64), s=np.zeros(1, np.int64))
    mark = len(ctx.out["power"])
    targets, tgt = ctx.targets, ctx.tgt
    material = ctx.scene.geometry.material
    assert material is not None  # mirror planes are faces of a material
    rho_m = material.rho_m
    for plane in ctx.mirrors:
        side_x = _dot(pos - plane.point[:, None], plane.normal[:, None])
        images = plane.reflect_points(ctx.t_pos)
        img_nrm = plane.reflect_vectors(ctx.t_nrm)
        side_t = _dot(ctx.t_pos - plane.point[:, None], plane.normal[:, None])
        for j in range(len(tgt)):
            if not side_x[0] * side_t[j] > 0:
                continue
            to = images[:, j : j + 1] - pos
            d = np.sqrt(_dot(to, to))
            wdir = to / d
            ct = -_dot(to, img_nrm[:, j : j + 1]) / d
            src = sources.response(np.array([i]), _dot(wdir, nrm), wdir.T) / sources.total_response(i)
            back = -plane.reflect_vectors(wdir)
            f = w0 * src * targets.response(np.array([tgt[j]]), ct, back.T) / (d * d)
            if f[0] > 0:
                _record_mirror(
                    ctx,
                    plane,
                    j,
                    pos,
                    pos + isect.offset * wdir,
                    np.zeros(1, np.int64),
                    f,
                    d,
                    wdir,
                    one,
                    rho_m,
                )
    for key in ctx.out:  # every path of the batch carries the same contribution
        added = ctx.out[key][mark:]
        ctx.out[key][mark:] = [
            np.tile(np.arange(n_paths), len(a)) if key == "path" else np.repeat(a, n_paths) for a in added
        ]


def _take(sel: IntArray, *arrays: Any) -> tuple[Any, ...]:
    """Each array's entries (its last axis) at `sel`."""
    return tuple(a.take(sel, axis=-1) for a in arrays)


def _record_mirror(
    ctx: BatchState,
    plane: Any,
    j: int,
    points: FloatArray,
    shadow_origins: FloatArray,
    ok: IntArray,
    f: FloatArray,
    d: FloatArray,
    wdir: FloatArray,
    paths: _Vertex,
    rho_m: FloatArray,
    share: Share | None = None,
    resp: FloatArray | None = None,
) -> None:
    """Visibility x -> y (first hit on the plane's mirror faces) and y -> target, rho_m(y), transmittance of
    both legs, the runs' share (`share(ok, wdir, B(y), T(y -> t))`, with B(y) from `resp`); then record."""
    isect, medium = ctx.scene.intersector, ctx.scene.medium
    sel = np.flatnonzero(f > 0)
    if len(sel) == 0:
        return
    ok, f, d, wdir = ok.take(sel), f.take(sel), d.take(sel), wdir.take(sel, axis=1)
    if resp is not None:
        resp = resp.take(sel)
    x, so = points.take(ok, axis=1), shadow_origins.take(ok, axis=1)
    cos_p = np.maximum(np.abs(_dot(wdir, plane.normal[:, None])), 1e-300)
    # distances to the plane along wdir from the vertex (to y) and from the shadow-ray origin
    t_y = np.abs(_dot(x - plane.point[:, None], plane.normal[:, None])) / cos_p
    t_s = np.abs(_dot(so - plane.point[:, None], plane.normal[:, None])) / cos_p
    prim, t_hit = isect.intersect(so.T, wdir.T)
    hit = (prim >= 0) & (np.abs(t_hit - t_s) <= 4.0 * isect.offset + 1e-6 * t_s)
    hit[hit] = plane.faces[prim[hit]]
    sel = np.flatnonzero(hit)
    if len(sel) == 0:
        return
    ok, f, d, wdir, t_y, prim, cos_p = _take(sel, ok, f, d, wdir, t_y, prim, cos_p)
    if resp is not None:
        resp = resp.take(sel)
    f = f * rho_m.take(prim)
    y = points.take(ok, axis=1) + t_y * wdir
    out_dir = plane.reflect_vectors(wdir)
    rest = d - t_y
    side = np.sign(_dot(points.take(ok, axis=1) - plane.point[:, None], plane.normal[:, None]))
    y_off = y + isect.offset * side * plane.normal[:, None]
    vis = ~isect.occluded(y_off.T, out_dir.T, rest - 2.0 * isect.offset)
    sel = np.flatnonzero(vis & (f > 0))
    if len(sel) == 0:
        return
    ok, f, d, wdir, t_y, out_dir, y, rest, cos_p, prim = _take(sel, ok, f, d, wdir, t_y, out_dir, y, rest, cos_p, prim)
    t_rest: Any = 1.0
    if medium is not None:
        t_rest = medium.transmittance(y.T, out_dir.T, rest)
        f = f * medium.transmittance(points.take(ok, axis=1).T, wdir.T, t_y) * t_rest
    if share is not None:
        assert resp is not None  # callers with a share pass the response
        last = resp.take(sel) / ctx.t_total[j] * cos_p / (rest * rest)
        f = f * share(ok, wdir, last, t_rest, _Image(plane, j, y, prim))
    ctx.out["target"].append(np.full(len(ok), j, np.int64))
    ctx.out["k"].append(paths.k.take(ok) + 1)
    ctx.out["s"].append(paths.s.take(ok))
    ctx.out["delay"].append((paths.lengths.take(ok) + d) * (1.0 / SPEED_OF_LIGHT))
    ctx.out["power"].append(f)
    ctx.out["path"].append(paths.path.take(ok))
