"""Connections of medium vertices to point devices with bounded weights (physics.md section 4, heavy tails).

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
identically by the two runs (each stores its source-side factor in `_Paths.first` at
the first vertex and computes the target-side factor at the connection, `side_weight`),
and w_tx + w_rx = 1, so the sum of the two runs is unbiased for the whole family
(each run is unbiased for its family with any path-dependent weight; Veach 1997, ch. 9).
Algorithms 2-4 leave transmittances out of A and B (any positive path function gives a
partition). Algorithm 5 (`connection_weight`) uses the exact balance heuristic of its
strategies with free-flight distances (Veach 1997, section 10.2): F = R / W c T(device ->
x) / r^2 with c = 1 at a medium vertex (sigma_t cancels between the strategies); for paths
of two or more vertices each factor is multiplied by the density of the direction leaving
its end vertex (the phase function there, or 1/pi at a surface: `_Paths.first_rho`), which
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

The phase lobe (`lobe_connections`, KernelSettings.phase_lobe). For a phase function with a tall peak
(HG g -> +-1) the single-scattering integrand of Tx -> p -> Rx concentrates on the Tx-Rx line, where the
scattering angle theta ~ rho (1/r_1 + 1/r_n) lies inside the lobe of width ~ (1 - |g|): neither device's
emission samples that thin needle, so a run either misses it (most runs, biased low with a small error
bar) or hits it with a huge weight (the bound above grows with p_max ~ 1/(1 - g)^2). Each device then
also samples the lobe: a direction with density p(cos alpha) about the axis toward the other device
(`phase.sample`), a free-flight collision along it. In the triangle Tx, p, Rx the scattering angle is
the sum of the angles at the two devices, theta = alpha + beta, so for a phase function decreasing in
theta p(theta) <= min(p(alpha), p(beta)). The n = 1 family is then shared among four strategies by the
balance heuristic on their densities (per volume, sigma_t(p) common to all and left out):

    F = R_src / W_src T_src / r_src^2,   L = R_tgt / W_tgt T_tgt / r_tgt^2   (the emissions, as above),
    Lambda = p(cos alpha) T_src / r_src^2 + p(cos beta) T_tgt / r_tgt^2     (the two lobes),

the emission runs weighting by F / (F + L + Lambda) (L / (...) from the other side) and the lobe samples
by their own term over the same sum. Every strategy's estimate is then f / (sigma_t (F + L + Lambda)) and

    contribution <= albedo R_src R_tgt p(theta) T / (r_src^2 r_tgt^2 Lambda)
                 <= albedo R_src,max R_tgt,max min(1 / r_src^2, 1 / r_tgt^2),

at most 4 albedo R_tx,max R_rx,max / D^2 whatever g (for g < 0 the lobe about the axis points away from
the other device, onto the axis beyond the source, where the backward peak lies). The lobe is drawn when
the phase function's peak exceeds LOBE_PEAK times the isotropic 1 / (4 pi) (`phase_lobe_wanted`), in
runs of algorithm 5 (from both devices, or from one: `lobe_connections`) and of algorithms 2-4 from both
devices, in grey scenes; at lower peaks the weights above are already
bounded by a moderate p_max and nothing changes. Algorithms 2-4 place points on the emissions' first
segments (time strata and equiangular points, density n_T + n_E per length) rather than collisions:
their shares (segments._direction_mis) weigh R / W / r^2 (n_T + n_E) of each device against
sigma_t Lambda, the lobes' densities per volume (`lobe_volume_density`), and the bound is the same.

Algorithms 2-4 (`first_segment_branch`). The points-on-segments estimators connect a point p of
the source's k-th segment to the target; the target's own side samples the same single-
scattering family by a collision p on its first segment, a phase-sampled branch with k
reflections and next-event estimates at the branch's surface vertices. Run from both
devices (`KernelSettings.mis`), the two share each path by the same partition (k = 0,
where both sides place points on their first segment, keeps the exact balance heuristic of
kernel._direction_mis). Algorithm 2 (3) alone is then the backward (forward) points plus
the forward (backward) branch; algorithm 4 runs all of them.

Algorithm 4's double-scattering family (`first_segment_branch(double=True)`, the report's section 9): light
in-scattered from the source at p_in on the source's first ray is carried along a ray
from p_in (its phase-sampled direction, then k <= K reflections) and out-scattered toward
the target at points p_out along every later segment. Both runs sample the family
Tx -> p_in -> (k reflections) -> p_out -> Rx (each from its own side), weighted by
the same partition A / (A + B) with x_1 = p_in, x_n = p_out. Surface vertices of that
branch make no connections: Tx -> p_in -> (k) -> Rx is the s = 1 family of algorithm 2,
estimated elsewhere, so nothing is counted twice.
"""

