"""The shared path-tracing kernel: one batch of paths from one device, NEE to others.

The five algorithms of physics.md section 4 are configurations of this one loop.
Paths leave the source device with pdf proportional to its angular response
(weight = its integrated response). Forward: source = transmitter, targets =
receivers; backward: source = receiver (rays within its FOV), targets =
transmitters. The channel gain is symmetric in the two devices, so the same code
serves both directions. Each step intersects the surfaces, then:

- surface vertex x (reflection k): next-event estimation (NEE) to every target,
      dH = w * rho/pi * cos(theta_x) * R_target(cos) / d^2 * V * T(x -> target),
  tallied at (k, s); then Lambertian reflection (cosine sampling, w *= rho);
  with materials (bsdf.py: Phong, mirror) rho/pi becomes the BRDF f(incoming, toward
  target), the outgoing direction is sampled from a lobe chosen by albedo, and planar
  mirrors reach the targets through their images (`mirrors.connect_mirrors`);
- algorithm 1: every segment multiplies w by its transmittance T (extinction only);
- algorithms 2-4 (`segment_scatter`): points p on each segment (time strata, see
  segments.py) connect to the targets with one scattering event,
      dH = w * T(o -> p) * sigma_s(p) * phase(cos) * R_target / d^2 * V * T(p -> target) * |stratum|,
  tallied at (k, 1); the path itself stays unscattered (s = 0). Forward this is
  algorithm 3 (Tx -> k reflections -> p -> Rx), backward algorithm 2
  (Tx -> p -> k reflections -> Rx). Run from both devices (`mis`), the shared family
  (k = 0: Tx -> p -> Rx) is weighted by the balance heuristic, and each device also
  scatters on its own first segment (single_scatter.first_segment_branch) to sample the
  other side's family, shared by a path partition of unity with bounded weights near
  the devices; algorithm 4 adds the double-scattering family Tx -> p_in -> (k) ->
  p_out -> Rx at (k, 2) (single_scatter.py);
- algorithm 5 (`free_flight`): the collision distance is sampled (regular tracking
  of the medium's optical depth); a collision before the surface is a medium vertex:
  w *= albedo, new direction from the phase function. NEE with the phase function at
  (k, s + 1) from the collision and from `equiangular_points` equiangular points of the
  segment, combined by the balance heuristic (segments.scattering_point_throughput). Surface
  vertices keep w (T / P(no collision) = 1). Run from both
  devices (`both_sides`), every connection is weighted by the partition of unity of
  weights.py (bounded weights near point devices).
With a peaked phase function (KernelSettings.phase_lobe) the source also samples the phase lobe about
the axis toward each target for Tx -> p -> Rx, once per path before the first step
(lobe.lobe_connections), and the first vertices' shares make room for it.
The phase cosine is dot(ray direction, direction to the target) in both directions
(the phase functions are symmetric). The line-of-sight term (k = s = 0) is exact
and never sampled (los.py). Russian roulette from `rr_start_depth` (k + s) on, with
survival probability min(1, w / (theta initial w)) (`rr_threshold` theta), keeps every
estimator unbiased.

Code map (one module per kind of part, imports only downward; one section per event, as in pbrt-v4's
VolPathIntegrator and Mitsuba 3's volpath):
- path.py: the path state (`Paths`, a structure of arrays), `KernelSettings`, `WorkItem`, `BatchState`;
- segments.py: points on segments (time strata, equiangular points, their densities);
- weights.py: the device factors and the partition of unity of runs from both devices;
- lobe.py: the phase-lobe strategy;
- uniform_medium.py, context.py: next-event estimation in one home (`BatchContext.connect`, the
  measurement equation: it evaluates the BRDF or the phase function itself, callers pass a `Vertices`
  description with the path throughput and their weights; algorithm 5's scattering points in a medium
  the same everywhere take its medium branch on their segments' equiangular frames,
  `uniform_medium.connect_on_segments`, tests/engine/test_medium_next_events.py holds the two equal);
- mirrors.py: connections through perfect-mirror images;
- single_scatter.py: the segment-points event of algorithms 2-4 and their branch from the first segment;
- events.py: surface vertex, medium next events, medium collision, roulette;
- kernel.py (here): `trace_batch`, the loop over steps calling the events.

Every loop here is over steps of the paths; all work inside is array operations.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from owcsim.engine.core import qmc
from owcsim.engine.core.allocator import tune_allocator
from owcsim.engine.core.arrays import FloatArray, IntArray
from owcsim.engine.core.sampling import sample_cosine_cone, to_world
from owcsim.engine.integrator.context import BatchContext
from owcsim.engine.integrator.events import medium_collision, medium_next_events, surface_vertex
from owcsim.engine.integrator.lobe import lobe_connections
from owcsim.engine.integrator.mirrors import connect_source_mirrors
from owcsim.engine.integrator.path import KernelSettings, Paths, WorkItem, device_sets
from owcsim.engine.integrator.single_scatter import segment_scatter
from owcsim.engine.integrator.uniform_medium import EquiangularFrames
from owcsim.engine.integrator.weights import first_vertex_factor
from owcsim.engine.scene.scene import Scene
from owcsim.engine.sources.devices import Devices
from owcsim.engine.tally.tally import BatchTally
from owcsim.schemas.algorithms import Direction


@dataclass
class _PowerBalance:
    """The power balance of the result's diagnostics (forward runs) [W/W]: reaching surfaces, leaving the scene."""

    surface: float = 0.0
    escaped: float = 0.0


