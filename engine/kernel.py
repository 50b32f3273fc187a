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
from .sampling import sample_cosine_about
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


def trace_batch(scene: Scene, item: WorkItem, settings: KernelSettings) -> BatchTally:
    """Trace one batch of paths and return its tally."""
    rng = item.rng()
    sources, targets = device_sets(scene, item.direction)
    isect, geo, medium = scene.intersector, scene.geometry, scene.medium
    rays0 = (isect.n_intersect, isect.n_occluded)
    med0 = medium.evaluations if medium is not None else 0
    tgt = np.asarray(item.targets, np.int64)
    t_pos, t_nrm = targets.positions[tgt], targets.normals[tgt]
    n, i = item.n_paths, item.source
    forward = item.direction == "forward"

    w0 = sources.total_response(i)
    u = rng.random((n, 2))
    directions = sources.sample_directions(i, u[:, 0], u[:, 1])
    origins = np.broadcast_to(sources.positions[i] + isect.offset * sources.normals[i], (n, 3)).copy()
    weights = np.full(n, w0)
    lengths = np.zeros(n)
    path = np.arange(n)
    out = {k: [] for k in ("target", "order", "delay", "power", "path")}
    surface_power = escaped_power = 0.0

    for depth in range(1, settings.max_reflections + 1):
        # --- intersect -------------------------------------------------------------
        prim, t = isect.intersect(origins, directions)
        hit = prim >= 0
        escaped_power += weights[~hit].sum()
        if not hit.all():
            prim, t, origins, directions, weights, lengths, path = (
                a[hit] for a in (prim, t, origins, directions, weights, lengths, path))
        if len(path) == 0:
            break
        points = origins + t[:, None] * directions
        if medium is not None:
            weights = weights * medium.transmittance(origins, directions, t)
        lengths = lengths + t
        normals = isect.normals[prim]
        flip = np.einsum("ij,ij->i", normals, directions) > 0
        normals[flip] *= -1.0  # two-sided surfaces: shade on the side the ray arrives from
        rho = geo.reflectance[prim]
        surface_power += weights.sum()

        spawn = points + isect.offset * normals  # where rays leave this surface from

        # --- next-event estimation to every target -----------------------------------
        _connect(scene, targets, tgt, t_pos, t_nrm, points, spawn, normals, weights * rho / np.pi,
                 lengths, path, depth, out)
        if depth == settings.max_reflections:
            break

        # --- Lambertian reflection, then Russian roulette ----------------------------
        weights = weights * rho
        u = rng.random((len(path), 3))
        directions = sample_cosine_about(normals, u[:, 0], u[:, 1])
        origins = spawn
        alive = weights > 0
        if settings.russian_roulette and depth >= settings.rr_start_depth:
            q = np.minimum(1.0, weights / w0)
            alive &= u[:, 2] < q
            weights = weights / np.where(alive, q, 1.0)
        if not alive.all():
            origins, directions, weights, lengths, path = (
                a[alive] for a in (origins, directions, weights, lengths, path))
        if len(path) == 0:
            break

    cat = {k: (np.concatenate(v) if v else np.zeros(0)) for k, v in out.items()}
    n_cont = len(cat["power"])
    tally = reduce_contributions(
        item_links(scene, item), n, settings.bins, settings.max_reflections + 1, settings.n_scatter_orders,
        cat["target"].astype(np.int64), cat["order"].astype(np.int64), np.zeros(n_cont, np.int64),
        cat["delay"], cat["power"], cat["path"].astype(np.int64))
    tally.rays_intersect = isect.n_intersect - rays0[0]
    tally.rays_occluded = isect.n_occluded - rays0[1]
    tally.surface_power = surface_power if forward else 0.0
    tally.escaped_power = escaped_power if forward else 0.0
    tally.medium_evaluations = (medium.evaluations - med0) if medium is not None else 0
    return tally


def _connect(scene, targets, tgt, t_pos, t_nrm, points, spawn, normals, radiance_weight, lengths, path, depth, out):
    """NEE from surface points to each target: visibility, cosines, response, 1/d^2, extinction.

    `radiance_weight` is weight * rho / pi (outgoing radiance per unit incident power);
    `spawn` the points offset off their surface (shadow-ray origins).
    """
    isect, medium = scene.intersector, scene.medium
    n_pts, n_tgt = len(points), len(tgt)
    step = max(1, NEE_CHUNK // max(n_tgt, 1))
    for lo in range(0, n_pts, step):  # chunks bound memory; one chunk for ordinary batches
        sl = slice(lo, lo + step)
        to = t_pos[None, :, :] - points[sl, None, :]  # (n, T, 3), unnormalized
        d2 = np.einsum("ntk,ntk->nt", to, to)
        d = np.sqrt(d2)
        cos_s = np.einsum("ntk,nk->nt", to, normals[sl]) / d
        cos_t = -np.einsum("ntk,tk->nt", to, t_nrm) / d
        f = (radiance_weight[sl, None] / d2) * np.maximum(cos_s, 0.0) * targets.response(tgt[None, :], cos_t)
        flat = np.flatnonzero(f > 0)
        if len(flat) == 0:
            continue
        pi, ti = (flat, np.zeros(len(flat), np.int64)) if n_tgt == 1 else np.divmod(flat, n_tgt)
        f, d = f.ravel()[flat], d.ravel()[flat]
        wdir = to.reshape(-1, 3)[flat] / d[:, None]
        gi = pi + lo
        if not scene.all_visible:
            # The shadow ray stops short of the device, which may sit on a surface itself.
            keep = ~isect.occluded(spawn[gi], wdir, d - 2.0 * isect.offset)
            gi, ti, f, d, wdir = gi[keep], ti[keep], f[keep], d[keep], wdir[keep]
        if medium is not None:
            f = f * medium.transmittance(points[gi], wdir, d)
        out["target"].append(ti)
        out["order"].append(np.full(len(gi), depth))
        out["delay"].append((lengths[gi] + d) / SPEED_OF_LIGHT)
        out["power"].append(f)
        out["path"].append(path[gi])
