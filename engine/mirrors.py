"""Perfect-mirror connections by the image method (next-event estimation through one mirror).

A target t seen through a mirror plane is its image t' (position, normal and C-frame
reflected): the connection x -> y -> t has length |t' - x| and adds one reflection at
y with the mirror's reflectance rho_m(y) (Hecht, Optics, sec. 5.4; Barry et al. 1993
treat specular walls the same way). These functions record into the kernel's
per-batch context (`kernel._Context`).

Vertices x are surface vertices (factor f(incoming, x -> y) cos, or rho / pi folded in by
the caller) or medium vertices (factor phase(cos), `in_dirs`); in a medium both legs pay
their transmittance T(x -> y) T(y -> t).

Runs from both devices (medium_nee.py). A path x_1 ... x_{n-1} y t whose last reflection
is the mirror y is sampled by this run through the image of t, and by the other device's
run as a path whose *first* vertex is y (its ray hits the mirror, reflects specularly, and
reaches x_{n-1}, ...). The two runs share it by the same function of the path as every
other path: the target-side factor is evaluated at the mirror point y,
    B(y) = R_t(cos at t) / W_t |cos th_y| / |y - t|^2     (x T(y -> t) for algorithm 5),
which is exactly the first-vertex factor (`medium_nee.first_vertex_factor`) the other run
stores when its first vertex is y. Hence
- algorithm 5 (`both_sides`): share = F rho_1 / (F rho_1 + B(y) / pi) (the n >= 2 case of
  `medium_nee.connection_weight`; 1/pi is the direction density leaving a surface vertex
  there, rho_1 the phase or 1/pi leaving x_1, F = `_Paths.first`);
- algorithms 2-4 (`mis`): share = A / (A + B(y)) with A the source factor of the path's
  first scattering point (no transmittances: `medium_nee.side_weight`). Image connections
  are made (i) from points on the source's first segment when the other side's family is
  estimated from here (Tx -> p -> mirror -> Rx is algorithm 2's family, reached forward only
  through the image) and (ii) from the surface vertices of the scattering branch
  (`branch_surface`), which also follows the materials (Phong lobes, specular reflection
  off mirrors).
The source's own mirror paths (source -> mirror -> target, no random choice) are computed
identically by both runs, which count half each.
"""
from __future__ import annotations

from typing import NamedTuple

import numpy as np

from .constants import SPEED_OF_LIGHT


