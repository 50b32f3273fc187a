"""Regions of a participating medium: where along a ray segment the medium is.

A region answers `intervals(origins, directions, lengths)`: the parts [a, b] of each
segment origin + t direction, 0 <= t <= length (unit directions, t in metres) that lie
inside it, as a list of chunks `(ray, a, b)`. Within one chunk a ray appears at most
once, and a ray's intervals come in order along the ray from chunk to chunk. Only
segments that actually cross the region appear (zero-length overlaps are dropped).
Whole scene: one chunk [0, length]; box: one chunk (slab method); closed mesh: one
chunk per pair of boundary crossings, found by closest-hit queries on Embree.
"""

from __future__ import annotations

import warnings

import numpy as np
from embreex import rtcore_scene
from embreex.mesh_construction import TriangleMesh

from owcsim.engine.core.constants import RAY_OFFSET_FACTOR
from owcsim.engine.core.errors import SceneError
from owcsim.engine.core.lazy import trimesh  # imported on first use: it pulls in scipy (issue 10)

Chunk = tuple[np.ndarray, np.ndarray, np.ndarray]  # (ray index, a, b) [m]

#: Boundary crossings followed per segment of a closed-mesh region before giving up (with a warning).
MAX_CROSSINGS = 64


def as_rows(a) -> np.ndarray:
    """(n, 3) float64 from any layout (e.g. the transpose of a (3, n) array), without copying when possible."""
    return np.asarray(a, dtype=np.float64)


def clip_box(origins: np.ndarray, directions: np.ndarray, lengths: np.ndarray, lo: np.ndarray, hi: np.ndarray):
    """Slab method: (t_enter, t_exit) of each segment within the closed box lo..hi; empty where t_exit <= t_enter.

    A zero direction component inside its slab leaves that axis unconstrained, outside
    it empties the interval; a segment starting on a face and leaving the box gets
    t_enter = t_exit = 0.
    """
    t_enter = np.zeros(len(lengths))
    t_exit = np.array(lengths, dtype=np.float64)
    for k in range(3):
        o, d = origins[:, k], directions[:, k]
        with np.errstate(divide="ignore", invalid="ignore"):
            inv = 1.0 / d
            t0, t1 = (lo[k] - o) * inv, (hi[k] - o) * inv
        par = d == 0
        inside = (o >= lo[k]) & (o <= hi[k])
        t_enter = np.maximum(t_enter, np.where(par, np.where(inside, -np.inf, np.inf), np.minimum(t0, t1)))
        t_exit = np.minimum(t_exit, np.where(par, np.where(inside, np.inf, -np.inf), np.maximum(t0, t1)))
    return t_enter, t_exit


class WholeRegion:
    """The medium fills the whole scene."""

    bounds = None

    def intervals(self, origins, directions, lengths) -> list[Chunk]:
        ray = np.flatnonzero(lengths > 0)
        return [(ray, np.zeros(len(ray)), lengths[ray])]

    def contains(self, points: np.ndarray) -> np.ndarray:
        return np.ones(len(points), bool)


class BoxRegion:
    """Axis-aligned box lo..hi [m] (closed)."""

    def __init__(self, lo, hi):
        self.lo, self.hi = np.asarray(lo, np.float64), np.asarray(hi, np.float64)
        self.bounds = (self.lo, self.hi)

    def intervals(self, origins, directions, lengths) -> list[Chunk]:
        t0, t1 = clip_box(origins, directions, lengths, self.lo, self.hi)
        ray = np.flatnonzero(t1 > t0)
        return [(ray, t0[ray], t1[ray])]

    def contains(self, points: np.ndarray) -> np.ndarray:
        return np.all((points >= self.lo) & (points <= self.hi), axis=1)


def _winding_number(points: np.ndarray, tri: np.ndarray) -> np.ndarray:
    """Generalized winding number of a closed oriented triangle mesh `tri` (F, 3, 3) at `points` (P, 3).

    Sum of signed solid angles / 4 pi (Van Oosterom & Strackee 1983): +-1 inside, 0 outside.
    """
    out = np.zeros(len(points))
    for i, p in enumerate(points):
        a, b, c = (tri[:, j] - p for j in range(3))
        la, lb, lc = (np.linalg.norm(x, axis=1) for x in (a, b, c))
        num = np.einsum("ij,ij->i", a, np.cross(b, c))
        den = (
            la * lb * lc
            + np.einsum("ij,ij->i", a, b) * lc
            + np.einsum("ij,ij->i", b, c) * la
            + np.einsum("ij,ij->i", c, a) * lb
        )
        out[i] = 2.0 * np.arctan2(num, den).sum() / (4.0 * np.pi)
    return out