from __future__ import annotations

import numpy as np


def _dot(a, b):
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]


#: The phase lobe is sampled (KernelSettings.phase_lobe) when the phase function's peak exceeds this multiple of
#: the isotropic 1 / (4 pi): HG |g| >= 0.81 (4 pi p(1) = (1 + g) / (1 - g)^2: 45 at g = 0.8, 56 at 0.82, 190
#: at 0.9). Below it the emissions' weights, bounded with p_max, gave honest error bars (g = 0.7 and 0.9:
#: docs/smoke-error-bars.md) and such scenes keep their bits.
LOBE_PEAK = 50.0


def phase_lobe_wanted(phase) -> bool:
    """True when the phase function's forward or backward peak exceeds LOBE_PEAK / (4 pi) [1/sr]."""
    peak = float(np.max(phase.eval(np.array([1.0, -1.0]))))
    return 4.0 * np.pi * peak > LOBE_PEAK


def lobe_axis(ctx, j: int):
    """(source position, unit axis toward the item's j-th target), or None where the two coincide."""
    from owcsim.engine.integrator.kernel import device_sets

    src, _ = device_sets(ctx.scene, ctx.item.direction)
    x = src.positions[ctx.item.source]
    axis = ctx.t_pos[:, j] - x
    length = float(np.sqrt(axis @ axis))
    return None if length == 0.0 else (x, axis / length)


def lobe_source_density(ctx, j: int, points, transmittance):
    """The source's lobe density p(cos alpha) T(source -> p) / r^2 at medium points (3, n) [1/(sr m^2)] for
    the item's j-th target (alpha between p - source and the axis toward the target); 0 without an axis."""
    frame = lobe_axis(ctx, j)
    if frame is None:
        return np.zeros(points.shape[1])
    x, axis = frame
    v = points - x[:, None]
    r2 = _dot(v, v)
    cos = _dot(v, axis[:, None]) / np.sqrt(r2)
    return ctx.scene.phase.eval(cos) * transmittance / r2


def lobe_volume_density(ctx, y, points):
    """sigma_t(p) Lambda(p) [1/m^3]: the two lobe strategies' densities per volume at medium points (3, n)
    between the item's source and the target at `y` (3,) (algorithms 2-4, whose point densities
    segments.first_segment_density are per volume); 0 where the devices coincide."""
    from owcsim.engine.integrator.kernel import device_sets

    scene = ctx.scene
    medium, phase = scene.medium, scene.phase
    src, _ = device_sets(scene, ctx.item.direction)
    x = src.positions[ctx.item.source]
    axis = np.asarray(y, float) - x
    length = float(np.sqrt(axis @ axis))
    if length == 0.0:
        return np.zeros(points.shape[1])
    axis = axis / length
    uniform = medium.uniform_coefficients  # (sigma_t, sigma_s) of a medium the same everywhere, else None
    out = np.zeros(points.shape[1])
    for pos, a in ((x, axis), (np.asarray(y, float), -axis)):  # the source's lobe, then the target's
        v = points - pos[:, None]
        r2 = _dot(v, v)
        r = np.sqrt(r2)
        if uniform is not None:
            tr = np.exp(-uniform[0] * r)  # = medium.transmittance
        else:
            tr = medium.transmittance(np.broadcast_to(pos, (len(r), 3)), (v / r).T, r)
        cos = v[0] * a[0] + v[1] * a[1] + v[2] * a[2]
        cos /= r
        tr *= phase.eval(cos)
        tr /= r2
        out += tr
    return out * (uniform[0] if uniform is not None else medium.sigma_t_at(points.T))


