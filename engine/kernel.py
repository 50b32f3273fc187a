"""The shared path-tracing kernel: one batch of paths from one device, NEE to others.

Algorithm 1 (physics.md section 4, report chapter 6) in either direction:
paths leave the source device with pdf proportional to its angular response
(weight = its integrated response), bounce on Lambertian surfaces (cosine
sampling, weight *= rho), and at every surface vertex x_k connect to every target
device (next-event estimation):

    dH = weight * T(segments) * rho/pi * cos(theta_x) * response_target(cos) / d^2 * V * T(d)

tallied at reflection order k and delay (path length + d) / c. Forward: source =
transmitter, targets = receivers; backward: source = receiver (rays within its
FOV), targets = transmitters. The line-of-sight term (k = 0) is computed exactly,
not sampled (see `los.py`). Russian roulette from `rr_start_depth` on, with
survival probability min(1, weight / initial weight), keeps the estimator unbiased.

Every loop here is over bounces; all work inside is one array operation per step.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .constants import SPEED_OF_LIGHT
from .devices import Devices
from .sampling import cosine_about_soa
from .scene import Scene
from .tally import BatchTally, TimeBins, reduce_contributions

#: Upper bound on paths x targets connected in one array operation (memory bound).
NEE_CHUNK = 1 << 20


@dataclass(frozen=True)
class KernelSettings:
    max_reflections: int
    russian_roulette: bool
    rr_start_depth: int
    bins: TimeBins
    n_scatter_orders: int = 1  # scattering orders tallied (0..S-1); 1 for algorithm 1


@dataclass(frozen=True)
class WorkItem:
    """A batch: `n_paths` paths from device `source` of the `direction`'s source set.

    `targets` are indices in the other set; `batch` the batch index for this source;
    `seed_key` spawns the batch's independent random stream (fixed by the job).
    """

    direction: str  # "forward" or "backward"
    source: int
    targets: tuple[int, ...]
    batch: int
    n_paths: int
    seed: int
    phase: int = 0  # 0 = main run, 1 = pilot

    def rng(self) -> np.random.Generator:
        key = (self.phase, 0 if self.direction == "forward" else 1, self.source, self.batch)
        return np.random.default_rng(np.random.SeedSequence(self.seed, spawn_key=key))


def device_sets(scene: Scene, direction: str) -> tuple[Devices, Devices]:
    """(sources, targets) for a direction."""
    if direction == "forward":
        return scene.transmitters, scene.receivers
    return scene.receivers, scene.transmitters


def item_links(scene: Scene, item: WorkItem) -> np.ndarray:
    """Global link index of each of the item's targets."""
    t = np.asarray(item.targets)
    if item.direction == "forward":
        return scene.link(item.source, t)
    return scene.link(t, item.source)


