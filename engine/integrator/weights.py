"""Bounded weights for runs from both devices: the device factors and the partition of unity (physics.md section 4).

The problem. A path traced from one device (the source) connects its last vertex x_n to
the other device y (the target) by next-event estimation (NEE); the connection carries
R_y(cos) / |x_n - y|^2. Equiangular points cancel the 1/r^2 along one segment, but a
segment passing at distance h from y still contributes ~1/h, and over random segments
E[(1/h)^2] = int h^-2 h dh diverges logarithmically: the reported standard errors are
then unreliable (issue 12: replicate spread up to 5x the reported error at g = 0.9).

The construction: both devices sample every path, and a partition of unity splits
each path between them. For a path x_1 ... x_n (vertices between the devices, x_1 next
to the transmitter) define the device factors

    A = R_tx(x_1) / W_tx * c(x_1) / |x_1 - Tx|^2,     B = R_rx(x_n) / W_rx * c(x_n) / |x_n - Rx|^2,

R the device's angular response toward the vertex, W its integral (`Devices.total_response`),
c = sigma_t(x) at a medium vertex and |cos| toward the device at a surface vertex. A / W-
normalised is the density (per volume or per area, up to the free-flight transmittance)
with which the device's own rays put their first vertex at x. The run from the
transmitter weights its estimate of the path by w_tx = A / (A + B), the run from the
receiver by w_rx = B / (A + B): both weights are functions of the path alone, computed
identically by the two runs (each stores its source-side factor in `Paths.first` at
the first vertex and computes the target-side factor at the connection, `side_weight`),
and w_tx + w_rx = 1, so the sum of the two runs is unbiased for the whole family
(each run is unbiased for its family with any path-dependent weight; Veach 1997, ch. 9).
Algorithms 2-4 leave transmittances out of A and B (any positive path function gives a
partition). Algorithm 5 (`connection_weight`) uses the exact balance heuristic of its
strategies with free-flight distances (Veach 1997, section 10.2): F = R / W c T(device ->
x) / r^2 with c = 1 at a medium vertex (sigma_t cancels between the strategies); for paths
of two or more vertices each factor is multiplied by the density of the direction leaving
its end vertex (the phase function there, or 1/pi at a surface: `Paths.first_rho`), which
matters for forward-peaked phase functions; and the two-medium-vertex family
Tx -> x_1 -> x_2 -> Rx has a third strategy (`connect_from_target`: x_1 from the
transmitter, x_2 from the receiver, joined), which carries the corner where x_1 lies near
the transmitter and x_2 near the receiver.

The bound (the worst weight). Paths keep w <= W_src (phase sampling multiplies by the
albedo, reflections by rho <= 1, and the roulette's survival min(1, w / W_src) only
raises weights below W_src up to W_src). With the free-flight and equiangular densities
combined by the balance heuristic, a medium vertex's estimate is at most
w * albedo * p_max * R_tgt / r_n^2 (the transmittance T(o -> p) sigma_s over
p_ff = sigma_t T(o -> p) is the albedo), so, with p_max the phase function's maximum,

    contribution <= W_src * albedo * p_max * min(R_tgt,max / r_n^2, W_tgt R_src,max / (W_src r_1^2))

(the second bound: w_src <= A / B; with the direction factors of multi-vertex paths the same
holds with p_max folded into the constant, and transmittances <= 1). For single scattering (n = 1, x_1 = x_n, the family
that carries the heavy tail) r_1 + r_n >= D, the distance between the devices, so
max(r_1, r_n) >= D / 2 and

    contribution <= 4 albedo p_max max(R_tx,max W_rx, R_rx,max W_tx) / D^2,

a bounded weight (HG: p_max = (1 + g) / (4 pi (1 - g)^2); Tx: W = 1, R_max = (m + 1) / 2 pi;
Rx: W = A pi sin^2 FOV, R_max = A). For n >= 2 the weight is bounded unless x_1 lies
near the transmitter and x_n near the receiver at once; there the equiangular points
(density >= N_E h / (pi r_n^2) along the segment) make the second moment finite:
with c <= (1/h) r_n^2 / (r_1^2 + r_n^2), E[c^2] ~ int dr_1 int r_n dr_n r_n^2 / (r_1^2 + r_n^2)^2
is finite near r_1 = r_n = 0 (and for n = 2 the third strategy bounds the corner: there the
weight is at most p(cos_1) p(cos_2) T / r_12^2 x W_tgt albedo^2, r_12 ~ D). What stays heavy
at g -> 1 is the product of the two phase peaks on paths nearly collinear with the two
devices, which no one of the three strategies samples (docs/smoke-error-bars.md). Surface vertices
(devices on or near a wall) get the same treatment, which also bounds the 1/r^2 of a wall point next
to a device.
The phase lobe's strategies join these weights (lobe.py); algorithms 2-4's branch from the first segment
and its double-scattering family are in single_scatter.py.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from owcsim.engine.core.arrays import BoolArray, FloatArray, IntArray
from owcsim.engine.integrator.path import BatchState, Paths, device_sets, dot3
from owcsim.engine.sources.devices import Devices


def side_weight(first: FloatArray, last: FloatArray) -> FloatArray:
    """w = first / (first + last) (0 where both vanish): this run's share of a path."""
    total = first + last
    return np.where(total > 0, first / np.where(total > 0, total, 1.0), 0.0)