def lobe_connections(ctx, n: int, rng, segments: bool = False) -> None:
    """The source's phase-lobe strategy for Tx -> p -> Rx (algorithm 5 from both devices; module docstring).

    Per target j and path of the batch: a direction w with density p(w . a) about the unit axis a toward
    the target (`phase.sample`), a free-flight collision p at distance t along it (density sigma_t T), and
    the connection to the target:
        dH = albedo R_src(w) / p(w . a) x p(cos theta) R_tgt T(p -> y) / d^2 x Lambda_src / (F + L + Lambda),
    (Lambda_src = p(cos alpha) T(source -> p) / r^2, the same share as `connection_weight` gives the
    emissions), tallied at (k, s) = (0, 1) with the batch's path of the same index. `segments`
    (algorithms 2-4): the emissions place points on their first segments instead of collisions, so the
    share is sigma_t Lambda_src over the sum of both devices' point densities
    (segments.first_segment_density) and sigma_t Lambda (as segments._direction_mis weighs them).
    Algorithm 5 from one side (no partner run): the source's two strategies share the path,
    Lambda_src / (F + Lambda_src), and its emission F / (F + Lambda_src) (kernel._medium_next_events); the
    weight then keeps the one-sided 1 / d^2 near the target but no longer grows with the peak.
    """
    from owcsim.engine.core.constants import SPEED_OF_LIGHT
    from owcsim.engine.integrator.kernel import device_sets

    scene = ctx.scene
    medium, isect, phase = scene.medium, scene.intersector, scene.phase
    src, _ = device_sets(scene, ctx.item.direction)
    i = ctx.item.source
    n_src, w_src = src.normals[i], src.total_response(i)
    for j in range(len(ctx.tgt)):  # a loop over devices
        frame = lobe_axis(ctx, j)
        u = rng.random((3, n))
        if frame is None:
            continue
        x, axis = frame
        dirs = phase.sample(np.repeat(axis[:, None], n, axis=1), u[0], u[1])
        r_src = src.response_one(i, _dot(dirs, n_src[:, None]), dirs.T if src.directional else None)
        live = (r_src > 0).nonzero()[0]
        if len(live) == 0:
            continue
        dirs, r_src = dirs.take(live, axis=1), r_src.take(live)
        origins = np.repeat((x + isect.offset * n_src)[:, None], len(live), axis=1)
        prim, t_hit = isect.intersect(origins.T, dirs.T)
        seg = np.where(prim >= 0, t_hit, scene.medium_far_distance)
        t_col, collided = medium.sample_distance(origins.T, dirs.T, seg, u[2].take(live))
        sel = collided.nonzero()[0]
        if len(sel) == 0:
            continue
        live, dirs, r_src, t_col = live.take(sel), dirs.take(sel, axis=1), r_src.take(sel), t_col.take(sel)
        origins = origins[:, : len(sel)]
        points = origins + t_col * dirs
        sigma_t, sigma_s = medium.coefficients_at(points.T)
        y = ctx.t_pos[:, j : j + 1]
        out = y - points
        d2 = _dot(out, out)
        d = np.sqrt(d2)
        out /= d
        keep = (sigma_s > 0).nonzero()[0]
        if not scene.all_visible and len(keep):
            o_k, w_k = points.take(keep, axis=1), out.take(keep, axis=1)
            keep = keep[~isect.occluded(o_k.T, w_k.T, d.take(keep) - 2.0 * isect.offset)]
        if len(keep) == 0:
            continue
        live, dirs, r_src, t_col, points, out, d2, d = (
            live.take(keep),
            dirs.take(keep, axis=1),
            r_src.take(keep),
            t_col.take(keep),
            points.take(keep, axis=1),
            out.take(keep, axis=1),
            d2.take(keep),
            d.take(keep),
        )
        albedo = sigma_s.take(keep) / sigma_t.take(keep)
        t_idx = int(ctx.tgt[j])
        r_tgt = ctx.targets.response_one(
            t_idx, _dot(out, ctx.t_nrm_neg[:, j : j + 1]), -out.T if ctx.t_directional else None
        )
        t_src = medium.transmittance(origins[:, : len(live)].T, dirs.T, t_col)
        t_tgt = medium.transmittance(points.T, out.T, d)
        lam_src = lobe_source_density(ctx, j, points, t_src)
        v = points - x[:, None]
        r2_src = _dot(v, v)
        lam_tgt = phase.eval(_dot(out, axis[:, None])) * t_tgt / d2  # the target's lobe: cos beta = out . a
        if not (segments or ctx.settings.both_sides):  # algorithm 5 from one side: F / (F + Lambda_src) and back
            total = r_src / w_src * t_src / r2_src
        elif segments:  # algorithms 2-4: densities per volume (segments._direction_mis)
            from owcsim.engine.integrator.segments import first_segment_density

            sig = sigma_t.take(keep)
            lam_src, lam_tgt = sig * lam_src, sig * lam_tgt
            total = first_segment_density(ctx, src, i, y[:, 0], points)
            total += first_segment_density(ctx, ctx.targets, t_idx, x, points)
        else:
            total = r_src / w_src * t_src / r2_src  # F (the source's emission, as first_medium_factor)
            total += r_tgt / ctx.t_total[j] * t_tgt / d2  # L
        total += lam_src
        if segments or ctx.settings.both_sides:
            total += lam_tgt
        sampled = phase.eval(_dot(dirs, axis[:, None]))  # p(w . a), this strategy's direction density
        power = albedo * r_src / sampled * phase.eval(_dot(dirs, out)) * r_tgt * t_tgt / d2
        power *= np.where(total > 0, lam_src / np.where(total > 0, total, 1.0), 0.0)
        ok = (power > 0).nonzero()[0]
        if len(ok) == 0:
            continue
        ctx.record(
            np.full(len(ok), j, np.int64),
            np.zeros(len(ok), np.int64),
            np.ones(len(ok), np.int64),
            (t_col.take(ok) + d.take(ok)) / SPEED_OF_LIGHT,
            power.take(ok),
            live.take(ok),
        )