def _orient(faces: np.ndarray, label: str) -> tuple[np.ndarray, np.ndarray]:
    """Consistent winding within each shell of a closed mesh: (faces, shell label per face).

    Two faces sharing an edge are consistent when they run along it in opposite
    directions. Orientation relative to a root face spreads by min-label propagation
    with pointer jumping (vectorized; no graph library needed).
    """
    n = len(faces)
    e = faces[:, [0, 1, 1, 2, 2, 0]].reshape(-1, 2)
    key = np.sort(e, axis=1)
    order = np.lexsort((key[:, 1], key[:, 0]))  # watertight: each edge exactly twice, adjacent after sorting
    ea, eb = order[0::2], order[1::2]
    fa, fb = ea // 3, eb // 3
    flip = e[ea, 0] == e[eb, 0]  # same direction along the shared edge: one of the two must be flipped
    lab, par = np.arange(n), np.zeros(n, bool)  # invariant: par[f] = orientation of f relative to face lab[f]
    while True:
        tgt = np.concatenate([fb, fa])
        cand = np.concatenate([lab[fa], lab[fb]])
        cpar = np.concatenate([par[fa] ^ flip, par[fb] ^ flip])
        better = np.flatnonzero(cand < lab[tgt])
        if len(better) == 0:
            break
        tgt, cand, cpar = tgt[better], cand[better], cpar[better]
        o = np.lexsort((cand, tgt))
        tgt, cand, cpar = tgt[o], cand[o], cpar[o]
        first = np.concatenate([[True], tgt[1:] != tgt[:-1]])
        lab[tgt[first]], par[tgt[first]] = cand[first], cpar[first]
        for _ in range(64):  # pointer jumping: f relative to lab[lab[f]]
            nxt = lab[lab]
            if np.array_equal(nxt, lab):
                break
            par, lab = par ^ par[lab], nxt
    if np.any(par[fa] ^ par[fb] ^ flip):
        raise SceneError(f"{label}: the mesh region is not orientable (it has no consistent inside)")
    faces = np.where(par[:, None], faces[:, ::-1], faces)
    return faces, lab