def device_factor(devices: Devices, i: int, points: FloatArray, c: Any) -> FloatArray:
    """R_i(cos) / W_i * c / r^2 for points (3, n) seen from device i [1/m^2 x c]."""
    v = points - devices.positions[i][:, None]
    r2 = dot3(v, v)
    r = np.sqrt(r2)
    cos = dot3(v, devices.normals[i][:, None]) / r
    toward = (v / r).T if devices.directional else None
    return devices.response_one(i, cos, toward) / devices.total_response(i) * c / r2


def source_factor(ctx: BatchState, points: FloatArray) -> FloatArray:
    """A for medium points (3, n) as first vertices: the source's factor with c = sigma_t(p)."""
    src, _ = device_sets(ctx.scene, ctx.item.direction)
    return device_factor(src, ctx.item.source, points, ctx.medium.sigma_t_at(points.T))


def target_factor(ctx: BatchState, j: int, points: FloatArray) -> FloatArray:
    """B for medium points (3, n) connected to the item's j-th target (c = sigma_t(p))."""
    return device_factor(ctx.targets, int(ctx.tgt[j]), points, ctx.medium.sigma_t_at(points.T))


def surface_target_factor(ctx: BatchState, j: int, points: FloatArray, normals: FloatArray) -> FloatArray:
    """B for surface points (3, n) with unit normals connected to the j-th target (c = |cos| at the point)."""
    y = ctx.t_pos[:, j : j + 1]
    v = y - points
    c = np.abs(dot3(v, normals)) / np.sqrt(dot3(v, v))
    return device_factor(ctx.targets, int(ctx.tgt[j]), points, c)


def first_vertex_factor(
    ctx: BatchState, paths: Paths, prim: IntArray, t: FloatArray, t_col: FloatArray, collided: BoolArray
) -> FloatArray:
    """`Paths.first` for paths on their first segment: the source factor at their first vertex.

    The first vertex is the collision or the surface hit (c = |cos| of the surface normal
    with the ray); paths with neither get 0 (they make no connection). Algorithms 2-4
    (`collided` all False) use R / W c / r^2; algorithm 5 (`KernelSettings.both_sides`)
    uses F = R / W c T(source -> x_1) / r^2 with c = 1 at a medium vertex
    (`connection_weight`).
    """
    scene = ctx.scene
    src, _ = device_sets(scene, ctx.item.direction)
    i = ctx.item.source
    hit = prim >= 0
    t1 = np.where(collided, t_col, np.where(hit, t, 1.0))
    points = paths.origins + t1 * paths.directions
    c = np.where(collided, 1.0, 0.0) if ctx.settings.both_sides else np.zeros(len(t1))
    if collided.any() and not ctx.settings.both_sides:
        c[collided] = ctx.medium.sigma_t_at(points[:, collided].T)
    surf = hit & ~collided
    if surf.any():
        normals = scene.intersector.normals_soa.take(prim[surf], axis=1)
        c[surf] = np.abs(dot3(normals, paths.directions[:, surf]))
    factor = np.where(collided | hit, device_factor(src, i, points, c), 0.0)
    if ctx.settings.both_sides and scene.medium is not None:
        live = (collided | hit).nonzero()[0]
        if len(live):
            factor[live] *= ctx.medium.transmittance(paths.origins[:, live].T, paths.directions[:, live].T, t1[live])
    return factor