def side_weight(first, last):
    """w = first / (first + last) (0 where both vanish): this run's share of a path."""
    total = first + last
    return np.where(total > 0, first / np.where(total > 0, total, 1.0), 0.0)


def _device_factor(devices, i: int, points, c):
    """R_i(cos) / W_i * c / r^2 for points (3, n) seen from device i [1/m^2 x c]."""
    v = points - devices.positions[i][:, None]
    r2 = _dot(v, v)
    r = np.sqrt(r2)
    cos = _dot(v, devices.normals[i][:, None]) / r
    toward = (v / r).T if devices.directional else None
    return devices.response_one(i, cos, toward) / devices.total_response(i) * c / r2


def source_factor(ctx, points):
    """A for medium points (3, n) as first vertices: the source's factor with c = sigma_t(p)."""
    from owcsim.engine.integrator.kernel import device_sets

    src, _ = device_sets(ctx.scene, ctx.item.direction)
    return _device_factor(src, ctx.item.source, points, ctx.scene.medium.sigma_t_at(points.T))


def target_factor(ctx, j: int, points):
    """B for medium points (3, n) connected to the item's j-th target (c = sigma_t(p))."""
    return _device_factor(ctx.targets, int(ctx.tgt[j]), points, ctx.scene.medium.sigma_t_at(points.T))


def first_vertex_factor(ctx, paths, prim, t, t_col, collided):
    """`_Paths.first` for paths on their first segment: the source factor at their first vertex.

    The first vertex is the collision or the surface hit (c = |cos| of the surface normal
    with the ray); paths with neither get 0 (they make no connection). Algorithms 2-4
    (`collided` all False) use R / W c / r^2; algorithm 5 (`KernelSettings.both_sides`)
    uses F = R / W c T(source -> x_1) / r^2 with c = 1 at a medium vertex
    (`connection_weight`).
    """
    from owcsim.engine.integrator.kernel import device_sets

    scene = ctx.scene
    src, _ = device_sets(scene, ctx.item.direction)
    i = ctx.item.source
    hit = prim >= 0
    t1 = np.where(collided, t_col, np.where(hit, t, 1.0))
    points = paths.origins + t1 * paths.directions
    c = np.where(collided, 1.0, 0.0) if ctx.settings.both_sides else np.zeros(len(t1))
    if collided.any() and not ctx.settings.both_sides:
        c[collided] = scene.medium.sigma_t_at(points[:, collided].T)
    surf = hit & ~collided
    if surf.any():
        normals = scene.intersector.normals_soa.take(prim[surf], axis=1)
        c[surf] = np.abs(_dot(normals, paths.directions[:, surf]))
    factor = np.where(collided | hit, _device_factor(src, i, points, c), 0.0)
    if ctx.settings.both_sides and scene.medium is not None:
        live = (collided | hit).nonzero()[0]
        if len(live):
            factor[live] *= scene.medium.transmittance(paths.origins[:, live].T, paths.directions[:, live].T, t1[live])
    return factor


