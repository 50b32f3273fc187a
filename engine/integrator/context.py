"""Next-event estimation in one home: the measurement equation from path vertices to the targets.

`BatchContext.connect` takes a group of vertices (`Vertices`: where they are, their kind, surface or
medium, and what weighs their estimates) and evaluates, per vertex and target,

    dH = throughput * f * R_target(cos_target) / d^2 * V(x, target) * T(x -> target) * weights,

f the vertex's BRDF x cos (surface) or phase function (medium), the weights the caller's MIS weight and
the run's share of the path under the partition of unity (weights.py). The estimates wait per depth
and reach the batch's tally together (`flush`, `reduce`). Algorithm 5's scattering points in a medium
the same everywhere take a faster route on their segments' frames (`connect_on_segments`, uniform_medium.py).
"""

from __future__ import annotations

from dataclasses import dataclass
from enum import Enum
from typing import Any

import numpy as np

from owcsim.engine.core import qmc
from owcsim.engine.core.arrays import FloatArray, IntArray
from owcsim.engine.core.constants import SPEED_OF_LIGHT
from owcsim.engine.integrator.path import BatchState, Paths, WorkItem, dot, dot_vector, item_links, rows
from owcsim.engine.integrator.weights import connection_weight, side_weight
from owcsim.engine.surfaces.bsdf import Materials
from owcsim.engine.tally.packed import PackedBuilder
from owcsim.engine.tally.spectral import ChannelBuilder
from owcsim.engine.tally.tally import BatchBuilder, BatchTally
from owcsim.schemas.algorithms import Direction

#: Upper bound on paths x targets connected in one array operation (memory bound).
NEE_CHUNK = 1 << 20


class VertexKind(Enum):
    """Where a vertex lies: on a surface (BRDF x cos toward the target) or in the medium (phase function)."""

    SURFACE = "surface"
    MEDIUM = "medium"


@dataclass(frozen=True)
class Vertices:
    """Path vertices making next-event estimates: the argument of `BatchContext.connect`.

    Where: `points` (3, n) [m], shadow rays from `shadow_origins` (3, n) (offset off a surface).
    Kind: SURFACE with unit `normals` (3, n) facing the arriving ray and f = rho / pi (`reflectance` (n,),
    Lambertian) or f_bsdf(incoming, out) (`materials` = (Materials per vertex, arriving directions (3, n))),
    or neither: f = cos_x, the caller folded the BRDF into the throughput; MEDIUM with arriving
    directions `in_dirs` (3, n), f = phase(dot(in_dirs, out)).
    Weights: `throughput` (n,) the path throughput (power per watt over the sampling densities), `mis`
    (n,) or a number, the caller's MIS weight; `partition` (surface vertices of algorithms 2-4 run from
    both devices): this run's share A / (A + B) (weights.side_weight, A = `Paths.first`); `mid_g` (n,):
    T / r^2 of the edge that reached a medium vertex and `lobe` (the source's lobe density (n,), the unit
    axis toward the target) of algorithm 5 from both devices (weights.connection_weight).
    Cells and delays: `paths` (cells k and s, lengths), `scatter_order` (n,) instead of paths.s,
    `extra_length` (n,) [m] added to paths.lengths.
    """

    kind: VertexKind
    points: FloatArray
    shadow_origins: FloatArray
    throughput: FloatArray
    paths: Paths
    normals: FloatArray | None = None
    reflectance: FloatArray | None = None
    materials: tuple[Materials, FloatArray] | None = None
    in_dirs: FloatArray | None = None
    mis: FloatArray | float | None = None
    partition: bool = False
    mid_g: FloatArray | None = None
    lobe: tuple[FloatArray, FloatArray] | None = None
    scatter_order: IntArray | None = None
    extra_length: FloatArray | None = None

    @classmethod
    def on_surface(
        cls,
        points: FloatArray,
        shadow_origins: FloatArray,
        throughput: FloatArray,
        paths: Paths,
        normals: FloatArray,
        *,
        reflectance: FloatArray | None = None,
        materials: tuple[Materials, FloatArray] | None = None,
        partition: bool = False,
    ) -> Vertices:
        """Surface vertices (Lambertian `reflectance`, `materials`, or the BRDF folded into `throughput`)."""
        return cls(
            VertexKind.SURFACE,
            points,
            shadow_origins,
            throughput,
            paths,
            normals=normals,
            reflectance=reflectance,
            materials=materials,
            partition=partition,
        )

    @classmethod
    def in_medium(
        cls,
        points: FloatArray,
        throughput: FloatArray,
        paths: Paths,
        in_dirs: FloatArray,
        *,
        mis: FloatArray | None = None,
        mid_g: FloatArray | None = None,
        lobe: tuple[FloatArray, FloatArray] | None = None,
        scatter_order: IntArray | None = None,
        extra_length: FloatArray | None = None,
    ) -> Vertices:
        """Medium vertices (scattering points: their shadow rays start at the points)."""
        return cls(
            VertexKind.MEDIUM,
            points,
            points,
            throughput,
            paths,
            in_dirs=in_dirs,
            mis=mis,
            mid_g=mid_g,
            lobe=lobe,
            scatter_order=scatter_order,
            extra_length=extra_length,
        )