def first_medium_factor(ctx: BatchState, points: FloatArray, transmittance: FloatArray) -> FloatArray:
    """F for medium points (3, n) as first vertices of algorithm 5: R / W T(source -> p) / r^2."""
    src, _ = device_sets(ctx.scene, ctx.item.direction)
    return device_factor(src, ctx.item.source, points, transmittance)


def connection_weight(
    ctx: BatchState,
    paths: Paths,
    vertex: IntArray | None,
    column: IntArray,
    d: FloatArray,
    tr: FloatArray,
    response: FloatArray,
    vertex_factor: FloatArray,
    surface: bool,
    mid_g: FloatArray | None = None,
    lobe: FloatArray | None = None,
) -> FloatArray:
    """This run's share of the paths whose last vertices `paths`[vertex] connect to the targets `column` (algorithm 5).

    With F = `Paths.first` (the source factor of x_1, transmittance included) and
    L = R_tgt / W_tgt c T(x_n -> target) / d^2 (c = |cos| at a surface, 1 in the medium):
    - one vertex (n = 1): F / (F + L);
    - n >= 2: the balance heuristic of the two unidirectional strategies, F rho_1 / (F rho_1 + L rho_n),
      rho the direction density leaving the end vertex (phase, or 1/vertex at a surface);
    - two medium vertices and no reflection (Tx -> x_1 -> x_2 -> Rx, `mid_g` = T / r^2 of
      the edge x_1 -> x_2): the balance heuristic of three strategies, the third being
      `connect_from_target` (x_1 from the transmitter, x_2 from the receiver, joined):
      q_self / (q_self + q_other + F L), q_self = F rho_1 g, q_other = L rho_2 g.
    `lobe` (per connected vertex, with KernelSettings.phase_lobe): Lambda of the phase-lobe strategies
    (module docstring), added to the n = 1 medium family's denominator: F / (F + L + Lambda).
    Every strategy evaluates the same function of the path, so the shares sum to 1.
    `response` R_tgt(cos) and `vertex_factor` (cos at a surface vertex, the phase function's value
    at a medium vertex) come from the connection (context.BatchContext.connect), which computed them.
    """

    def rows(a: Any) -> Any:  # the connected vertices' values (`vertex` None: every vertex, in order)
        return a if vertex is None else a.take(vertex)

    t_total = ctx.t_total
    resp = response / (t_total[0] if len(t_total) == 1 else t_total.take(column))
    rho_t: Any
    if surface:
        last = resp * vertex_factor * tr / (d * d)
        rho_t = 1.0 / np.pi
    else:
        last = resp * tr / (d * d)
        rho_t = vertex_factor
    first = rows(paths.first)
    k, s = rows(paths.k), rows(paths.s)
    depth = k + s
    if len(depth) == 0:  # no connection to weigh (the caller had every shadow ray blocked)
        return np.zeros(0)
    if depth.min() >= 2:  # every path has several vertices (the usual step past the first)
        a = first * rows(paths.first_rho)
        b = last * rho_t
    else:
        several = depth >= 2
        a = np.where(several, first * rows(paths.first_rho), first)
        b = np.where(several, last * rho_t, last)
    if mid_g is not None and not surface:
        three = (k == 0) & (s == 2)
        if three.any():
            g = rows(mid_g)
            a = np.where(three, a * g, a)
            b = np.where(three, b * g + first * last, b)
    if lobe is not None and not surface:  # Tx -> p -> Rx: the two lobes' densities join the emissions'
        b = np.where((k == 0) & (s == 1), b + lobe, b)
    return side_weight(a, b)