def first_medium_factor(ctx, points, transmittance):
    """F for medium points (3, n) as first vertices of algorithm 5: R / W T(source -> p) / r^2."""
    from owcsim.engine.integrator.kernel import device_sets

    src, _ = device_sets(ctx.scene, ctx.item.direction)
    return _device_factor(src, ctx.item.source, points, transmittance)


def connection_weight(ctx, paths, vertex, column, d, tr, response, vertex_factor, surface: bool, mid_g=None, lobe=None):
    """This run's share of the paths whose last vertices `paths`[vertex] connect to the targets `column` (algorithm 5).

    With F = `_Paths.first` (the source factor of x_1, transmittance included) and
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
    at a medium vertex) come from the connection (kernel._Context.connect), which computed them.
    """

    def rows(a):  # the connected vertices' values (`vertex` None: every vertex, in order)
        return a if vertex is None else a.take(vertex)

    t_total = ctx.t_total
    resp = response / (t_total[0] if len(t_total) == 1 else t_total.take(column))
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


def connect_from_target(ctx, mp, points, rng) -> None:
    """Third strategy for Tx -> x_1 -> x_2 -> Rx (algorithm 5 from both devices, forward runs only).

    x_1 is this path's first vertex (a collision, `mp` just after it: weight
    W_src albedo(x_1), arriving direction mp.directions); x_2 is drawn from the target:
    a direction with pdf R / W_tgt, a free-flight distance along it (density
    sigma_t T(target -> x_2)); the two are joined:
        dH = w * p(cos_1) T(x_1 -> x_2) / r_12^2 * albedo(x_2) * p(cos_2) * W_tgt,
    weighted by F L / (F rho_1 g + L rho_2 g + F L) (`connection_weight`): where x_1 is near
    the transmitter and x_2 near the receiver, the corner neither unidirectional strategy
    samples well, this one carries the path, and its estimate there is bounded.
    """
    first = ((mp.k == 0) & (mp.s == 1)).nonzero()[0]
    if len(first) == 0:
        return
    scene, medium, isect = ctx.scene, ctx.scene.medium, ctx.scene.intersector
    x1 = points.take(first, axis=1)
    arriving = mp.directions.take(first, axis=1)
    w, F, lengths, path = (mp.weights.take(first), mp.first.take(first), mp.lengths.take(first), mp.path.take(first))
    n = len(first)
    for j in range(len(ctx.tgt)):
        t_idx = int(ctx.tgt[j])
        u = rng.random((3, n))
        dirs = np.ascontiguousarray(ctx.targets.sample_directions(t_idx, u[0], u[1]).T)
        pos = ctx.t_pos[:, j : j + 1]
        origin = pos + isect.offset * ctx.t_nrm[:, j : j + 1]
        origins = np.repeat(origin, n, axis=1)
        prim, t_hit = isect.intersect(origins.T, dirs.T)
        seg = np.where(prim >= 0, t_hit, scene.medium_far_distance)
        t_y, col = medium.sample_distance(origins.T, dirs.T, seg, u[2])
        sel = col.nonzero()[0]
        if len(sel) == 0:
            continue
        y = origins.take(sel, axis=1) + t_y.take(sel) * dirs.take(sel, axis=1)
        a = x1.take(sel, axis=1)
        v = y - a
        r12 = np.sqrt(_dot(v, v))
        w12 = v / r12
        keep = (r12 > 0).nonzero()[0]
        if not scene.all_visible and len(keep):
            keep = keep[~isect.occluded(a[:, keep].T, w12[:, keep].T, r12[keep] - 2.0 * isect.offset)]
        if len(keep) == 0:
            continue
        sel, y, a, r12, w12 = (
            sel.take(keep),
            y.take(keep, axis=1),
            a.take(keep, axis=1),
            r12.take(keep),
            w12.take(keep, axis=1),
        )
        dj = dirs.take(sel, axis=1)
        p_cos1, p_cos2 = _dot(arriving.take(sel, axis=1), w12), -_dot(w12, dj)
        p1, p2 = scene.phase.eval(p_cos1), scene.phase.eval(p_cos2)
        g = medium.transmittance(a.T, w12.T, r12) / (r12 * r12)
        to_dev = pos - y
        r2 = np.sqrt(_dot(to_dev, to_dev))
        resp = ctx.targets.response(np.full(len(sel), t_idx), _dot(dj, ctx.t_nrm[:, j : j + 1]), dj.T) / ctx.t_total[j]
        L = resp * medium.transmittance(y.T, (to_dev / r2).T, r2) / (r2 * r2)
        Fs = F.take(sel)
        q_c = Fs * L
        total = Fs * p1 * g + L * p2 * g + q_c
        share = np.where(total > 0, q_c / np.where(total > 0, total, 1.0), 0.0)
        power = w.take(sel) * p1 * g * medium.albedo_at(y.T) * p2 * ctx.t_total[j] * share
        ok = (power > 0).nonzero()[0]
        if len(ok) == 0:
            continue
        ratio = None
        if "ratio" in ctx.out:  # spectral: the ratios at x_1 (k = 0: only smoke per band changes them)
            ratio = mp.ratio.take(first.take(sel.take(ok)), axis=1)
            if ctx.spectra.depth_row:  # sigma_s,b T_b at x_2 over the carrier's, T_b / T_c of x_1 -> x_2
                o_k, d_k = origins.take(sel.take(ok), axis=1), dj.take(ok, axis=1)
                tau = medium.optical_depth(o_k.T, d_k.T, t_y.take(sel.take(ok)))
                tau = tau + medium.optical_depth(a.take(ok, axis=1).T, w12.take(ok, axis=1).T, r12.take(ok))
                ratio = ctx.spectra.estimate_ratio(ctx.spectra.scatter(ratio, tau))
            if ctx.spectra.phase_bands is not None:  # p_b / p_c at x_1 and at x_2
                ratio = ratio[: ctx.spectra.n_bands] * ctx.spectra.phase_ratio(p_cos1.take(ok))
                ratio = ratio * ctx.spectra.phase_ratio(p_cos2.take(ok))
        from owcsim.engine.core.constants import SPEED_OF_LIGHT

        ctx.record(
            np.full(len(ok), j, np.int64),
            np.zeros(len(ok), np.int64),
            np.full(len(ok), 2, np.int64),
            (lengths.take(sel.take(ok)) + r12.take(ok) + r2.take(ok)) / SPEED_OF_LIGHT,
            power.take(ok),
            path.take(sel.take(ok)),  # cell k = 0, s = 2
            ratio,
        )