@dataclass
class _Chunk:
    """The estimates of one chunk of `connect` still alive: their vertex rows (None: every vertex of the
    chunk, in order), local target column, estimate f, distance d [m] and unit direction toward the target
    (3, m), the target's response and the vertex factor (cos_x, or the phase function's value)."""

    vertex: IntArray | None
    column: IntArray
    f: FloatArray
    d: FloatArray
    out_dir: FloatArray
    response: FloatArray
    vertex_factor: FloatArray


class BatchContext(BatchState):
    """Per-batch connection machinery and contribution lists (tallied by `reduce`)."""

    def __init__(self, *args: Any) -> None:
        super().__init__(*args)
        self.channels: ChannelBuilder | None = None  # the per-(link, channel) sums of spectral scenes
        self.w0 = 1.0  # the source's weight W_source (trace_batch), the roulette's scale
        self.pending: dict[int, list[tuple[Any, ...]]] = {}  # depth k + s -> estimate groups waiting for their step
        self.builder: BatchBuilder | PackedBuilder | None = None  # the batch's tally (trace_batch)
        #: frames of a time-varying medium (engine/media/frame_ratios.py): one tally per frame, of the estimates
        #: x the frame's ratio row, and which of the batch's targets each frame tallies (F, T)
        self.frame_builders: list[BatchBuilder] = []
        self.frame_targets: Any = None
        #: (2, n_paths) quasi-random uniforms of the first bounce (KernelSettings.qmc_block), step 0
        self.first_bounce_u: FloatArray | None = None

    def bounce_uniforms(self, paths: Paths, rng: np.random.Generator) -> FloatArray:
        """(2, n) uniforms for the new directions of `paths`: the path's quasi-random pair on the first
        bounce under KernelSettings.qmc_block, else pseudo-random ones."""
        if self.first_bounce_u is not None:
            return self.first_bounce_u.take(paths.path, axis=1)
        return rng.random((2, len(paths)))

    def start_tally(self, item: WorkItem) -> None:
        settings = self.settings
        # A path may add several estimates to one order cell in one step: points on segments, equiangular
        # points with the collision, mirror images made one step early, the third strategy of events.py.
        several = (
            settings.segment_scatter
            or (settings.free_flight and settings.equiangular_points > 0)
            or bool(self.mirrors)
            or settings.both_sides
            or settings.in_then_out
        )
        links = item_links(self.scene, item)
        if item.packed:  # several sources' paths (engine/run/allocation.py): per-path sums, reduced per source
            plan = settings.tally
            kept = max(plan.cir_slots(links).max(initial=-1), plan.order_slots(links).max(initial=-1))
            if several or self.ratios is not None or kept >= 0:
                raise RuntimeError("a packed batch needs algorithm 1 without mirrors, spectra, CIR or order split")
            self.builder = PackedBuilder(plan, links, len(self.tgt), np.asarray(item.sources), np.asarray(item.counts))
            return
        block = qmc.block_size(item.n_paths, settings.qmc_block)  # paths per independent sample
        if self.spectra is not None:  # per-(link, channel) sums (tally/spectral.py)
            self.channels = ChannelBuilder(
                self.spectra, item.direction, item.source, self.tgt, links, item.n_paths, block
            )
        self.builder = BatchBuilder(
            settings.tally, links, item.n_paths, several, block, first_batch=item.batch == 0, channels=self.channels
        )
        frames = self.scene.path_ratios
        if self.spectra is None and frames is not None:  # one tally per frame (engine/run/frames_reweighted.py)
            self.frame_targets = frames.frame_targets(item.direction is Direction.FORWARD, item.source, self.tgt)
            self.frame_builders = [
                BatchBuilder(settings.tally, links, item.n_paths, several, block, first_batch=item.batch == 0)
                for _ in range(frames.n_bands)
            ]

    def connect(self, v: Vertices, target: int | None = None) -> None:
        """Next-event estimation from the vertices `v` to the targets: the measurement equation.

            dH = throughput * f * R_target(cos_target) / d^2 * V(x, target) * T(x -> target) * mis,

        f the vertex's scattering function toward the target (`Vertices`); algorithm 5 from both devices
        multiplies weights.connection_weight, the target's lobe density p(out . axis) T / d^2 joining
        the source's (`Vertices.lobe`). `target`: only the item's j-th target (else every one).
        `partition`: this run's share A / (A + B) of the path (weights.side_weight), A = `Paths.first`
        (the source factor of the path's first vertex) and B = R_target(cos_target) / W_target cos_x / d^2
        (the factor with which the target's own rays put their first vertex here); the other run computes
        the same two factors swapped, so the shares sum to 1 (Veach 1997, ch. 9). Through Lambertian
        reflections it is the balance heuristic of the two directions (the densities of the inner vertices
        are the same both ways). Cells: paths.k and paths.s (or `scatter_order`); delays: paths.lengths
        (+ `extra_length`) + d.
        """
        n_pts = v.points.shape[1]
        columns = np.arange(len(self.tgt)) if target is None else np.array([target])
        chunk = max(1, NEE_CHUNK // len(columns))
        for lo in range(0, n_pts, chunk):  # chunks bound memory; one chunk for ordinary batches
            hi = min(lo + chunk, n_pts)
            est = self._estimate(v, columns, lo, hi, n_pts)
            if est is not None:
                self._finish(v, est)

    def _estimate(self, v: Vertices, columns: IntArray, lo: int, hi: int, n_pts: int) -> _Chunk | None:
        """The estimates of vertices lo..hi to the targets `columns` before visibility and transmittance."""
        n_tgt = len(columns)
        column_rows: IntArray | None
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
        out_dir = y - rows(v.points, vertex_rows)
        d2 = dot(out_dir, out_dir)
        d = np.sqrt(d2)
        out_dir *= 1.0 / d  # unit, in place (one division)
        cos_target = dot(out_dir, y_nrm) if y_ids is not None else dot_vector(out_dir, y_nrm)
        toward = -out_dir.T if self.t_directional else None  # tabulated transmitters need the direction
        if y_ids is None:
            response = self.targets.response_one(int(self.tgt[columns[0]]), cos_target, toward)
        else:
            response = self.targets.response(y_ids, cos_target, toward)
        f = response / d2 * rows(v.throughput, vertex_rows)
        vertex_factor, factor = self._vertex_factor(v, vertex_rows, out_dir)
        f *= factor
        if v.mis is not None:
            f *= v.mis if np.isscalar(v.mis) else rows(v.mis, vertex_rows)
        if v.partition:
            w_tgt = self.t_total[columns[0]] if column_rows is None else self.t_total.take(column_rows)
            f *= side_weight(rows(v.paths.first, vertex_rows), response / w_tgt * vertex_factor / d2)
        column = np.full(len(f), columns[0]) if column_rows is None else column_rows
        return self._visible(v, _Chunk(vertex_rows, column, f, d, out_dir, response, vertex_factor))

    def _vertex_factor(self, v: Vertices, vertex_rows: IntArray | None, out_dir: FloatArray) -> tuple[Any, Any]:
        """(vertex factor, the factor of the estimate): (cos_x, cos_x f_bsdf) at a surface vertex (cos_x rho / pi
        Lambertian, cos_x when the caller folded the BRDF in), (p, p) at a medium vertex, p the phase function."""
        if v.normals is not None:  # surface vertex: BRDF x cos
            n_x = rows(v.normals, vertex_rows)
            vertex_factor = dot(out_dir, n_x)  # cos_x
            np.maximum(vertex_factor, 0.0, out=vertex_factor)
            if v.materials is not None:
                mat, arriving = v.materials
                mat = mat if vertex_rows is None else mat.take(vertex_rows)
                return vertex_factor, vertex_factor * mat.eval(rows(arriving, vertex_rows), n_x, out_dir)
            if v.reflectance is not None:
                return vertex_factor, vertex_factor * rows(v.reflectance, vertex_rows) * (1.0 / np.pi)
            return vertex_factor, vertex_factor
        vertex_factor = self.phase.eval(dot(rows(v.in_dirs, vertex_rows), out_dir))  # medium vertex
        return vertex_factor, vertex_factor

    def _visible(self, v: Vertices, c: _Chunk) -> _Chunk | None:
        """The estimates of `c` that are > 0 and whose shadow ray reaches the target; None if none."""
        scene, medium, isect = self.scene, self.scene.medium, self.scene.intersector
        live = (c.f > 0).nonzero()[0]
        if len(live) == 0:
            return None
        both_sides = self.settings.both_sides and medium is not None
        # `vertex`: the vertex of each live estimate, None while that is every vertex of `points` in order
        # (then no gathers: in smoke nearly every connection contributes)
        if len(live) < len(c.f):
            c.vertex = live if c.vertex is None else c.vertex.take(live)
            c.f, c.d = c.f.take(live), c.d.take(live)
            if not scene.all_visible or medium is not None or "ratio" in self.out:  # the direction goes on
                c.out_dir = c.out_dir.take(live, axis=1)
            c.column = c.column.take(live)
            if both_sides:
                c.response, c.vertex_factor = c.response.take(live), c.vertex_factor.take(live)
        if scene.all_visible:
            return c
        # the shadow ray stops short of the device (it may sit on a surface)
        blocked = isect.occluded(rows(v.shadow_origins, c.vertex).T, c.out_dir.T, c.d - 2.0 * isect.offset)
        seen = (~blocked).nonzero()[0]
        if len(seen) == 0:  # every shadow ray of the chunk blocked (a furnished room): nothing to record
            return None
        if len(seen) < len(c.d):
            c.vertex = seen if c.vertex is None else c.vertex.take(seen)
            c.column, c.f, c.d = c.column.take(seen), c.f.take(seen), c.d.take(seen)
            if medium is not None or "ratio" in self.out:  # the direction is needed further on
                c.out_dir = c.out_dir.take(seen, axis=1)
            if both_sides:
                c.response, c.vertex_factor = c.response.take(seen), c.vertex_factor.take(seen)
        return c

    def _finish(self, v: Vertices, c: _Chunk) -> None:
        """Transmittance to the target, algorithm 5's two-sided share, band ratios and delays; then record."""
        medium, paths, vertex = self.scene.medium, v.paths, c.vertex
        f, d, out_dir = c.f, c.d, c.out_dir
        tau = None
        if medium is not None:
            tau = medium.optical_depth(rows(v.points, vertex).T, out_dir.T, d)
            tr = np.exp(-tau)  # = medium.transmittance
            f = f * tr
            if self.settings.both_sides:  # algorithm 5 from both devices: this run's share (weights.connection_weight)
                lobe = None
                if v.lobe is not None:
                    lobe = rows(v.lobe[0], vertex) + self.phase.eval(dot_vector(out_dir, v.lobe[1])) * tr / (d * d)
                f = f * connection_weight(
                    self,
                    paths,
                    vertex,
                    c.column,
                    d,
                    tr,
                    c.response,
                    c.vertex_factor,
                    surface=v.normals is not None,
                    mid_g=v.mid_g,
                    lobe=lobe,
                )
        length = rows(paths.lengths, vertex) + d
        if v.extra_length is not None:
            length += rows(v.extra_length, vertex)
        s_order = rows(paths.s if v.scatter_order is None else v.scatter_order, vertex)
        ratio = None
        if "ratio" in self.out:  # bands or frames: the path's ratios, with T_b / T_c of the connection
            spectra = self.ratios
            assert spectra is not None  # (only parts with ratios carry them)
            seg = (rows(v.points, vertex).T, out_dir.T, d) if medium is not None else None
            ratio = spectra.estimate_ratio(rows(paths.ratio, vertex), tau, seg)
            if v.normals is None and spectra.phase_bands is not None:  # medium vertex: p_b / p_c
                ratio = ratio * spectra.phase_ratio(dot(rows(v.in_dirs, vertex), out_dir))
        length *= 1.0 / SPEED_OF_LIGHT
        self.record(c.column, rows(paths.k, vertex), s_order, length, f, rows(paths.path, vertex), ratio)

    def flush(self, depth: int | None = None) -> None:
        """Tally the estimates of cells of depth k + s <= `depth` (all with None).

        Estimates of deeper cells made early (the branches of algorithms 2-4, mirror images, the third
        strategy of events.connect_from_target) wait for their depth, so that every estimate of a (path, cell) reaches
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
            if self.frame_builders:  # frame f's estimates: the carrier's x its ratio row
                self._add_frames(cat)

    def _add_frames(self, cat: list[Any]) -> None:
        """Each frame's tally gets the step's estimates of its targets times the frame's ratio row."""
        target, k, s, delay, power, path, ratio = cat[:7]
        several = len(self.tgt) > 1
        for f, builder in enumerate(self.frame_builders):  # a loop over frames: each its own tally
            keep = self.frame_targets[f]
            if keep.all():
                builder.add_step(target, k, s, delay, power * ratio[f], path)
            elif keep.any() and several:
                sel = keep.take(target).nonzero()[0]
                builder.add_step(
                    target.take(sel),
                    k.take(sel),
                    s.take(sel),
                    delay.take(sel),
                    power.take(sel) * ratio[f].take(sel),
                    path.take(sel),
                )

    def reduce(self, n_paths: int) -> BatchTally:
        self.flush()
        weights = None
        if self.item.direction is Direction.BACKWARD and self.settings.tally.group_weights.size:
            weights = self.settings.tally.group_weights[:, self.tgt]  # (G, T): targets are transmitters
        assert self.builder is not None
        tally = self.builder.finish(weights)  # (with the channel sums of spectral scenes)
        if self.frame_builders:
            tally.frames = [b.finish(weights) for b in self.frame_builders]
        return tally
