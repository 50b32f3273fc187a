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
  mirrors reach the targets through their images (`connect_mirrors`);
- algorithm 1: every segment multiplies w by its transmittance T (extinction only);
- algorithms 2-4 (`segment_scatter`): points p on each segment (time strata, see
  segments.py) connect to the targets with one scattering event,
      dH = w * T(o -> p) * sigma_s(p) * phase(cos) * R_target / d^2 * V * T(p -> target) * |stratum|,
  tallied at (k, 1); the path itself stays unscattered (s = 0). Forward this is
  algorithm 3 (Tx -> k reflections -> p -> Rx), backward algorithm 2
  (Tx -> p -> k reflections -> Rx). Run from both devices (`mis`), the shared family
  (k = 0: Tx -> p -> Rx) is weighted by the balance heuristic, and each device also
  scatters on its own first segment (medium_nee.first_segment_branch) to sample the
  other side's family, shared by a path partition of unity with bounded weights near
  the devices; algorithm 4 adds the double-scattering family Tx -> p_in -> (k) ->
  p_out -> Rx at (k, 2) (medium_nee.py);
- algorithm 5 (`free_flight`): the collision distance is sampled (regular tracking
  of the medium's optical depth); a collision before the surface is a medium vertex:
  w *= albedo, new direction from the phase function. NEE with the phase function at
  (k, s + 1) from the collision and from `equiangular_points` equiangular points of the
  segment, combined by the balance heuristic (`_scattering_point_throughput`). Surface
  vertices keep w (T / P(no collision) = 1). Run from both
  devices (`both_sides`), every connection is weighted by the partition of unity of
  medium_nee.py (bounded weights near point devices).
With a peaked phase function (KernelSettings.phase_lobe) the source also samples the phase lobe about
the axis toward each target for Tx -> p -> Rx, once per path before the first step
(medium_nee.lobe_connections), and the first vertices' shares make room for it.
The phase cosine is dot(ray direction, direction to the target) in both directions
(the phase functions are symmetric). The line-of-sight term (k = s = 0) is exact
and never sampled (los.py). Russian roulette from `rr_start_depth` (k + s) on, with
survival probability min(1, w / (theta initial w)) (`rr_threshold` theta), keeps every
estimator unbiased.

Code map (one section per event, as in pbrt-v4's VolPathIntegrator and Mitsuba 3's volpath):
`trace_batch` runs the steps: intersect, segment points (segments.segment_scatter),
free flight with its next-event estimates (`_medium_next_events`, whose balance heuristic is
`_scattering_point_throughput`), surface vertex (`_surface_vertex`), medium collision
(`_medium_collision`), roulette (`_roulette`, inside each event's one compaction). Every
next-event estimate toward a target goes through `_Context.connect`: the measurement equation
in one place (it evaluates the BRDF or the phase function itself; callers pass the path
throughput and their MIS weight); algorithm 5's scattering points in a medium the same everywhere
take its medium branch on their segments' equiangular frames (`_Context.connect_on_segments`, the
same equation without gathering the paths; tests/engine/test_medium_next_events.py holds the two
equal). Path state is a structure of arrays (`_Paths`).

Every loop here is over steps of the paths; all work inside is array operations.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from owcsim.engine.core import qmc
from owcsim.engine.core.allocator import tune_allocator
from owcsim.engine.core.constants import SPEED_OF_LIGHT
from owcsim.engine.core.sampling import cosine_about_soa
from owcsim.engine.integrator.medium_nee import (
    connect_from_target,
    connection_weight,
    first_medium_factor,
    first_vertex_factor,
    lobe_axis,
    lobe_connections,
    lobe_source_density,
    side_weight,
)
from owcsim.engine.integrator.mirrors import connect_mirrors, connect_source_mirrors
from owcsim.engine.integrator.segments import EquiangularFrame, segment_scatter
from owcsim.engine.scene.scene import Scene
from owcsim.engine.sources.devices import Devices
from owcsim.engine.tally.spectral import ChannelBuilder
from owcsim.engine.tally.tally import BatchBuilder, BatchTally, TallyPlan, TimeBins
from owcsim.schemas.algorithms import Direction

#: Upper bound on paths x targets connected in one array operation (memory bound).
NEE_CHUNK = 1 << 20
#: Steps with at most this many segments connect their scattering points as one group (`connect_on_segments`)
SMALL_STEP = 2048


@dataclass(frozen=True)
class KernelSettings:
    max_reflections: int  # K
    russian_roulette: bool
    rr_start_depth: int
    tally: TallyPlan
    max_scattering: int = 0  # S: 0 for algorithm 1, 1 for 2-4, S for 5
    free_flight: bool = False  # algorithm 5
    segment_scatter: bool = False  # algorithms 2-4
    strata_length: float = 0.0  # [m] path-length width of the time strata (c dt)
    max_strata: int = 64
    equiangular_points: int = 2  # per segment and target, combined with the time strata (balance heuristic)
    #: algorithms 2-4 run from both devices: balance heuristic on the family both directions sample
    #: (k = 0), path partition of unity on the others (medium_nee.py)
    mis: bool = False
    #: which single-scattering family algorithms 2-4 estimate: 2 (Tx -> p -> k -> Rx), 3 (Tx -> k -> p -> Rx), 4 (both)
    segment_family: int = 4
    #: algorithm 5 run from both devices: every connection is weighted by the path partition of unity
    #: of medium_nee.side_weight (bounded weights near point devices)
    both_sides: bool = False
    #: roulette threshold theta: survival min(1, w / (theta w0)); paths above theta w0 always survive
    rr_threshold: float = 0.25  # measured: benchmarks/replicate_study.py --study roulette (docs/smoke-error-bars.md)
    #: a peaked phase function: the source also samples the phase lobe about the axis toward each target for
    #: Tx -> p -> Rx (medium_nee.lobe_connections, balance heuristic): algorithm 5 (from either side or both),
    #: algorithms 2-4 from both devices
    phase_lobe: bool = False
    #: paths per block of randomly shifted Sobol points for the first dimensions of each path (emission
    #: direction, first free-flight distance, first bounce direction; engine/core/qmc.py); a batch that is not a
    #: whole number of blocks, or qmc_block <= 1, draws pseudo-random numbers. Blocks are independent, the
    #: paths in a block are not: the tallies take a block as one sample of the standard errors (tally.py).
    qmc_block: int = qmc.BLOCK
    #: tallies per target: 1, or 1 + the channels of a spectral scene (engine/spectral/spectra.py); bounds batch memory
    tally_channels: int = 1

    @property
    def in_then_out(self) -> bool:
        """Algorithm 4 with S = 2: the double-scattering family Tx -> p_in -> (k) -> p_out -> Rx (medium_nee.py)."""
        return self.segment_scatter and self.mis and self.max_scattering >= 2

    @property
    def n_scatter_orders(self) -> int:
        return self.max_scattering + 1

    @property
    def bins(self) -> TimeBins:
        return self.tally.bins


@dataclass(frozen=True)
class WorkItem:
    """A batch: `n_paths` paths from device `source` of the `direction`'s source set.

    `targets` are indices in the other set; `batch` the batch index for this source;
    `seed_key` spawns the batch's independent random stream (fixed by the job).
    """

    direction: Direction  # FORWARD or BACKWARD (its value is accepted too)
    source: int
    targets: tuple[int, ...]
    batch: int
    n_paths: int
    seed: int
    phase: int = 0  # 0 = main run, 1 = pilot

    def __post_init__(self) -> None:
        object.__setattr__(self, "direction", Direction(self.direction))  # one spelling: the enum

    def rng(self) -> np.random.Generator:
        key = (self.phase, self.direction.code, self.source, self.batch)
        return np.random.default_rng(np.random.SeedSequence(self.seed, spawn_key=key))


def device_sets(scene: Scene, direction: Direction) -> tuple[Devices, Devices]:
    """(sources, targets) of paths run in `direction` (forward: from the transmitters)."""
    if direction is Direction.FORWARD:
        return scene.transmitters, scene.receivers
    return scene.receivers, scene.transmitters


def item_links(scene: Scene, item: WorkItem) -> np.ndarray:
    """Global link index of each of the item's targets."""
    t = np.asarray(item.targets)
    if item.direction is Direction.FORWARD:
        return scene.link(item.source, t)
    return scene.link(t, item.source)


def _dot(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Row-wise dot product of (3, n) component arrays (a[0] b[0] + a[1] b[1] + a[2] b[2], two temporaries)."""
    out = a[0] * b[0]
    term = a[1] * b[1]
    out += term
    np.multiply(a[2], b[2], out=term)
    out += term
    return out


def _dot_vector(a: np.ndarray, v: np.ndarray) -> np.ndarray:
    """dot(a, v) of (3, n) component rows with one vector v (3,), its zero components skipped (devices
    facing along an axis: one pass instead of five; x * 0 adds exactly nothing to a finite sum)."""
    terms = [(a[i], float(v[i])) for i in range(3) if v[i] != 0.0]
    if not terms:
        return np.zeros(a.shape[1])
    row, c = terms[0]
    out = row * c if c != 1.0 else row.copy()
    for row, c in terms[1:]:
        out += row * c if c != 1.0 else row
    return out


class _Paths:
    """Path state as a structure of arrays: (3, n) component arrays and (n,) arrays, one row per path.

    A new per-path quantity is one more name in FIELDS (and one more keyword where the batch starts);
    `gather(idx)` compacts every field with one index array (`take`, several times faster than a mask).
    """

    #: `weights`: the path throughput (power per watt carried so far, divided by the sampling densities);
    #: `first`: the source-side density factor of the path's first vertex (medium_nee.first_vertex_factor);
    #: `first_rho`: the direction density of leaving it (phase, or 1/pi at a surface; medium_nee.side_weight);
    #: both None unless the run shares paths with the other device's (KernelSettings.mis, both_sides)
    #: `ratio`: (B, n) per-band throughput over the carrier's of spectral scenes, (0, n) otherwise (spectra.py)
    FIELDS = ("origins", "directions", "weights", "lengths", "path", "k", "s", "first", "first_rho", "ratio")
    origins: np.ndarray  # (3, n) [m]
    directions: np.ndarray  # (3, n) unit
    weights: np.ndarray  # (n,) path throughput
    lengths: np.ndarray  # (n,) path length so far [m]
    path: np.ndarray  # (n,) index of the path in the batch
    k: np.ndarray  # (n,) reflections so far
    s: np.ndarray  # (n,) scattering events so far
    first: np.ndarray | None
    first_rho: np.ndarray | None
    ratio: np.ndarray  # (B, n) band ratios (+ a carrier-depth row), or (0, n): spectra.SceneSpectra

    def __init__(self, **arrays):
        for name in self.FIELDS:
            setattr(self, name, arrays[name])

    def __len__(self) -> int:
        return len(self.weights)

    @staticmethod
    def _of(fields: dict) -> "_Paths":
        """A _Paths from a complete field dict, without the keyword machinery (a step makes several)."""
        out = object.__new__(_Paths)
        out.__dict__.update(fields)
        return out

    def gather(self, idx) -> "_Paths":
        """The paths at rows `idx` (any order, repeats allowed), every field gathered once (None stays None)."""
        return _Paths._of({f: None if a is None else a.take(idx, axis=-1) for f, a in self.__dict__.items()})

    keep = gather

    def keep_where(self, mask) -> "_Paths":
        """The paths where `mask` holds; free when it holds everywhere."""
        if mask.all():
            return _Paths._of(dict(self.__dict__))
        return self.gather(mask.nonzero()[0])

    @staticmethod
    def concat(parts) -> "_Paths":
        if len(parts) == 1:
            return parts[0]
        return _Paths._of(
            {
                f: None if a is None else np.concatenate([p.__dict__[f] for p in parts], axis=-1)
                for f, a in parts[0].__dict__.items()
            }
        )


def trace_batch(scene: Scene, item: WorkItem, settings: KernelSettings) -> BatchTally:
    """Trace one batch of paths and return its tally.

    Each step of the loop is one segment of every live path, handled event by event
    (the sections below): intersect, segment points (algorithms 2-4), free flight and its
    equiangular partner (algorithm 5), surface vertex, medium collision, roulette. Every
    next-event estimate goes through `_Context.connect` (the measurement equation).
    """
    tune_allocator()  # once per process: the step's temporaries reuse heap memory (engine/core/allocator.py)
    rng = item.rng()
    sources, targets = device_sets(scene, item.direction)
    isect, medium = scene.intersector, scene.medium
    rays0 = (isect.n_intersect, isect.n_occluded)
    med0 = medium.evaluations if medium is not None else 0
    n, i = item.n_paths, item.source
    forward = item.direction == "forward"
    K, S = settings.max_reflections, settings.max_scattering
    free_flight = settings.free_flight and medium is not None
    points_on_segments = settings.segment_scatter and medium is not None
    ctx = _Context(scene, targets, np.asarray(item.targets, np.int64), settings, item)
    ctx.start_tally(item)

    # --- emission: directions with pdf R_source / W_source, throughput W_source ----------------------------
    w0 = ctx.w0 = sources.total_response(i)
    two_sided = settings.mis or settings.both_sides
    block = qmc.block_size(n, settings.qmc_block)
    if block > 1:
        first_u = qmc.shifted_blocks(n, block, rng)  # (5, n)
        u = first_u[:2]
    else:
        first_u, u = None, rng.random((2, n))
    paths = _Paths(
        directions=np.ascontiguousarray(sources.sample_directions(i, u[0], u[1]).T),
        origins=np.repeat((sources.positions[i] + isect.offset * sources.normals[i])[:, None], n, axis=1),
        weights=np.full(n, w0),
        lengths=np.zeros(n),
        path=np.arange(n),
        k=np.zeros(n, np.int64),
        s=np.zeros(n, np.int64),
        first=np.zeros(n) if two_sided else None,
        first_rho=np.full(n, 1.0 / np.pi) if two_sided else None,
        ratio=ctx.spectra.initial_ratio(n) if ctx.spectra is not None else np.ones((0, n)),
    )
    # source -> mirror -> target (order k = 1, none when K = 0): the same for every path; half each from both devices
    if ctx.mirrors and K >= 1:
        connect_source_mirrors(ctx, sources, i, w0 * (0.5 if settings.mis or settings.both_sides else 1.0), n)
    if settings.phase_lobe and (free_flight or points_on_segments and settings.mis):
        lobe_connections(ctx, n, rng, segments=not free_flight)  # Tx -> p -> Rx from the phase lobe (medium_nee)
    surface_power = escaped_power = 0.0
    far = scene.medium_far_distance  # segments that leave the scene run to where the medium has absorbed all

    for step in range(K + S + 2):
        # ====== intersect ==================================================================================
        prim, t = isect.intersect(paths.origins.T, paths.directions.T)
        hit = prim >= 0
        t_seg = np.where(hit, t, far) if medium is not None else t
        # ====== segment points (algorithms 2-4): single scattering at points along the segment ============
        if points_on_segments:
            segment_scatter(ctx, paths, t_seg, rng, first=step == 0, prim=prim)
        if step == 0 and settings.mis and not points_on_segments:  # no medium: segment_scatter does not set it
            paths.first = first_vertex_factor(ctx, paths, prim, t, np.zeros(len(t)), np.zeros(len(t), bool))
        # ====== free flight (algorithm 5): collision distance; NEE from the collision and equiangular points =
        collided = None
        ctx.first_bounce_u = first_u[3:5] if first_u is not None and step == 0 else None
        if free_flight:
            assert medium is not None  # free_flight holds only with a medium
            u_ff = first_u[2] if first_u is not None and step == 0 else rng.random(len(paths))
            t_col, collided = medium.sample_distance(paths.origins.T, paths.directions.T, t_seg, u_ff)
            if settings.both_sides and step == 0:
                paths.first = first_vertex_factor(ctx, paths, prim, t, t_col, collided)
            frames = _EquiangularFrames(ctx, paths, t_seg) if settings.equiangular_points else None
            medium_rows = (collided & (paths.s < S)).nonzero()[0]
            _medium_next_events(ctx, paths, frames, medium_rows, t_col.take(medium_rows), rng)
            if ctx.spectra is not None and ctx.spectra.depth_row:  # smoke per band: T_b / T_c of the flight
                flown = (hit & ~collided & (paths.k < K)).nonzero()[0]  # (its collisions: `_medium_collision`)
                if len(flown):
                    tau = medium.optical_depth(
                        paths.origins.take(flown, axis=1).T, paths.directions.take(flown, axis=1).T, t.take(flown)
                    )
                    paths.ratio = ctx.spectra.transmit_rows(paths.ratio, flown, tau)
        elif medium is not None:  # algorithm 1 (and 2-4): the segment's extinction
            tau = medium.optical_depth(paths.origins.T, paths.directions.T, t_seg)
            paths.weights = paths.weights * np.exp(-tau)  # = medium.transmittance
            if ctx.spectra is not None:  # spectral smoke: the carrier depth travelled (spectra.py)
                paths.ratio = ctx.spectra.transmit(paths.ratio, tau)
        at_surface = hit if collided is None else hit & ~collided
        if forward:  # the power balance of the result's diagnostics (forward runs)
            escaped_power += paths.weights[~hit if collided is None else ~hit & ~collided].sum()
        survivors = []
        # ====== surface vertex =============================================================================
        on_surface = at_surface & (paths.k < K)
        if on_surface.all():  # the usual step of a closed room: no index arrays
            sp, sp_prim, sp_t = paths, prim, t
        else:
            surface_rows = on_surface.nonzero()[0]
            sp, sp_prim, sp_t = paths.gather(surface_rows), prim.take(surface_rows), t.take(surface_rows)
        if len(sp):
            if forward:
                surface_power += sp.weights.sum()
            survivors.append(_surface_vertex(ctx, sp, sp_prim, sp_t, rng))
        # ====== medium collision (algorithm 5) ==============================================================
        if free_flight and len(medium_rows):
            survivors.append(_medium_collision(ctx, paths, medium_rows, t_col.take(medium_rows), rng))
        # ====== next step: the survivors (each event applied Russian roulette, `_roulette`) ==================
        paths = _Paths.concat(survivors) if survivors else paths.gather(np.zeros(0, np.int64))
        ctx.flush(step + 1)  # the estimates of cells of depth k + s = step + 1 are complete
        if len(paths) == 0:
            break

    tally = ctx.reduce(n)
    tally.rays_intersect = isect.n_intersect - rays0[0]
    tally.rays_occluded = isect.n_occluded - rays0[1]
    tally.surface_power = surface_power if forward else 0.0
    tally.escaped_power = escaped_power if forward else 0.0
    tally.medium_evaluations = (medium.evaluations - med0) if medium is not None else 0
    return tally


def _surface_vertex(ctx: "_Context", sp: _Paths, prims, ts, rng) -> _Paths:
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
    np.negative(normals, out=normals, where=_dot(normals, sp.directions) > 0)  # two-sided: face the arriving ray
    spawn = normals * isect.offset
    spawn += points
    arriving = sp.directions
    sp = _Paths(
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
        ratio=ctx.spectra.reflect(sp.ratio, prims) if ctx.spectra is not None else sp.ratio,
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
    # (`_Context.connect`'s `partition`), not by halves: a half from a side that can hardly sample a path (a
    # 1 deg FOV cone seen from the transmitter) keeps a 1/r^2 tail whose runs miss it and report half of H0
    partition = settings.mis and sp.first is not None
    if geo.material is None:  # every surface Lambertian
        rho = geo.reflectance.take(prims)
        ctx.connect(points, spawn, sp.weights, sp, normals=normals, reflectance=rho, partition=partition)
        if last:
            return sp.gather(np.zeros(0, np.int64))
        sp.weights = sp.weights * rho
        u = ctx.bounce_uniforms(sp, rng)
        sp.directions = cosine_about_soa(normals, u[0], u[1])
    else:
        materials = geo.material.take(prims)
        ctx.connect(
            points, spawn, sp.weights, sp, normals=normals, materials=(materials, arriving), partition=partition
        )
        if ctx.mirrors:  # ... -> x -> mirror -> target, through the target's mirror images (mirrors.py)
            connect_mirrors(
                ctx,
                points,
                spawn,
                sp.weights,
                sp,
                normals=normals,
                brdf=(materials, arriving),
                first_factor=sp.first if partition else None,
            )
        if last:
            return sp.gather(np.zeros(0, np.int64))
        u = ctx.bounce_uniforms(sp, rng)
        sp.directions, factor = materials.sample(arriving, normals, u[0], u[1])
        sp.weights = sp.weights * factor
    alive = sp.weights > 0
    alive &= goes_on
    return _roulette(ctx, sp, alive, rng)


def _scattering_point_throughput(weights, transmittance, sigma_t, sigma_s, n_e):
    """Algorithm 5's balance heuristic (Veach 1997, ch. 9) in one place: the throughput of a scattering point.

    Two techniques place scattering points at distance s on a segment o + s w: the free-flight
    collision, density p_ff(s) = sigma_t(s) T(o -> s), and `equiangular_points` equiangular points per
    target, density n_E(s) (segments.EquiangularFrame.density). Every point of either set makes a
    next-event estimate with MIS weight p / (p_ff + n_E) over its own density p, i.e. throughput
        w T(o -> s) sigma_s(s) / (p_ff(s) + n_E(s)),
    the same formula for both (for the collision it is w x albedo x p_ff / (p_ff + n_E)); without
    equiangular points (n_E = 0) it is the collision's w x albedo.
    """
    total = sigma_t * transmittance  # p_ff
    total += n_e
    num = weights * transmittance
    num *= sigma_s
    # total = 0 only where T = 0 or sigma_t = 0 (then sigma_s = 0): num is 0 there and stays
    # (a division masked by `where` is ~2.5x slower than a plain one: only when needed)
    return (
        np.divide(num, total, out=num)
        if total.min(initial=1.0) > 0
        else np.divide(num, total, out=num, where=total > 0)
    )


class _EquiangularFrames:
    """Algorithm 5, one step: the segments that may scatter once more (s < S, finite) and, per target,
    their equiangular frame, computed once and shared by the equiangular points and the collision's
    density n_E. `rows` None: every path's segment (the usual step; no gathers)."""

    def __init__(self, ctx: "_Context", paths: _Paths, t_seg):
        ok = (paths.s < ctx.settings.max_scattering) & np.isfinite(t_seg)
        self.rows = None if ok.all() else ok.nonzero()[0]
        self.end = _rows(t_seg, self.rows)
        o, w = _rows(paths.origins, self.rows), _rows(paths.directions, self.rows)
        self.frames = [EquiangularFrame(o, w, ctx.t_pos[:, j : j + 1], 0.0, self.end) for j in range(len(ctx.tgt))]

    def segment_of(self, rows):
        """The frame index of the segments of paths `rows` (each among `self.rows`)."""
        return rows if self.rows is None else np.searchsorted(self.rows, rows)


def _medium_next_events(
    ctx: "_Context", paths: _Paths, eq: _EquiangularFrames | None, collision_rows, t_col, rng
) -> None:
    """Algorithm 5: next-event estimation from the scattering points of this step's segments.

    The points of a segment are its free-flight collision (paths `collision_rows`, at t_col) and,
    with `equiangular_points`, that many stratified equiangular points per target (segments.py);
    all connect with the phase function at (k, s + 1), with the throughput of
    `_scattering_point_throughput`. The path itself continues from the collision only
    (`_medium_collision`). The equiangular points of all segments are drawn as one (n_eq, segments)
    grid, stratum i of every segment in row i (broadcasting, no index arrays). Where
    `_Context.connect_on_segments` applies (a medium the same everywhere, see there) the points connect
    through their segment's frame without gathering the paths; else through `connect`.
    """
    settings, medium = ctx.settings, ctx.scene.medium
    n_eq = settings.equiangular_points if eq is not None else 0
    uniform = medium.uniform_coefficients  # (sigma_t, sigma_s) of a medium the same everywhere, else None
    if uniform is not None and uniform[1] <= 0:  # no point scatters
        return
    for j in range(len(ctx.tgt)):
        if eq is not None and n_eq:
            frame = eq.frames[j]
            n_seg = len(eq.end)
            # stratum i of [0, 1): (i + u) / n_eq; the uniforms drawn segment by segment (the order of the
            # equiangular points before the grid: the same numbers reach the same points)
            xi = np.add(rng.random((n_seg, n_eq)).T, np.arange(n_eq)[:, None], out=np.empty((n_eq, n_seg)))
            xi *= 1.0 / n_eq
            s_eq = np.clip(frame.sample(None, xi), 0.0, eq.end)
            empty = frame.span <= 0  # (a segment of length 0 has no equiangular points)
            if not empty.any() and ctx.connect_on_segments(j, paths, eq, s_eq, collision_rows, t_col):
                continue
            seg_rows = np.arange(n_seg) if eq.rows is None else eq.rows
            s_eq, n_e_eq, eq_rows = s_eq.ravel(), frame.density(s_eq, n_eq).ravel(), np.tile(seg_rows, n_eq)
            if empty.any():
                keep = np.tile(~empty, n_eq).nonzero()[0]
                s_eq, n_e_eq, eq_rows = s_eq.take(keep), n_e_eq.take(keep), eq_rows.take(keep)
            rows = np.concatenate([eq_rows, collision_rows])
            s = np.concatenate([s_eq, t_col])
            # (a collision lies on a finite segment with s < S: its row is in eq.rows, sorted)
            n_e = np.concatenate([n_e_eq, frame.density(t_col, n_eq, eq.segment_of(collision_rows))])
        else:
            rows, s, n_e = collision_rows, t_col, np.zeros(len(collision_rows))
        if len(rows) == 0:
            continue
        pp = paths.gather(rows)
        points = pp.origins + s * pp.directions
        if uniform is not None:  # every point scatters
            sigma_t, sigma_s = uniform
            inside = None
        else:
            sigma_t, sigma_s = medium.coefficients_at(points.T)
            inside = (sigma_s > 0).nonzero()[0]
        if inside is not None and len(inside) < len(s):
            if len(inside) == 0:
                continue
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
        if ctx.spectra is not None:  # smoke per band: sigma_s,b T_b over the carrier's at the point (spectra.py)
            pp.ratio = ctx.spectra.scatter(pp.ratio, tau)
        throughput = _scattering_point_throughput(pp.weights, transmittance, sigma_t, sigma_s, n_e)
        mid_g = lobe = None
        if settings.both_sides:  # a point on the first segment is the path's first vertex (medium_nee)
            at_first = (pp.k + pp.s == 0).nonzero()[0]  # only on the first segment (pp's fields are its own copies)
            if len(at_first):
                assert pp.first is not None  # two-sided runs carry it
                pp.first[at_first] = first_medium_factor(
                    ctx, points.take(at_first, axis=1), transmittance.take(at_first)
                )
                lobe_frame = lobe_axis(ctx, j) if settings.phase_lobe else None
                if lobe_frame is not None:  # the source's lobe density at the first vertices (medium_nee)
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
        pp.s = pp.s + 1
        ctx.connect(
            points, points, throughput, pp, in_dirs=pp.directions, target=j, extra_length=s, mid_g=mid_g, lobe=lobe
        )


def _medium_collision(ctx: "_Context", paths: _Paths, rows, t_col, rng) -> _Paths:
    """Algorithm 5: paths `rows` collide at t_col (their estimates: `_medium_next_events`): throughput x
    albedo, the third strategy of medium_nee for Tx -> x_1 -> x_2 -> Rx, and a new direction from the
    phase function. Returns the paths that go on."""
    settings, scene = ctx.settings, ctx.scene
    medium, phase = scene.medium, scene.phase
    K, S = settings.max_reflections, settings.max_scattering
    mp = paths.gather(rows)
    points = mp.origins + t_col * mp.directions
    if ctx.spectra is not None and ctx.spectra.depth_row:  # smoke per band: ratio tracking (spectra.py)
        # the carrier sampled t_col with density sigma_t,c T_c and keeps albedo_c: band b's true sigma_s,b T_b
        # over that is (sigma_s,b / sigma_s,c) exp(-tau_c (sigma_t,b / sigma_t,c - 1)) x albedo_c
        mp.ratio = ctx.spectra.scatter(mp.ratio, medium.optical_depth(mp.origins.T, mp.directions.T, t_col))
    mp.lengths = mp.lengths + t_col
    uniform = medium.uniform_coefficients
    if uniform is not None and uniform[0] > 0:  # the same albedo everywhere: a number
        mp.weights = mp.weights * (uniform[1] / uniform[0])
    else:
        mp.weights = mp.weights * medium.albedo_at(points.T)
    mp.s = mp.s + 1
    if ctx.mirrors:  # ... -> x -> mirror -> target: only the collision reaches it (mirrors.py)
        connect_mirrors(ctx, points, points, mp.weights, mp, in_dirs=mp.directions)
    if settings.both_sides and S >= 2 and ctx.item.direction == "forward":  # third strategy, Tx -> x1 -> x2 -> Rx
        connect_from_target(ctx, mp, points, rng)
    u = ctx.bounce_uniforms(mp, rng)
    arriving = mp.directions
    mp.directions = phase.sample(arriving, u[0], u[1])
    if ctx.spectra is not None:  # Mie per band: p_b / p_c of the sampled direction (spectra.py)
        mp.ratio = ctx.spectra.turn(mp.ratio, _dot(arriving, mp.directions))
    if settings.both_sides:  # leaving the path's first vertex: its phase density (medium_nee)
        at_first = mp.k + mp.s == 1
        if at_first.any():
            mp.first_rho = np.asarray(np.where(at_first, phase.eval(_dot(arriving, mp.directions)), mp.first_rho))
    mp.origins = points
    return _roulette(ctx, mp, ((mp.k < K) | (mp.s < S)) & (mp.weights > 0), rng)


def _roulette(ctx: "_Context", paths: _Paths, alive, rng) -> _Paths:
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
            w = _rows(paths.weights, at)
            q = np.minimum(1.0, w * (1.0 / (settings.rr_threshold * ctx.w0)))
            survive = rng.random(len(q)) < q
            w = w / np.where(survive, q, 1.0)
            if at is None:
                paths.weights, alive = w, survive
            else:
                paths.weights[at] = w
                alive[at[~survive]] = False
    return paths.keep_where(alive)


def _rows(a, idx):
    """a[..., idx], or `a` itself when idx is None (every row)."""
    return a if idx is None else a.take(idx, axis=-1)


class _Context:
    """Per-batch connection machinery and contribution lists (tallied by `reduce`)."""

    KEYS = ("target", "k", "s", "delay", "power", "path")

    def __init__(self, scene, targets, tgt, settings, item):
        self.scene, self.targets, self.tgt, self.settings, self.item = scene, targets, tgt, settings, item
        self.t_pos = np.ascontiguousarray(targets.positions[tgt].T)  # (3, T)
        self.t_nrm = np.ascontiguousarray(targets.normals[tgt].T)
        self.t_nrm_neg = -self.t_nrm  # (3, T): cos at the target = dot(direction toward it, -normal)
        self.t_total = np.array([targets.total_response(int(t)) for t in tgt], float)
        self.t_directional = targets.directional
        #: spectral scenes: per-band tables; estimates carry their band ratios ("ratio") when paths do
        self.spectra = scene.spectra
        self.channels = None  # the per-(link, channel) sums of spectral scenes (spectra.ChannelBuilder)
        self.keys = self.KEYS + (("ratio",) if self.spectra is not None and self.spectra.carry else ())
        self.out: dict[str, list[np.ndarray]] = {k: [] for k in self.keys}
        self.w0 = 1.0  # the source's weight W_source (trace_batch), the roulette's scale
        self.pending: dict[int, list[tuple]] = {}  # depth k + s -> estimate groups waiting for their step
        self.mirrors = scene.mirror_planes
        self.builder: BatchBuilder | None = None  # the batch's tally (trace_batch)
        #: (2, n_paths) quasi-random uniforms of the first bounce (KernelSettings.qmc_block), step 0
        self.first_bounce_u: np.ndarray | None = None

    def bounce_uniforms(self, paths: _Paths, rng) -> np.ndarray:
        """(2, n) uniforms for the new directions of `paths`: the path's quasi-random pair on the first
        bounce under KernelSettings.qmc_block, else pseudo-random ones."""
        if self.first_bounce_u is not None:
            return self.first_bounce_u.take(paths.path, axis=1)
        return rng.random((2, len(paths)))

    def start_tally(self, item: WorkItem) -> None:
        settings = self.settings
        # A path may add several estimates to one order cell in one step: points on segments, equiangular
        # points with the collision, mirror images made one step early, the third strategy of medium_nee.
        several = (
            settings.segment_scatter
            or (settings.free_flight and settings.equiangular_points > 0)
            or bool(self.mirrors)
            or settings.both_sides
            or settings.in_then_out
        )
        block = qmc.block_size(item.n_paths, settings.qmc_block)  # paths per independent sample
        links = item_links(self.scene, item)
        if self.spectra is not None:  # per-(link, channel) sums (tally/spectral.py)
            self.channels = ChannelBuilder(
                self.spectra, item.direction, item.source, self.tgt, links, item.n_paths, block
            )
        self.builder = BatchBuilder(
            settings.tally, links, item.n_paths, several, block, first_batch=item.batch == 0, channels=self.channels
        )

    def connect(
        self,
        points,
        shadow_origins,
        throughput,
        paths,
        *,
        normals=None,
        reflectance=None,
        materials=None,
        in_dirs=None,
        mis=None,
        target: int | None = None,
        scatter_order=None,
        extra_length=None,
        mid_g=None,
        brdf=None,
        lobe=None,
        partition=False,
    ) -> None:
        """Next-event estimation from vertices `points` (3, n) to the targets: the measurement equation.

            dH = throughput * f * R_target(cos_target) / d^2 * V(x, target) * T(x -> target) * mis,

        `throughput` (n,) the path throughput at the vertex (power per watt over the sampling
        densities); f the vertex's scattering function toward the target: at a surface vertex
        (`normals`) rho / vertex cos_x (`reflectance`, Lambertian) or f_bsdf(incoming, out) cos_x
        (`materials` = (Materials per vertex, arriving directions)); at a medium vertex the phase
        function p(dot(arriving `in_dirs`, out)). `mis` (n,) or a scalar: the caller's multiple
        importance sampling weight; algorithm 5 from both devices multiplies medium_nee.connection_weight.
        `target`: only the item's j-th target (else every one). Cells: paths.k and paths.s (or
        `scatter_order`); delays: paths.lengths (+ `extra_length`) + d. `mid_g` (per vertex): T / r^2 of
        the edge that reached a medium vertex (medium_nee.connection_weight). `brdf` is `materials`
        under its former name, and a surface vertex with neither takes f = cos_x: the caller folded the
        BRDF into `throughput` (mirrors.branch_surface calls it so). `lobe` (with `target`): (the source's lobe
        density per vertex, the unit axis toward the target) of KernelSettings.phase_lobe; the target's lobe
        density p(out . axis) T / d^2 joins it in medium_nee.connection_weight.
        `partition` (surface vertices of algorithms 2-4 run from both devices): this run's share
        A / (A + B) of the path (medium_nee.side_weight), A = `_Paths.first` (the source factor of the
        path's first vertex) and B = R_target(cos_target) / W_target cos_x / d^2 (the factor with which the
        target's own rays put their first vertex here); the other run computes the same two factors swapped,
        so the shares sum to 1 (Veach 1997, ch. 9). Through Lambertian reflections it is the balance
        heuristic of the two directions (the densities of the inner vertices are the same both ways).
        """
        materials = materials if materials is not None else brdf
        scene, targets = self.scene, self.targets
        isect, medium = scene.intersector, scene.medium
        n_pts = points.shape[1]
        columns = np.arange(len(self.tgt)) if target is None else np.array([target])
        n_tgt = len(columns)
        chunk = max(1, NEE_CHUNK // n_tgt)
        for lo in range(0, n_pts, chunk):  # chunks bound memory; one chunk for ordinary batches
            hi = min(lo + chunk, n_pts)
            if n_tgt == 1:  # one target: every vertex of the chunk, no index arrays
                vertex_rows = None if (lo, hi) == (0, n_pts) else np.arange(lo, hi)
                column_rows = None
                y, y_nrm = self.t_pos[:, columns[0] : columns[0] + 1], self.t_nrm_neg[:, columns[0]]
                y_ids = None
            else:
                vertex_rows = np.repeat(np.arange(lo, hi), n_tgt)
                column_rows = np.tile(columns, hi - lo)
                y, y_nrm = self.t_pos.take(column_rows, axis=1), self.t_nrm_neg.take(column_rows, axis=1)
                y_ids = self.tgt.take(column_rows)
            out_dir = y - _rows(points, vertex_rows)
            d2 = _dot(out_dir, out_dir)
            d = np.sqrt(d2)
            out_dir *= 1.0 / d  # unit, in place (one division)
            cos_target = _dot(out_dir, y_nrm) if y_ids is not None else _dot_vector(out_dir, y_nrm)
            toward = -out_dir.T if self.t_directional else None  # tabulated transmitters need the direction
            if y_ids is None:
                response = targets.response_one(int(self.tgt[columns[0]]), cos_target, toward)
            else:
                response = targets.response(y_ids, cos_target, toward)
            f = response / d2 * _rows(throughput, vertex_rows)
            if normals is not None:  # surface vertex: BRDF x cos
                n_x = _rows(normals, vertex_rows)
                vertex_factor = _dot(out_dir, n_x)  # cos_x
                np.maximum(vertex_factor, 0.0, out=vertex_factor)
                if materials is not None:
                    mat, arriving = materials
                    mat = mat if vertex_rows is None else mat.take(vertex_rows)
                    f *= vertex_factor * mat.eval(_rows(arriving, vertex_rows), n_x, out_dir)
                elif reflectance is not None:
                    f *= vertex_factor * _rows(reflectance, vertex_rows) * (1.0 / np.pi)
                else:
                    f *= vertex_factor
            else:  # medium vertex: phase function
                vertex_factor = scene.phase.eval(_dot(_rows(in_dirs, vertex_rows), out_dir))
                f *= vertex_factor
            if mis is not None:
                f *= mis if np.isscalar(mis) else _rows(mis, vertex_rows)
            if partition:
                w_tgt = self.t_total[columns[0]] if column_rows is None else self.t_total.take(column_rows)
                f *= side_weight(_rows(paths.first, vertex_rows), response / w_tgt * vertex_factor / d2)
            live = (f > 0).nonzero()[0]
            if len(live) == 0:
                continue
            both_sides = self.settings.both_sides and medium is not None
            # `vertex`: the vertex of each live estimate, None while that is every vertex of `points` in order
            # (then no gathers: in smoke nearly every connection contributes)
            if len(live) < len(f):
                vertex = live if vertex_rows is None else vertex_rows.take(live)
                f, d = f.take(live), d.take(live)
                if not scene.all_visible or medium is not None or "ratio" in self.out:  # the direction goes on
                    out_dir = out_dir.take(live, axis=1)
                column = np.full(len(live), columns[0]) if column_rows is None else column_rows.take(live)
                if both_sides:
                    response, vertex_factor = response.take(live), vertex_factor.take(live)
            else:
                vertex = vertex_rows
                column = np.full(len(live), columns[0]) if column_rows is None else column_rows
            if not scene.all_visible:  # the shadow ray stops short of the device (it may sit on a surface)
                blocked = isect.occluded(_rows(shadow_origins, vertex).T, out_dir.T, d - 2.0 * isect.offset)
                seen = (~blocked).nonzero()[0]
                if len(seen) == 0:  # every shadow ray of the chunk blocked (a furnished room): nothing to record
                    continue
                if len(seen) < len(d):
                    vertex = seen if vertex is None else vertex.take(seen)
                    column, f, d = column.take(seen), f.take(seen), d.take(seen)
                    if medium is not None or "ratio" in self.out:  # the direction is needed further on
                        out_dir = out_dir.take(seen, axis=1)
                    if both_sides:
                        response, vertex_factor = response.take(seen), vertex_factor.take(seen)
            if medium is not None:
                tau = medium.optical_depth(_rows(points, vertex).T, out_dir.T, d)
                tr = np.exp(-tau)  # = medium.transmittance
                f = f * tr
                if both_sides:  # algorithm 5 from both devices: this run's share (medium_nee.connection_weight)
                    f = f * connection_weight(
                        self,
                        paths,
                        vertex,
                        column,
                        d,
                        tr,
                        response,
                        vertex_factor,
                        surface=normals is not None,
                        mid_g=mid_g,
                        lobe=None
                        if lobe is None
                        else _rows(lobe[0], vertex) + scene.phase.eval(_dot_vector(out_dir, lobe[1])) * tr / (d * d),
                    )
            length = _rows(paths.lengths, vertex) + d
            if extra_length is not None:
                length += _rows(extra_length, vertex)
            s_order = _rows(paths.s if scatter_order is None else scatter_order, vertex)
            ratio = None
            if "ratio" in self.out:  # spectral: the path's band ratios, with T_b / T_c of the connection
                ratio = self.spectra.estimate_ratio(_rows(paths.ratio, vertex), tau if medium is not None else None)
                if normals is None and self.spectra.phase_bands is not None:  # medium vertex: p_b / p_c
                    ratio = ratio * self.spectra.phase_ratio(_dot(_rows(in_dirs, vertex), out_dir))
            length *= 1.0 / SPEED_OF_LIGHT
            self.record(column, _rows(paths.k, vertex), s_order, length, f, _rows(paths.path, vertex), ratio)

    def connect_on_segments(self, j: int, paths: _Paths, eq: _EquiangularFrames, s_eq, collision_rows, t_col) -> bool:
        """The medium branch of `connect` for algorithm 5's scattering points, computed on their segments.

        The points lie at distances s along the segments o + s w of `eq` (equiangular points `s_eq`
        (n_eq, segments), collisions of the paths `collision_rows` at t_col); toward target j (y, normal
        n_y) the segment's frame gives, with x = s - D (|w| = 1),
            d^2 = h^2 + x^2   (also the denominator of the equiangular density n_E(s)),
            cos_phase = w.(y - p) / d = -x / d,   cos_target = n_y.(p - y) / d = (s n_y.w - n_y.v) / d,
        so nothing of size (3, points) is formed and no path field is gathered for the equiangular points.
        The estimate is `connect`'s, with the throughput of `_scattering_point_throughput`:
            dH = w T(o -> p) sigma_s / (p_ff + n_E) x p(cos_phase) L W_y x share,   L = R_y / W_y T(p -> y) / d^2,
        and in two-sided runs the share of medium_nee.connection_weight, by the depth k + s of the paths:
        - 0 (the point is the path's first vertex): F / (F + L), F = R_src / W_src T(o -> p) / r^2
          (medium_nee.first_medium_factor; r, cos at the source from the segment: r^2 = |u + s w|^2,
          u = o - source);
        - >= 1: a / (a + L p + F L / g), a = F rho_1 (`_Paths.first`, `first_rho`), the last term only for
          Tx -> x_1 -> x_2 -> Rx (k = 0, s = 1 before the point; g = T(o -> p) / s^2, the third strategy).
        Applies to a medium the same everywhere, grey scenes, every target visible from every point
        (`Scene.all_visible`), devices whose response needs only the cosine, and paths of one depth class
        (algorithm 5's steps: all paths of a step have depth = step); returns False (nothing done)
        otherwise. The equiangular points and the collisions are tallied as two groups (the grid broadcasting
        over the segments, the collisions gathering theirs), or in steps of at most SMALL_STEP segments as one.
        """
        scene, settings = self.scene, self.settings
        medium = scene.medium
        uniform = medium.uniform_coefficients
        if uniform is None or self.spectra is not None or not scene.all_visible or self.t_directional:
            return False
        rows = eq.rows
        k, s_order = _rows(paths.k, rows), _rows(paths.s, rows)
        share = settings.both_sides
        if settings.phase_lobe and not share and len(k) and int((k + s_order).min()) == 0:
            return False  # one side, first vertices: the share with the lobe (`_medium_next_events`)
        mode = "deep"  # depth >= 2 (the usual step), "first" (depth 0), "second" (depth 1)
        if share and len(k):
            depth = k + s_order
            lo, hi = int(depth.min()), int(depth.max())
            if lo < 2:
                if hi != lo:
                    return False
                mode = "first" if lo == 0 else "second"
        sigma_t, sigma_s = uniform
        frame = eq.frames[j]
        o, w = _rows(paths.origins, rows), _rows(paths.directions, rows)
        y, n_y = self.t_pos[:, j], self.t_nrm[:, j]
        # per segment: n_y.v = n_y.y - n_y.o, n_y.w
        n_v = np.subtract(float(n_y @ y), _dot_vector(o, n_y))
        n_w = _dot_vector(w, n_y)
        seg = {
            "D": frame.D,
            "h2": frame.h2,
            "n_e": frame.scale * settings.equiangular_points,
            "n_v": n_v,
            "n_w": n_w,
            "w": _rows(paths.weights, rows),
            "length": _rows(paths.lengths, rows),
        }
        if mode == "first":  # the source's factor at the points: u = o - source, per segment |u|^2, u.w, n.u, n.w
            src, _ = device_sets(scene, self.item.direction)
            i = self.item.source
            if src.directional:
                return False
            u = o - src.positions[i][:, None]
            n_src = src.normals[i]
            seg["uu"] = _dot(u, u)
            seg["uw2"] = 2.0 * _dot(u, w)
            seg["nu"] = _dot_vector(u, n_src)
            seg["nw"] = _dot_vector(w, n_src)
            lobe = lobe_axis(self, j) if settings.phase_lobe else None
            if lobe is not None:  # the two lobe densities (medium_nee): per segment u.a, w.a, (y - o).a
                axis = lobe[1]
                seg["ua"] = _dot_vector(u, axis)
                seg["wa"] = _dot_vector(w, axis)
                seg["ya"] = np.subtract(float(axis @ y), _dot_vector(o, axis))
        elif share:
            seg["a"] = _rows(paths.first, rows) * _rows(paths.first_rho, rows)
            if mode == "second":  # Tx -> x_1 -> x_2 -> Rx: F on those segments, 0 on the others
                seg["F3"] = np.where((k == 0) & (s_order == 1), _rows(paths.first, rows), 0.0)
        t_id, inv_w = int(self.tgt[j]), 1.0 / self.t_total[j]
        phase, targets = scene.phase, self.targets
        n_eq = len(s_eq)
        per_path = (k, s_order + 1, _rows(paths.path, rows))
        col = eq.segment_of(collision_rows)
        # one group for a few segments: every per-segment value expanded, half the numpy calls (whose fixed
        # cost dominates small steps)
        if len(k) <= SMALL_STEP and len(col):

            def expand(v):
                return np.concatenate((v,) * n_eq + (v.take(col),))

            blocks: list[tuple[np.ndarray, dict | None]] = [
                (np.concatenate((s_eq.reshape(-1), t_col)), {key: expand(v) for key, v in seg.items()})
            ]
            fields_of: list[tuple | None] = [tuple(expand(v) for v in per_path)]
        else:
            blocks = [(s_eq, seg), (t_col, None)]
            fields_of = [None, None]
        for (s, g), fields in zip(blocks, fields_of):
            if s.size == 0:
                continue
            at = None
            if g is None:
                at, g = col, {key: v.take(col) for key, v in seg.items()}
            x = s - g["D"]
            d2 = x * x
            d2 += g["h2"]
            d = np.sqrt(d2)
            inv_d = np.divide(1.0, d)
            np.multiply(x, inv_d, out=x)
            p = phase.eval(np.negative(x, out=x))  # cos_phase
            cos_t = s * g["n_w"]
            cos_t -= g["n_v"]
            cos_t *= inv_d
            resp = targets.response_one(t_id, cos_t)
            t_o = np.multiply(s, -sigma_t)
            np.exp(t_o, out=t_o)  # T(o -> p) = medium.transmittance
            n_e = np.divide(g["n_e"], d2)  # the equiangular density n_E(s) (segments.EquiangularFrame.density)
            power = _scattering_point_throughput(g["w"], t_o, sigma_t, sigma_s, n_e)
            if mode == "first":
                r2 = s + g["uw2"]
                r2 *= s
                r2 += g["uu"]  # |u + s w|^2
                cos_src = s * g["nw"]
                cos_src += g["nu"]
                cos_src /= np.sqrt(r2)
                first = src.response_one(i, cos_src)
                first *= t_o
                first /= r2
                first *= 1.0 / src.total_response(i)  # F
                if "ua" in g:  # the source's lobe p(cos alpha) T(o -> p) / r^2, cos alpha = (u.a + s w.a) / r
                    lobe_d = s * g["wa"]
                    lobe_d += g["ua"]
                    lobe_d /= np.sqrt(r2)
                    lobe_d = phase.eval(lobe_d)
                    lobe_d *= t_o
                    lobe_d /= r2
            t_c = np.multiply(d, -sigma_t, out=t_o if mode != "second" else None)
            np.exp(t_c, out=t_c)  # T(p -> y)
            resp *= t_c
            resp /= d2  # L W_y = R_y T(p -> y) / d^2
            power *= resp
            power *= p
            if share:  # medium_nee.connection_weight
                resp *= inv_w  # L
                if mode == "first":  # F / (F + L (+ Lambda))
                    resp += first
                    num = first
                    if "ua" in g:  # + the target's lobe p(cos beta) T(p -> y) / d^2, cos beta = ((y - o).a - s w.a) / d
                        cos_b = np.multiply(s, g["wa"])
                        np.subtract(g["ya"], cos_b, out=cos_b)
                        cos_b *= inv_d
                        lobe_d += phase.eval(cos_b) * t_c / d2
                        resp += lobe_d
                else:  # a / (a + L p (+ F L / g))
                    num = g["a"]
                    if mode == "second":
                        extra = resp * g["F3"]
                        extra *= s
                        extra *= s
                        np.divide(extra, t_o, out=extra, where=extra > 0)  # F L s^2 / T(o -> p) (0 elsewhere)
                    resp *= p
                    resp += num
                    if mode == "second":
                        resp += extra
                if num.min(initial=1.0) > 0:  # then the denominator is > 0
                    np.divide(num, resp, out=resp)
                else:
                    np.divide(num, resp, out=resp, where=resp > 0)  # (all terms 0: power is 0)
                power *= resp
            delay = np.add(s, g["length"])
            delay += d
            delay *= 1.0 / SPEED_OF_LIGHT
            power, delay = power.reshape(-1), delay.reshape(-1)
            if fields is None:
                fields = tuple(np.concatenate((v,) * n_eq) if at is None else v.take(at) for v in per_path)
            n_points = len(power)
            live = None if power.min() > 0 else power.nonzero()[0]
            if live is not None:
                power, delay, fields = power.take(live), delay.take(live), tuple(v.take(live) for v in fields)
            medium.evaluations += n_points + len(power)  # o -> p of every point, p -> y of those that count
            self.record(np.full(len(power), j), fields[0], fields[1], delay, power, fields[2])
        return True

    def record(self, target, k, s, delay, power, path, ratio=None) -> None:
        """One group of estimates: local target index, cell (k, s), delay [s], power [W/W], path in the batch,
        and in spectral scenes whose paths carry band ratios, those (B, m) (spectra.py)."""
        for key, value in zip(self.KEYS, (target, k, s, delay, power, path)):
            self.out[key].append(value)
        if "ratio" in self.out:
            if ratio is None:
                raise RuntimeError("an estimate of a spectral scene was recorded without its band ratios")
            self.out["ratio"].append(ratio)

    def flush(self, depth: int | None = None) -> None:
        """Tally the estimates of cells of depth k + s <= `depth` (all with None).

        Estimates of deeper cells made early (the branches of algorithms 2-4, mirror images, the third
        strategy of medium_nee) wait for their depth, so that every estimate of a (path, cell) reaches
        the tally in one call (tally.BatchBuilder.add_step sums them per path before squaring). Every
        group of estimates lies in cells of one depth (each comes from paths of one depth).
        """
        for group in zip(*(self.out[key] for key in self.keys)):
            if len(group[4]):
                self.pending.setdefault(int(group[1][0] + group[2][0]), []).append(group)
        self.out = {k: [] for k in self.keys}
        for d in sorted(d for d in self.pending if depth is None or d <= depth):
            groups = self.pending.pop(d)
            assert self.builder is not None  # start_tally ran (trace_batch)
            cat = [g[0] if len(groups) == 1 else np.concatenate(g, axis=-1) for g in zip(*groups)]
            if self.channels is not None:  # every channel of every band (spectra.py); the main tally: the optical
                target, _k, _s, delay, power, path = cat[:6]
                ratio = cat[6] if len(cat) > 6 else np.ones((0, len(power)))
                cat[4] = self.channels.add(target, delay, power, ratio, path)
            self.builder.add_step(*cat[:6])

    def reduce(self, n_paths: int) -> BatchTally:
        self.flush()
        weights = None
        if self.item.direction == "backward" and self.settings.tally.group_weights.size:
            weights = self.settings.tally.group_weights[:, self.tgt]  # (G, T): targets are transmitters
        assert self.builder is not None
        return self.builder.finish(weights)  # (with the channel sums of spectral scenes)