def _dot(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Row-wise dot product of (3, n) component arrays."""
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]


def trace_batch(scene: Scene, item: WorkItem, settings: KernelSettings) -> BatchTally:
    """Trace one batch of paths and return its tally.

    Path state is kept as (3, n) component arrays (contiguous rows: the dot products
    and gathers of the bounce loop run at memory speed); compaction uses index
    arrays and `take`, which numpy runs several times faster than boolean masks.
    """
    rng = item.rng()
    sources, targets = device_sets(scene, item.direction)
    isect, geo, medium = scene.intersector, scene.geometry, scene.medium
    rays0 = (isect.n_intersect, isect.n_occluded)
    med0 = medium.evaluations if medium is not None else 0
    tgt = np.asarray(item.targets, np.int64)
    n, i = item.n_paths, item.source
    forward = item.direction == "forward"
    face_normals = isect.normals_soa
    reflectance = geo.reflectance

    w0 = sources.total_response(i)
    u = rng.random((2, n))
    directions = np.ascontiguousarray(sources.sample_directions(i, u[0], u[1]).T)
    origins = np.repeat((sources.positions[i] + isect.offset * sources.normals[i])[:, None], n, axis=1)
    weights = np.full(n, w0)
    lengths = np.zeros(n)
    path = np.arange(n)
    out = {k: [] for k in ("target", "cell", "delay", "power", "path")}
    n_orders, n_scatter = settings.max_reflections + 1, settings.n_scatter_orders
    surface_power = escaped_power = 0.0

    for depth in range(1, settings.max_reflections + 1):
        # --- intersect -------------------------------------------------------------
        prim, t = isect.intersect(origins.T, directions.T)
        if (prim < 0).any():
            hit = np.flatnonzero(prim >= 0)
            escaped_power += weights.sum() - weights.take(hit).sum()
            prim, t, weights, lengths, path = (a.take(hit) for a in (prim, t, weights, lengths, path))
            origins, directions = origins.take(hit, axis=1), directions.take(hit, axis=1)
        if len(path) == 0:
            break
        points = origins + t * directions
        if medium is not None:
            weights = weights * medium.transmittance(origins.T, directions.T, t)
        lengths = lengths + t
        normals = face_normals.take(prim, axis=1)
        normals *= np.where(_dot(normals, directions) > 0, -1.0, 1.0)  # two-sided: face the arriving ray
        rho = reflectance.take(prim)
        surface_power += weights.sum()
        spawn = points + isect.offset * normals  # where rays leave this surface from

        # --- next-event estimation to every target -----------------------------------
        _connect(scene, targets, tgt, points, spawn, normals, weights * rho * (1.0 / np.pi), lengths, path,
                 depth * n_scatter, n_orders * n_scatter, out)
        if depth == settings.max_reflections:
            break

        # --- Lambertian reflection, then Russian roulette ----------------------------
        weights = weights * rho
        u = rng.random((3, len(path)))
        directions = cosine_about_soa(normals, u[0], u[1])
        origins = spawn
        keep = None
        if settings.russian_roulette and depth >= settings.rr_start_depth:
            q = np.minimum(1.0, weights * (1.0 / w0))
            survive = u[2] < q
            weights = weights / np.where(survive, q, 1.0)
            keep = survive & (weights > 0)
        elif (weights == 0).any():
            keep = weights > 0
        if keep is not None:
            idx = np.flatnonzero(keep)
            weights, lengths, path = (a.take(idx) for a in (weights, lengths, path))
            origins, directions = origins.take(idx, axis=1), directions.take(idx, axis=1)
        if len(path) == 0:
            break

    cat = {k: (np.concatenate(v) if v else np.zeros(0, np.int64 if k in ("target", "cell", "path") else float))
           for k, v in out.items()}
    tally = reduce_contributions(item_links(scene, item), n, settings.bins, n_orders, n_scatter,
                                 cat["target"], cat["cell"], cat["delay"], cat["power"], cat["path"])
    tally.rays_intersect = isect.n_intersect - rays0[0]
    tally.rays_occluded = isect.n_occluded - rays0[1]
    tally.surface_power = surface_power if forward else 0.0
    tally.escaped_power = escaped_power if forward else 0.0
    tally.medium_evaluations = (medium.evaluations - med0) if medium is not None else 0
    return tally


def _connect(scene, targets, tgt, points, spawn, normals, radiance_weight, lengths, path, cell_offset, cell_stride,
             out):
    """NEE from surface points (3, n) to each target: cosines, response, 1/d^2, visibility, extinction.

    `radiance_weight` is weight * rho / pi (outgoing radiance per unit incident power);
    `spawn` the points offset off their surface (shadow-ray origins). A contribution to
    target j lands in tally cell j * cell_stride + cell_offset. Pairs (point, target)
    are flattened so that any number of targets is one array operation.
    """
    isect, medium = scene.intersector, scene.medium
    n_pts, n_tgt = points.shape[1], len(tgt)
    t_pos = np.ascontiguousarray(targets.positions[tgt].T)  # (3, T)
    t_nrm = np.ascontiguousarray(targets.normals[tgt].T)
    step = max(1, NEE_CHUNK // max(n_tgt, 1))
    for lo in range(0, n_pts, step):  # chunks bound memory; one chunk for ordinary batches
        hi = min(lo + step, n_pts)
        if n_tgt == 1:
            pi, ti = np.arange(lo, hi), np.zeros(hi - lo, np.int64)
            to = t_pos - points[:, lo:hi]
            nrm = normals[:, lo:hi]
        else:
            pi = np.repeat(np.arange(lo, hi), n_tgt)
            ti = np.tile(np.arange(n_tgt), hi - lo)
            to = t_pos.take(ti, axis=1) - points.take(pi, axis=1)
            nrm = normals.take(pi, axis=1)
        cs = _dot(to, nrm)  # cos at the surface, times d
        ct = -_dot(to, t_nrm if n_tgt == 1 else t_nrm.take(ti, axis=1))  # cos at the target, times d
        sel = np.flatnonzero((cs > 0) & (ct > 0))
        if len(sel) == 0:
            continue
        pi, ti, cs, ct = pi.take(sel), ti.take(sel), cs.take(sel), ct.take(sel)
        to = to.take(sel, axis=1)
        d2 = _dot(to, to)
        d = np.sqrt(d2)
        f = radiance_weight.take(pi) * (cs / d) * targets.response(tgt.take(ti), ct / d) / d2
        sel = np.flatnonzero(f > 0)
        if len(sel) == 0:
            continue
        pi, ti, f, d = pi.take(sel), ti.take(sel), f.take(sel), d.take(sel)
        wdir = to.take(sel, axis=1) / d
        if not scene.all_visible:
            # The shadow ray stops short of the device, which may sit on a surface itself.
            keep = np.flatnonzero(~isect.occluded(spawn.take(pi, axis=1).T, wdir.T, d - 2.0 * isect.offset))
            pi, ti, f, d, wdir = pi.take(keep), ti.take(keep), f.take(keep), d.take(keep), wdir.take(keep, axis=1)
        if medium is not None:
            f = f * medium.transmittance(points.take(pi, axis=1).T, wdir.T, d)
        out["target"].append(ti)
        out["cell"].append(ti * cell_stride + cell_offset)
        out["delay"].append((lengths.take(pi) + d) * (1.0 / SPEED_OF_LIGHT))
        out["power"].append(f)
        out["path"].append(path.take(pi))
