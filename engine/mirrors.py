"""Perfect-mirror connections by the image method (next-event estimation through one mirror).

A target t seen through a mirror plane is its image t' (position, normal and C-frame
reflected): the connection x -> y -> t has length |t' - x| and adds one reflection at
y with the mirror's reflectance rho_m(y) (Hecht, Optics, sec. 5.4; Barry et al. 1993
treat specular walls the same way). These functions record into the kernel's
per-batch context (`kernel._Context`).
"""
from __future__ import annotations

from typing import NamedTuple

import numpy as np

from .constants import SPEED_OF_LIGHT


def _dot(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Row-wise dot product of (3, n) component arrays."""
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]


class _SourceVertex(NamedTuple):
    """The source itself as the (single) vertex a mirror connection leaves from."""

    lengths: np.ndarray
    path: np.ndarray
    k: np.ndarray
    s: np.ndarray


def connect_mirrors(ctx, points, shadow_origins, weights, paths, normals, brdf=None):
    """NEE from surface vertices to the targets through one perfect-mirror reflection (image method).

    For a mirror plane, the target t seen through it is its image t' (normal and
    C-frame reflected): the connection x -> y -> t has length |t' - x|, leaves x
    toward t', and adds the reflection at y (k + 1) with factor rho_m(y). It counts
    when x and t lie on the same side of the plane, the ray x -> t' first meets a
    mirror face of that plane (at y), and y sees t. Weights are as for `connect`
    (Lambertian: rho / pi folded in by the caller; `brdf` = (Materials, arriving dirs)).
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
    for plane in ctx.mirrors:
        side_x = _dot(points.take(live, axis=1) - plane.point[:, None], plane.normal[:, None])
        images = plane.reflect_points(ctx.t_pos)  # (3, T)
        img_nrm = plane.reflect_vectors(ctx.t_nrm)
        side_t = _dot(ctx.t_pos - plane.point[:, None], plane.normal[:, None])
        for j in range(len(tgt)):  # a loop over devices
            # same side as the target, and off the plane (a vertex on the mirror cannot reflect on it)
            ok = live[(side_x * side_t[j] > 0) & (np.abs(side_x) > 4.0 * isect.offset)]
            if len(ok) == 0:
                continue
            to = images[:, j:j + 1] - points.take(ok, axis=1)
            d2 = _dot(to, to)
            d = np.sqrt(d2)
            wdir = to / d
            ct = -_dot(to, img_nrm[:, j:j + 1]) / d
            cs = _dot(to, normals.take(ok, axis=1)) / d
            keep = np.flatnonzero((cs > 0) & ((ct > 0) | (not targets.front_only)))
            if len(keep) == 0:
                continue
            ok, d, d2, wdir, ct, cs = ok.take(keep), d.take(keep), d2.take(keep), wdir.take(keep, axis=1), \
                ct.take(keep), cs.take(keep)
            lobe = cs
            if brdf is not None:
                mat, arriving = brdf
                lobe = lobe * mat.take(ok).eval(arriving.take(ok, axis=1), normals.take(ok, axis=1), wdir)
            back = -plane.reflect_vectors(wdir)  # from the real target toward y
            f = weights.take(ok) * lobe * targets.response(np.full(len(ok), tgt[j]), ct, back.T) / d2
            _record_mirror(ctx, plane, j, points, shadow_origins, ok, f, d, wdir, paths, mat_rho_m)

def connect_source_mirrors(ctx, sources, i, w0, n_paths):
    """Source -> one mirror reflection -> target: a constant every path of the batch adds."""
    isect = ctx.scene.intersector
    pos = sources.positions[i][:, None]
    nrm = sources.normals[i][:, None]
    one = _SourceVertex(lengths=np.zeros(1), path=np.zeros(1, np.int64), k=np.zeros(1, np.int64),
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

def _record_mirror(ctx, plane, j, points, shadow_origins, ok, f, d, wdir, paths, rho_m):
    """Visibility x -> y (first hit on the plane's mirror faces) and y -> target, rho_m(y); then record."""
    scene, isect, medium = ctx.scene, ctx.scene.intersector, ctx.scene.medium
    sel = np.flatnonzero(f > 0)
    if len(sel) == 0:
        return
    ok, f, d, wdir = ok.take(sel), f.take(sel), d.take(sel), wdir.take(sel, axis=1)
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
    ok, f, d, wdir, t_y, prim = ok.take(sel), f.take(sel), d.take(sel), wdir.take(sel, axis=1), \
        t_y.take(sel), prim.take(sel)
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
    ok, f, d, wdir, t_y, out_dir, y = ok.take(sel), f.take(sel), d.take(sel), wdir.take(sel, axis=1), \
        t_y.take(sel), out_dir.take(sel, axis=1), y.take(sel, axis=1)
    if medium is not None:
        f = f * medium.transmittance(points.take(ok, axis=1).T, wdir.T, t_y) \
            * medium.transmittance(y.T, out_dir.T, d - t_y)
    ctx.out["target"].append(np.full(len(ok), j, np.int64))
    ctx.out["k"].append(paths.k.take(ok) + 1)
    ctx.out["s"].append(paths.s.take(ok))
    ctx.out["delay"].append((paths.lengths.take(ok) + d) * (1.0 / SPEED_OF_LIGHT))
    ctx.out["power"].append(f)
    ctx.out["path"].append(paths.path.take(ok))