def trace_batch(scene: Scene, item: WorkItem, settings: KernelSettings) -> BatchTally:
    """Trace one batch of paths and return its tally.

    Each step of the loop is one segment of every live path, handled event by event
    (`_step`): intersect, segment points (algorithms 2-4), free flight and its
    equiangular partner (algorithm 5), surface vertex, medium collision, roulette. Every
    next-event estimate goes through `BatchContext.connect` (the measurement equation).
    """
    tune_allocator()  # once per process: the step's temporaries reuse heap memory (engine/core/allocator.py)
    rng = item.rng()
    sources, targets = device_sets(scene, item.direction)
    isect, medium = scene.intersector, scene.medium
    rays0 = (isect.n_intersect, isect.n_occluded)
    med0 = medium.evaluations if medium is not None else 0
    forward = item.direction is Direction.FORWARD
    ctx = BatchContext(scene, targets, np.asarray(item.targets, np.int64), settings, item)
    ctx.start_tally(item)
    paths, first_u = _emit(ctx, item, rng)
    power = _PowerBalance()
    for step in range(settings.max_reflections + settings.max_scattering + 2):
        paths = _step(ctx, paths, step, first_u, rng, power)
        ctx.flush(step + 1)  # the estimates of cells of depth k + s = step + 1 are complete
        if len(paths) == 0:
            break

    tally = ctx.reduce(item.n_paths)
    tally.rays_intersect = isect.n_intersect - rays0[0]
    tally.rays_occluded = isect.n_occluded - rays0[1]
    tally.surface_power = power.surface if forward else 0.0
    tally.escaped_power = power.escaped if forward else 0.0
    tally.medium_evaluations = (medium.evaluations - med0) if medium is not None else 0
    return tally


def _emit(ctx: BatchContext, item: WorkItem, rng: np.random.Generator) -> tuple[Paths, FloatArray | None]:
    """Emission: directions with pdf R_source / W_source, throughput W_source; the source's mirror paths and
    the phase lobe. Returns the paths and the (5, n) quasi-random uniforms of their first dimensions (None:
    pseudo-random)."""
    scene, settings = ctx.scene, ctx.settings
    sources, _ = device_sets(scene, item.direction)
    isect, medium = scene.intersector, scene.medium
    n, i = item.n_paths, item.source
    w0 = ctx.w0 = sources.total_response(i)
    two_sided = settings.mis or settings.both_sides
    block = 1 if item.packed else qmc.block_size(n, settings.qmc_block)  # packed: pseudo-random paths
    if block > 1:
        first_u = qmc.shifted_blocks(n, block, rng)  # (5, n)
        u = first_u[:2]
    else:
        first_u, u = None, rng.random((2, n))
    if item.packed:  # several receivers of one field of view and gain (engine/run/allocation.py): their origins
        src, counts = np.asarray(item.sources, np.int64), np.asarray(item.counts, np.int64)
        origins = np.repeat((sources.positions[src] + isect.offset * sources.normals[src]).T, counts, axis=1)
        directions = _packed_directions(sources, src, counts, u)
    else:
        origins = np.repeat((sources.positions[i] + isect.offset * sources.normals[i])[:, None], n, axis=1)
        directions = np.ascontiguousarray(sources.sample_directions(i, u[0], u[1]).T)
    paths = Paths(
        directions=directions,
        origins=origins,
        weights=np.full(n, w0),
        lengths=np.zeros(n),
        path=np.arange(n),
        k=np.zeros(n, np.int64),
        s=np.zeros(n, np.int64),
        first=np.zeros(n) if two_sided else None,
        first_rho=np.full(n, 1.0 / np.pi) if two_sided else None,
        ratio=ctx.ratios.initial_ratio(n) if ctx.ratios is not None else np.ones((0, n)),
    )
    # source -> mirror -> target (order k = 1, none when K = 0): the same for every path; half each from both devices
    if ctx.mirrors and settings.max_reflections >= 1:
        connect_source_mirrors(ctx, sources, i, w0 * (0.5 if settings.mis or settings.both_sides else 1.0), n)
    free_flight = settings.free_flight and medium is not None
    points_on_segments = settings.segment_scatter and medium is not None
    if settings.phase_lobe and (free_flight or points_on_segments and settings.mis):
        lobe_connections(ctx, n, rng, segments=not free_flight)  # Tx -> p -> Rx from the phase lobe (lobe.py)
    return paths, first_u