def _surface_target_factor(ctx, j: int, points, normals):
    """B for surface points (3, n) with unit normals connected to the j-th target (c = |cos| at the point)."""
    y = ctx.t_pos[:, j : j + 1]
    v = y - points
    c = np.abs(_dot(v, normals)) / np.sqrt(_dot(v, v))
    return _device_factor(ctx.targets, int(ctx.tgt[j]), points, c)


def _scatter_on_first_segment(ctx, paths, t_seg, rng):
    """Branches from a free-flight collision p on the source's first segment (weight x albedo), leaving p
    in a phase-sampled direction, with `first` = the source factor at p and s = 1; None if none collide."""
    scene = ctx.scene
    medium = scene.medium
    ok = (np.isfinite(t_seg) & (paths.k + paths.s == 0)).nonzero()[0]
    if len(ok) == 0:
        return None
    base = paths.keep(ok)
    t_in, col = medium.sample_distance(base.origins.T, base.directions.T, t_seg.take(ok), rng.random(len(ok)))
    sel = col.nonzero()[0]
    if len(sel) == 0:
        return None
    br = base.keep(sel)
    t_in = t_in.take(sel)
    p_in = br.origins + t_in * br.directions
    br.weights = br.weights * medium.albedo_at(p_in.T)
    br.first = source_factor(ctx, p_in)
    if ctx.spectra is not None:  # spectral smoke: sigma_s,b T_b over the carrier's (engine/spectral/spectra.py)
        br.ratio = ctx.spectra.scatter(br.ratio, medium.optical_depth(br.origins.T, br.directions.T, t_in))
    u = rng.random((2, len(br)))
    arriving = br.directions
    br.directions = scene.phase.sample(br.directions, u[0], u[1])
    if ctx.spectra is not None and ctx.spectra.phase_bands is not None:  # p_b / p_c of the sampled direction
        br.ratio = ctx.spectra.turn(br.ratio, _dot(arriving, br.directions))
    br.origins, br.lengths, br.s = p_in, br.lengths + t_in, br.s + 1
    return br.keep_where(br.weights > 0)