def _dot(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Row-wise dot product of (3, n) component arrays."""
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]


class _Vertex(NamedTuple):
    """What a mirror connection records of its vertices (a stand-in for kernel._Paths)."""

    lengths: np.ndarray
    path: np.ndarray
    k: np.ndarray
    s: np.ndarray


def connect_mirrors(ctx, points, shadow_origins, weights, paths, normals=None, brdf=None, in_dirs=None,
                    only=None, first_factor=None):
    """NEE from vertices (3, n) to the targets through one perfect-mirror reflection (image method).

    For a mirror plane, the target t seen through it is its image t' (normal and
    C-frame reflected): the connection x -> y -> t has length |t' - x|, leaves x
    toward t', and adds the reflection at y (k + 1) with factor rho_m(y). It counts
    when x and t lie on the same side of the plane, the ray x -> t' first meets a
    mirror face of that plane (at y), and y sees t. Weights are as for `connect`
    (Lambertian: rho / pi folded in by the caller; `brdf` = (Materials, arriving dirs);
    medium vertices: `in_dirs`, factor phase(cos)). `only`: the item's target index to
    connect to (default all). Runs from both devices (module docstring): algorithm 5
    (`settings.both_sides`) weights by its partition from `paths.first`; algorithms 2-4
    pass the path's source factor A per vertex as `first_factor`.
    Paths with two or more consecutive mirror reflections next to the target are not
    estimated (second-order images).
    """
    scene, targets, tgt = ctx.scene, ctx.targets, ctx.tgt
    isect, geo = scene.intersector, scene.geometry
    K = ctx.settings.max_reflections
    live = np.flatnonzero(paths.k + 1 <= K)
    if len(live) == 0:
        return
    mat_rho_m = geo.material.rho_m
    share = None
    if first_factor is not None:
        share = _partition_share(first_factor)
    elif ctx.settings.both_sides:
        share = _both_sides_share(ctx, paths, in_dirs)
    for plane in ctx.mirrors:
        side_x = _dot(points.take(live, axis=1) - plane.point[:, None], plane.normal[:, None])
        images = plane.reflect_points(ctx.t_pos)  # (3, T)
        img_nrm = plane.reflect_vectors(ctx.t_nrm)
        side_t = _dot(ctx.t_pos - plane.point[:, None], plane.normal[:, None])
        for j in (range(len(tgt)) if only is None else (only,)):  # a loop over devices
            # same side as the target, and off the plane (a vertex on the mirror cannot reflect on it)
            ok = live[(side_x * side_t[j] > 0) & (np.abs(side_x) > 4.0 * isect.offset)]
            if len(ok) == 0:
                continue
            to = images[:, j:j + 1] - points.take(ok, axis=1)
            d2 = _dot(to, to)
            d = np.sqrt(d2)
            wdir = to / d
            ct = -_dot(to, img_nrm[:, j:j + 1]) / d
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
                if brdf is not None:
                    mat, arriving = brdf
                    lobe = lobe * mat.take(ok).eval(arriving.take(ok, axis=1), normals.take(ok, axis=1), wdir)
            else:
                lobe = scene.phase.eval(_dot(in_dirs.take(ok, axis=1), wdir))
            back = -plane.reflect_vectors(wdir)  # from the real target toward y
            resp = targets.response(np.full(len(ok), tgt[j]), ct, back.T)
            f = weights.take(ok) * lobe * resp / d2
            _record_mirror(ctx, plane, j, points, shadow_origins, ok, f, d, wdir, paths, mat_rho_m,
                           share=share, resp=resp)


def _partition_share(first_factor):
    """Algorithms 2-4 from both devices: A / (A + B(y)), B without transmittance (medium_nee.side_weight)."""
    from .medium_nee import side_weight

    def share(ok, wdir, last, t_rest):
        return side_weight(first_factor.take(ok), last)
    return share


def _both_sides_share(ctx, paths, in_dirs):
    """Algorithm 5 from both devices: F rho_1 / (F rho_1 + B(y) T(y -> t) / pi) (module docstring)."""
    from .medium_nee import side_weight

    scene = ctx.scene

    def share(ok, wdir, last, t_rest):
        at_first = (paths.k.take(ok) + paths.s.take(ok)) == 1  # the connecting vertex is x_1 itself
        rho_f = paths.first_rho.take(ok)
        if in_dirs is not None and at_first.any():  # leaving a first medium vertex toward y: its phase density
            rho_f = np.where(at_first, scene.phase.eval(_dot(in_dirs.take(ok, axis=1), wdir)), rho_f)
        elif in_dirs is None:
            rho_f = np.where(at_first, 1.0 / np.pi, rho_f)
        return side_weight(paths.first.take(ok) * rho_f, last * t_rest / np.pi)
    return share


def connect_segment_mirrors(ctx, j: int, points, weights, pp, s, order: int) -> None:
    """Algorithms 2-4 from both devices: points p on the source's first segment -> mirror -> j-th target.

    `weights` as `kernel.segment_points` forms them before its direction weight (point
    density included); the family source -> p -> mirror -> target belongs to the other
    side's family (algorithm 2's forward, algorithm 3's backward), so the connection is
    made only where that family is estimated (`segment_family`) and shared with the other
    run by A(p) / (A(p) + B(y)) (module docstring).
    """
    from .medium_nee import source_factor

    settings = ctx.settings
    forward = ctx.item.direction == "forward"
    fam = settings.segment_family
    if not (fam == 4 or (fam == 2) == forward):
        return
    vertex = _Vertex(lengths=pp.lengths + s, path=pp.path, k=pp.k, s=np.full(len(pp), order, np.int64))
    connect_mirrors(ctx, points, points, weights, vertex, in_dirs=pp.directions, only=j,
                    first_factor=source_factor(ctx, points))


def branch_surface(ctx, br, points, spawn, normals, prims, rng, chain: bool):
    """A surface vertex of the scattering branch of algorithms 2-4 (medium_nee.first_segment_branch).

    `chain`: next-event estimates to the targets at scattering order 1 (f cos from the
    materials, or rho / pi), directly and through mirror images, each weighted by
    side_weight(A(p), B) (B at the vertex, or at the mirror point). Then the branch
    reflects: Lambertian scenes by cosine sampling (x rho), others from their materials
    (bsdf.Materials.sample: Phong lobes, specular reflection off mirrors). Returns the
    branch's new directions and weights.
    """
    from .kernel import _Context
    from .medium_nee import _surface_target_factor, side_weight
    from .sampling import cosine_about_soa

    geo = ctx.scene.geometry
    mat = geo.material.take(prims) if geo.material is not None else None
    rho = geo.reflectance.take(prims) if mat is None else None
    if chain:
        for j in range(len(ctx.tgt)):
            part = side_weight(br.first, _surface_target_factor(ctx, j, points, normals))
            sub = _Context(ctx.scene, ctx.targets, ctx.tgt[j:j + 1], ctx.settings, ctx.item)
            if mat is None:
                sub.connect(points, spawn, br.weights * rho / np.pi * part, br, normals=normals)
            else:
                sub.connect(points, spawn, br.weights * part, br, normals=normals, brdf=(mat, br.directions))
            for key in ctx.out:
                if key == "target":
                    ctx.out[key] += [np.full(len(a), j, np.int64) for a in sub.out[key]]
                else:
                    ctx.out[key] += sub.out[key]
            if ctx.mirrors:
                connect_mirrors(ctx, points, spawn, br.weights, br, normals=normals, brdf=(mat, br.directions),
                                only=j, first_factor=br.first)
    u = rng.random((2, len(br)))
    if mat is None:
        return cosine_about_soa(normals, u[0], u[1]), br.weights * rho
    directions, factor = mat.sample(br.directions, normals, u[0], u[1])
    return directions, br.weights * factor


def connect_source_mirrors(ctx, sources, i, w0, n_paths):
    """Source -> one mirror reflection -> target: a constant every path of the batch adds."""
    isect = ctx.scene.intersector
    pos = sources.positions[i][:, None]
    nrm = sources.normals[i][:, None]
    one = _Vertex(lengths=np.zeros(1), path=np.zeros(1, np.int64), k=np.zeros(1, np.int64),
                  s=np.zeros(1, np.int64))
    mark = len(ctx.out["power"])
    targets, tgt = ctx.targets, ctx.tgt
    for plane in ctx.mirrors:
        side_x = _dot(pos - plane.point[:, None], plane.normal[:, None])
        images = plane.reflect_points(ctx.t_pos)
        img_nrm = plane.reflect_vectors(ctx.t_nrm)
        side_t = _dot(ctx.t_pos - plane.point[:, None], plane.normal[:, None])
        for j in range(len(tgt)):
            if not side_x[0] * side_t[j] > 0:
                continue
            to = images[:, j:j + 1] - pos
            d = np.sqrt(_dot(to, to))
            wdir = to / d
            ct = -_dot(to, img_nrm[:, j:j + 1]) / d
            src = sources.response(np.array([i]), _dot(wdir, nrm), wdir.T) / sources.total_response(i)
            back = -plane.reflect_vectors(wdir)
            f = w0 * src * targets.response(np.array([tgt[j]]), ct, back.T) / (d * d)
            if f[0] > 0:
                _record_mirror(ctx, plane, j, pos, pos + isect.offset * wdir, np.zeros(1, np.int64), f, d, wdir,
                               one, ctx.scene.geometry.material.rho_m)
    for key in ctx.out:  # every path of the batch carries the same contribution
        added = ctx.out[key][mark:]
        ctx.out[key][mark:] = [np.tile(np.arange(n_paths), len(a)) if key == "path" else np.repeat(a, n_paths)
                               for a in added]


def _record_mirror(ctx, plane, j, points, shadow_origins, ok, f, d, wdir, paths, rho_m, share=None, resp=None):
    """Visibility x -> y (first hit on the plane's mirror faces) and y -> target, rho_m(y), transmittance of
    both legs, the runs' share (`share(ok, wdir, B(y), T(y -> t))`, with B(y) from `resp`); then record."""
    scene, isect, medium = ctx.scene, ctx.scene.intersector, ctx.scene.medium
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
    ok, f, d, wdir, t_y, prim, cos_p = ok.take(sel), f.take(sel), d.take(sel), wdir.take(sel, axis=1), \
        t_y.take(sel), prim.take(sel), cos_p.take(sel)
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
    ok, f, d, wdir, t_y, out_dir, y, rest, cos_p = ok.take(sel), f.take(sel), d.take(sel), \
        wdir.take(sel, axis=1), t_y.take(sel), out_dir.take(sel, axis=1), y.take(sel, axis=1), rest.take(sel), \
        cos_p.take(sel)
    t_rest = 1.0
    if medium is not None:
        t_rest = medium.transmittance(y.T, out_dir.T, rest)
        f = f * medium.transmittance(points.take(ok, axis=1).T, wdir.T, t_y) * t_rest
    if share is not None:
        last = resp.take(sel) / ctx.t_total[j] * cos_p / (rest * rest)
        f = f * share(ok, wdir, last, t_rest)
    ctx.out["target"].append(np.full(len(ok), j, np.int64))
    ctx.out["k"].append(paths.k.take(ok) + 1)
    ctx.out["s"].append(paths.s.take(ok))
    ctx.out["delay"].append((paths.lengths.take(ok) + d) * (1.0 / SPEED_OF_LIGHT))
    ctx.out["power"].append(f)
    ctx.out["path"].append(paths.path.take(ok))