def _packed_directions(sources: Devices, src: IntArray, counts: IntArray, u: FloatArray) -> FloatArray:
    """(3, n) emission directions of a packed batch's paths: about their sources' one normal (Devices
    .sample_directions), or, when the receivers face different ways (random orientation, several planes),
    each path about its own receiver's normal with the same pdf (the cone of the shared field of view)."""
    normals = sources.normals[src]
    if not np.ptp(normals, axis=0).any():
        return np.ascontiguousarray(sources.sample_directions(int(src[0]), u[0], u[1]).T)
    local = sample_cosine_cone(sources.cos_fov[src[0]], u[0], u[1])  # (n, 3); receivers: the FOV cone
    return np.ascontiguousarray(to_world(local, np.repeat(normals, counts, axis=0)).T)


def _step(
    ctx: BatchContext,
    paths: Paths,
    step: int,
    first_u: FloatArray | None,
    rng: np.random.Generator,
    power: _PowerBalance,
) -> Paths:
    """One segment of every live path, event by event; returns the paths that go on (each event applied
    Russian roulette, events.roulette)."""
    scene, settings = ctx.scene, ctx.settings
    isect, medium = scene.intersector, scene.medium
    forward = ctx.item.direction is Direction.FORWARD
    K, S = settings.max_reflections, settings.max_scattering
    free_flight = settings.free_flight and medium is not None
    points_on_segments = settings.segment_scatter and medium is not None
    far = scene.medium_far_distance  # segments that leave the scene run to where the medium has absorbed all
    # ====== intersect ======================================================================================
    prim, t = isect.intersect(paths.origins.T, paths.directions.T)
    hit = prim >= 0
    t_seg = np.where(hit, t, far) if medium is not None else t
    # ====== segment points (algorithms 2-4): single scattering at points along the segment ================
    if points_on_segments:
        segment_scatter(ctx, paths, t_seg, rng, first=step == 0, prim=prim)
    if step == 0 and settings.mis and not points_on_segments:  # no medium: segment_scatter does not set it
        paths.first = first_vertex_factor(ctx, paths, prim, t, np.zeros(len(t)), np.zeros(len(t), bool))
    # ====== free flight (algorithm 5): collision distance; NEE from the collision and equiangular points =====
    collided = None
    ctx.first_bounce_u = first_u[3:5] if first_u is not None and step == 0 else None
    if free_flight:
        assert medium is not None  # free_flight holds only with a medium
        u_ff = first_u[2] if first_u is not None and step == 0 else rng.random(len(paths))
        t_col, collided = medium.sample_distance(paths.origins.T, paths.directions.T, t_seg, u_ff)
        if settings.both_sides and step == 0:
            paths.first = first_vertex_factor(ctx, paths, prim, t, t_col, collided)
        frames = EquiangularFrames(ctx, paths, t_seg) if settings.equiangular_points else None
        medium_rows = (collided & (paths.s < S)).nonzero()[0]
        medium_next_events(ctx, paths, frames, medium_rows, t_col.take(medium_rows), rng)
        if ctx.ratios is not None and ctx.ratios.depth_row:  # bands or frames: T_b / T_c of the flight
            flown = (hit & ~collided & (paths.k < K)).nonzero()[0]  # (its collisions: `medium_collision`)
            if len(flown):
                flight = (paths.origins.take(flown, axis=1).T, paths.directions.take(flown, axis=1).T, t.take(flown))
                paths.ratio = ctx.ratios.transmit_rows(paths.ratio, flown, medium.optical_depth(*flight), flight)
    elif medium is not None:  # algorithm 1 (and 2-4): the segment's extinction
        tau = medium.optical_depth(paths.origins.T, paths.directions.T, t_seg)
        paths.weights = paths.weights * np.exp(-tau)  # = medium.transmittance
        if ctx.ratios is not None:  # bands: the carrier depth travelled; frames: T_f / T_c (spectra.py)
            paths.ratio = ctx.ratios.transmit(paths.ratio, tau, (paths.origins.T, paths.directions.T, t_seg))
    at_surface = hit if collided is None else hit & ~collided
    if forward:  # the power balance of the result's diagnostics (forward runs)
        power.escaped += paths.weights[~hit if collided is None else ~hit & ~collided].sum()
    survivors = []
    # ====== surface vertex =================================================================================
    on_surface = at_surface & (paths.k < K)
    if on_surface.all():  # the usual step of a closed room: no index arrays
        sp, sp_prim, sp_t = paths, prim, t
    else:
        surface_rows = on_surface.nonzero()[0]
        sp, sp_prim, sp_t = paths.gather(surface_rows), prim.take(surface_rows), t.take(surface_rows)
    if len(sp):
        if forward:
            power.surface += sp.weights.sum()
        survivors.append(surface_vertex(ctx, sp, sp_prim, sp_t, rng))
    # ====== medium collision (algorithm 5) ==================================================================
    if free_flight and len(medium_rows):
        survivors.append(medium_collision(ctx, paths, medium_rows, t_col.take(medium_rows), rng))
    # ====== next step: the survivors ========================================================================
    return Paths.concat(survivors) if survivors else paths.gather(np.zeros(0, np.int64))