def first_segment_branch(ctx, paths, t_seg, rng, chain: bool, double: bool) -> None:
    """Scattering at p on the source's first segment, then a branch with k <= K reflections (one traced branch
    serves both families below).

    p is a free-flight collision on the source's own first segment (density
    sigma_t T(o -> p), weight x albedo); the branch leaves p in a phase-sampled direction,
    pays extinction on every segment and reflects (cosine sampling, x rho) up to K times.
    - `chain`: single scattering source -> p -> (k = 1..K) -> target: every surface vertex x
      makes a next-event estimate to the targets at scattering order 1, weighted by
      side_weight(A(p), B(x)). The other device's points-on-segments estimator
      (algorithm 2 backward, 3 forward) samples the same family with the complement
      weight, so its ~1/h tail near this run's source is cut off (module docstring).
    - `double` (algorithm 4's in-then-out family, report section 9): on every branch
      segment `segment_points` places p_out (time strata + equiangular, balance
      heuristic), connected to the targets at scattering order 2, weighted by
      side_weight(A(p), B(p_out)); the other run samples the family from its side.
    """
    from owcsim.engine.integrator.mirrors import branch_surface
    from owcsim.engine.integrator.segments import segment_points

    scene, settings = ctx.scene, ctx.settings
    medium, isect = scene.medium, scene.intersector
    br = _scatter_on_first_segment(ctx, paths, t_seg, rng)
    K, far = settings.max_reflections, scene.medium_far_distance

    def partition(j, pp, points, *_):
        return side_weight(pp.first, target_factor(ctx, j, points))

    for _bounce in range(K + 1):
        if br is None or len(br) == 0:
            return
        prim, t = isect.intersect(br.origins.T, br.directions.T)
        hit = prim >= 0
        if double:
            seg = np.where(hit, t, far)
            live = (np.isfinite(seg)).nonzero()[0]
            segment_points(ctx, br.keep(live), seg.take(live), rng, order=2, weight_fn=partition)
        nxt = (hit & (br.k < K)).nonzero()[0]
        if len(nxt) == 0:
            return
        br = br.keep(nxt)
        ts = t.take(nxt)
        tau = medium.optical_depth(br.origins.T, br.directions.T, ts)
        br.weights = br.weights * np.exp(-tau)  # = medium.transmittance
        if ctx.spectra is not None:
            br.ratio = ctx.spectra.transmit(br.ratio, tau)
        points = br.origins + ts * br.directions
        prims = prim.take(nxt)
        normals = isect.normals_soa.take(prims, axis=1)
        normals *= np.where(_dot(normals, br.directions) > 0, -1.0, 1.0)
        spawn = points + isect.offset * normals
        br.lengths = br.lengths + ts
        br.k = br.k + 1
        if ctx.spectra is not None:  # spectral scenes: rho_b / rho_c of the face (engine/spectral/spectra.py)
            br.ratio = ctx.spectra.reflect(br.ratio, prims)
        # NEE (chain; materials and mirror images included), then reflection from the materials (mirrors.py)
        br.directions, br.weights = branch_surface(ctx, br, points, spawn, normals, prims, rng, chain)
        br.origins = spawn
        br = br.keep_where(br.weights > 0)