class MeshRegion:
    """Inside of a closed triangle mesh: points a ray from which crosses the boundary an odd number of times.

    Each closed shell is oriented so that its normals point from inside (odd parity) to
    outside: a shell nested in an even number of others faces outward, in an odd number
    inward (a hollow). A crossing is then an entry or an exit by the sign of
    direction . normal, and an interval counts as inside when it starts at an entry (or
    at a segment origin inside the bounding box) and ends at an exit. This is the parity
    rule wherever Embree reports every crossing, and it fails gracefully where one is
    lost (a ray grazing a silhouette edge): the open interval is counted as outside
    instead of flipping the parity of everything after it. Crossing distances are
    recomputed in float64 against the plane of the hit triangle, so they do not carry
    Embree's float32 rounding. Each query starts a scale-aware offset (1e-6 of the
    region's extent, or of the distance to its centre if larger) past the last crossing,
    so an inside piece shorter than that offset (a ray clipping a corner) can be missed:
    that is the resolution of a mesh region (about 2e-6 m in a 3 m region).
    """

    def __init__(self, vertices, faces, label: str = "medium.region"):
        vertices = np.asarray(vertices, np.float64)
        if not np.all(np.isfinite(vertices)):
            raise SceneError(f"{label}: vertices contain NaN or infinite values")
        mesh = trimesh.Trimesh(vertices, np.asarray(faces, np.int64), process=True)  # merges duplicate vertices
        if len(mesh.faces) == 0 or not mesh.is_watertight:
            raise SceneError(
                f"{label}: the mesh region is not closed (every edge must be shared by exactly two "
                f"triangles), so it has no inside"
            )
        faces, shell = _orient(np.asarray(mesh.faces, np.int64), label)
        tri = np.asarray(mesh.vertices, np.float64)[faces]
        shells = [np.flatnonzero(shell == s) for s in np.unique(shell)]
        for fi in shells:  # outward normals: positive volume
            t = tri[fi] - tri[fi[0], 0]
            if np.einsum("ij,ij->i", t[:, 0], np.cross(t[:, 1], t[:, 2])).sum() < 0:
                tri[fi] = tri[fi][:, ::-1]
        if len(shells) > 1:  # a shell nested in an odd number of others bounds a hollow: normals inward
            box = [(tri[fi].reshape(-1, 3).min(axis=0), tri[fi].reshape(-1, 3).max(axis=0)) for fi in shells]
            flip = []
            for i, fi in enumerate(shells):
                p = tri[fi[0], :1]
                depth = sum(
                    abs(_winding_number(p, tri[fj])[0]) > 0.5
                    for j, fj in enumerate(shells)
                    if j != i and np.all(p >= box[j][0]) and np.all(p <= box[j][1])
                )
                flip.append(depth % 2 == 1)
            for fi, f in zip(shells, flip):
                if f:
                    tri[fi] = tri[fi][:, ::-1]
        self.v0 = tri[:, 0]
        n = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
        self.normals = n / np.linalg.norm(n, axis=1, keepdims=True)
        self.lo, self.hi = tri.reshape(-1, 3).min(axis=0), tri.reshape(-1, 3).max(axis=0)
        self.bounds = (self.lo, self.hi)
        self.center = 0.5 * (self.lo + self.hi)
        self.extent = float(np.max(self.hi - self.lo))
        self._scene = rtcore_scene.EmbreeScene()
        TriangleMesh(self._scene, (tri - self.center).astype(np.float32))

    def _hit(self, origins, directions, start, t_far):
        """First crossing beyond `start` along each ray: (hit?, t from the ray origin, direction . normal).

        The query starts at origin + start * direction; t is exact (float64 plane intersection).
        """
        pos = origins + start[:, None] * directions - self.center
        out = self._scene.run(
            np.ascontiguousarray(pos, np.float32),
            np.ascontiguousarray(directions, np.float32),
            dists=np.asarray(t_far, np.float32).copy(),
            output=1,
        )
        prim = out["primID"].astype(np.int64)
        hit = prim >= 0
        f = np.where(hit, prim, 0)
        nrm = self.normals[f]
        dn = np.einsum("ij,ij->i", directions, nrm)
        with np.errstate(divide="ignore", invalid="ignore"):
            t = np.einsum("ij,ij->i", self.v0[f] - origins, nrm) / dn
        t = np.where(hit & np.isfinite(t), t, start + out["tfar"].astype(np.float64))
        return hit, t, dn

    def _offset(self, origins, directions, t):
        """Scale-aware step past a crossing [m]: ~16x float32 rounding of the query point."""
        r = np.abs(origins + t[:, None] * directions - self.center).max(axis=1)
        return RAY_OFFSET_FACTOR * np.maximum(np.maximum(r, self.extent), 1e-3)

    def intervals(self, origins, directions, lengths) -> list[Chunk]:
        t_enter, t_exit = clip_box(origins, directions, lengths, self.lo, self.hi)
        ids: np.ndarray = np.flatnonzero(t_exit > t_enter)  # segments that never meet the bounding box cost nothing
        o, d, L = origins[ids], directions[ids], lengths[ids]
        t_start: np.ndarray = np.zeros(len(ids))  # start of the current interval
        # Whether it may be inside: at an entry, or at an origin inside the bounding box (one outside it is outside).
        opened: np.ndarray = np.all((o >= self.lo) & (o <= self.hi), axis=1)
        t_query: np.ndarray = np.zeros(len(ids))  # the next query begins here
        chunks = []
        for _ in range(MAX_CROSSINGS):
            if len(ids) == 0:
                break
            # An open interval needs its closing crossing, even beyond the segment; a closed one only up to L.
            t_far = np.where(opened, 1e30, L - t_query + self._offset(o, d, t_query))
            hit, t, dn = self._hit(o, d, t_query, t_far)
            new = hit & (t > t_start) & (dn != 0)  # not the crossing we just stepped past, not grazing
            close = new & opened & (dn > 0)
            b = np.minimum(t, L)
            sel = np.flatnonzero(close & (b > t_start))
            if len(sel):
                chunks.append((ids[sel], t_start[sel], b[sel]))
            t_start = np.where(new, t, t_start)
            opened = np.where(new, dn < 0, opened)
            t_query = np.maximum(t, t_query)  # (rays that missed are dropped below)
            t_query = t_query + self._offset(o, d, t_query)
            keep = np.flatnonzero(hit & (t < L))
            ids, o, d, L, t_start, opened, t_query = (x[keep] for x in (ids, o, d, L, t_start, opened, t_query))
        if len(ids):
            warnings.warn(
                f"{len(ids)} segments cross the mesh region more than {MAX_CROSSINGS} times; "
                f"their remaining length is counted as outside",
                stacklevel=3,
            )
        return chunks

    def contains(self, points: np.ndarray) -> np.ndarray:
        """Inside test: the first crossing along a fixed oblique direction is an exit."""
        p = as_rows(points)
        inside = np.zeros(len(p), bool)
        ids = np.flatnonzero(np.all((p >= self.lo) & (p <= self.hi), axis=1))
        d = np.broadcast_to(np.array([0.5773502691896258, 0.5773502691896257, 0.5773502691896259]), (len(ids), 3))
        hit, _, dn = self._hit(p[ids], d, np.zeros(len(ids)), np.full(len(ids), 1e30))
        inside[ids] = hit & (dn > 0)
        return inside
