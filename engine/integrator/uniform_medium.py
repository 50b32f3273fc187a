"""Algorithm 5's next-event estimates in a medium the same everywhere, computed on the segments' frames.

The scattering points of a step (each segment's free-flight collision and its equiangular points) lie
at distances s along the segments o + s w; toward a target y (normal n_y) the segment's equiangular
frame gives, with x = s - D (|w| = 1),
    d^2 = h^2 + x^2   (also the denominator of the equiangular density n_E(s)),
    cos_phase = w.(y - p) / d = -x / d,   cos_target = n_y.(p - y) / d = (s n_y.w - n_y.v) / d,
so nothing of size (3, points) is formed and no path field is gathered for the equiangular points.
The estimate is `context.BatchContext.connect`'s (tests/engine/test_medium_next_events.py holds the two
equal), with the throughput of segments.scattering_point_throughput.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np

from owcsim.engine.core.arrays import FloatArray, IntArray
from owcsim.engine.core.constants import SPEED_OF_LIGHT
from owcsim.engine.integrator.lobe import lobe_axis
from owcsim.engine.integrator.path import BatchState, Paths, device_sets, dot, dot_vector, rows
from owcsim.engine.integrator.segments import EquiangularFrame, scattering_point_throughput
from owcsim.engine.sources.devices import Devices

#: Steps with at most this many segments connect their scattering points as one group (`connect_on_segments`)
SMALL_STEP = 2048


class EquiangularFrames:
    """Algorithm 5, one step: the segments that may scatter once more (s < S, finite) and, per target,
    their equiangular frame, computed once and shared by the equiangular points and the collision's
    density n_E. `rows` None: every path's segment (the usual step; no gathers)."""

    def __init__(self, ctx: BatchState, paths: Paths, t_seg: FloatArray):
        ok = (paths.s < ctx.settings.max_scattering) & np.isfinite(t_seg)
        self.rows = None if ok.all() else ok.nonzero()[0]
        self.end = rows(t_seg, self.rows)
        o, w = rows(paths.origins, self.rows), rows(paths.directions, self.rows)
        self.frames = [EquiangularFrame(o, w, ctx.t_pos[:, j : j + 1], 0.0, self.end) for j in range(len(ctx.tgt))]

    def segment_of(self, rows: IntArray) -> IntArray:
        """The frame index of the segments of paths `rows` (each among `self.rows`)."""
        return rows if self.rows is None else np.searchsorted(self.rows, rows)


def _mode(ctx: BatchState, paths: Paths, eq: EquiangularFrames) -> str | None:
    """The depth class of the step's segments: "deep" (depth k + s >= 2, or one-sided runs), "first"
    (depth 0), "second" (depth 1); None where the route does not apply (mixed shallow depths; one side's
    first vertices, shared with the lobe in events.medium_next_events)."""
    settings = ctx.settings
    k, s_order = rows(paths.k, eq.rows), rows(paths.s, eq.rows)
    share = settings.both_sides
    if settings.phase_lobe and not share and len(k) and int((k + s_order).min()) == 0:
        return None  # one side, first vertices: the share with the lobe (`events.medium_next_events`)
    mode = "deep"  # depth >= 2 (the usual step), "first" (depth 0), "second" (depth 1)
    if share and len(k):
        depth = k + s_order
        lo, hi = int(depth.min()), int(depth.max())
        if lo < 2:
            if hi != lo:
                return None
            mode = "first" if lo == 0 else "second"
    return mode


def _segment_values(ctx: BatchState, j: int, paths: Paths, eq: EquiangularFrames, mode: str) -> dict[str, Any] | None:
    """Per segment: the frame (D, h^2, n_E's numerator), n_y.v, n_y.w, the path's weight and length, and the
    two-sided shares' terms (source factors at depth 0, `first` x `first_rho` past it); None when the
    source is directional at depth 0."""
    settings = ctx.settings
    frame = eq.frames[j]
    o, w = rows(paths.origins, eq.rows), rows(paths.directions, eq.rows)
    y, n_y = ctx.t_pos[:, j], ctx.t_nrm[:, j]
    # per segment: n_y.v = n_y.y - n_y.o, n_y.w
    n_v = np.subtract(float(n_y @ y), dot_vector(o, n_y))
    n_w = dot_vector(w, n_y)
    seg = {
        "D": frame.D,
        "h2": frame.h2,
        "n_e": frame.scale * settings.equiangular_points,
        "n_v": n_v,
        "n_w": n_w,
        "w": rows(paths.weights, eq.rows),
        "length": rows(paths.lengths, eq.rows),
    }
    if mode == "first":  # the source's factor at the points: u = o - source, per segment |u|^2, u.w, n.u, n.w
        src, _ = device_sets(ctx.scene, ctx.item.direction)
        i = ctx.item.source
        if src.directional:
            return None
        u = o - src.positions[i][:, None]
        n_src = src.normals[i]
        seg["uu"] = dot(u, u)
        seg["uw2"] = 2.0 * dot(u, w)
        seg["nu"] = dot_vector(u, n_src)
        seg["nw"] = dot_vector(w, n_src)
        lobe = lobe_axis(ctx, j) if settings.phase_lobe else None
        if lobe is not None:  # the two lobe densities (lobe.py): per segment u.a, w.a, (y - o).a
            axis = lobe[1]
            seg["ua"] = dot_vector(u, axis)
            seg["wa"] = dot_vector(w, axis)
            seg["ya"] = np.subtract(float(axis @ y), dot_vector(o, axis))
    elif settings.both_sides:
        k, s_order = rows(paths.k, eq.rows), rows(paths.s, eq.rows)
        seg["a"] = rows(paths.first, eq.rows) * rows(paths.first_rho, eq.rows)
        if mode == "second":  # Tx -> x_1 -> x_2 -> Rx: F on those segments, 0 on the others
            seg["F3"] = np.where((k == 0) & (s_order == 1), rows(paths.first, eq.rows), 0.0)
    return seg


def connect_on_segments(
    ctx: BatchState,
    j: int,
    paths: Paths,
    eq: EquiangularFrames,
    s_eq: FloatArray,
    collision_rows: IntArray,
    t_col: FloatArray,
) -> bool:
    """The medium branch of `connect` for algorithm 5's scattering points, computed on their segments.

    The points lie at distances s along the segments o + s w of `eq` (equiangular points `s_eq`
    (n_eq, segments), collisions of the paths `collision_rows` at t_col); toward target j the frame gives
    d, cos_phase and cos_target (module docstring). The estimate is `connect`'s, with the throughput of
    segments.scattering_point_throughput:
        dH = w T(o -> p) sigma_s / (p_ff + n_E) x p(cos_phase) L W_y x share,   L = R_y / W_y T(p -> y) / d^2,
    and in two-sided runs the share of weights.connection_weight, by the depth k + s of the paths:
    - 0 (the point is the path's first vertex): F / (F + L), F = R_src / W_src T(o -> p) / r^2
      (weights.first_medium_factor; r, cos at the source from the segment: r^2 = |u + s w|^2,
      u = o - source);
    - >= 1: a / (a + L p + F L / g), a = F rho_1 (`Paths.first`, `first_rho`), the last term only for
      Tx -> x_1 -> x_2 -> Rx (k = 0, s = 1 before the point; g = T(o -> p) / s^2, the third strategy).
    Applies to a medium the same everywhere, grey scenes, every target visible from every point
    (`Scene.all_visible`), devices whose response needs only the cosine, and paths of one depth class
    (algorithm 5's steps: all paths of a step have depth = step); returns False (nothing done)
    otherwise. The equiangular points and the collisions are tallied as two groups (the grid broadcasting
    over the segments, the collisions gathering theirs), or in steps of at most SMALL_STEP segments as one.
    """
    scene = ctx.scene
    medium = ctx.medium
    if medium.uniform_coefficients is None or ctx.ratios is not None or not scene.all_visible or ctx.t_directional:
        return False
    mode = _mode(ctx, paths, eq)
    if mode is None:
        return False
    seg = _segment_values(ctx, j, paths, eq, mode)
    if seg is None:
        return False
    k, s_order = rows(paths.k, eq.rows), rows(paths.s, eq.rows)
    n_eq = len(s_eq)
    per_path = (k, s_order + 1, rows(paths.path, eq.rows))
    col = eq.segment_of(collision_rows)
    # one group for a few segments: every per-segment value expanded, half the numpy calls (whose fixed
    # cost dominates small steps)
    blocks: list[tuple[FloatArray, dict[str, Any] | None]]
    fields_of: list[tuple[Any, ...] | None]
    if len(k) <= SMALL_STEP and len(col):

        def expand(v: Any) -> Any:
            return np.concatenate((v,) * n_eq + (v.take(col),))

        blocks = [(np.concatenate((s_eq.reshape(-1), t_col)), {key: expand(v) for key, v in seg.items()})]
        fields_of = [tuple(expand(v) for v in per_path)]
    else:
        blocks = [(s_eq, seg), (t_col, None)]
        fields_of = [None, None]
    for (s, g), fields in zip(blocks, fields_of):
        if s.size == 0:
            continue
        at = None
        if g is None:
            at, g = col, {key: v.take(col) for key, v in seg.items()}
        power, delay = _point_estimates(ctx, j, s, g, mode)
        power, delay = power.reshape(-1), delay.reshape(-1)
        if fields is None:
            fields = tuple(np.concatenate((v,) * n_eq) if at is None else v.take(at) for v in per_path)
        n_points = len(power)
        live = None if power.min() > 0 else power.nonzero()[0]
        if live is not None:
            power, delay, fields = power.take(live), delay.take(live), tuple(v.take(live) for v in fields)
        medium.evaluations += n_points + len(power)  # o -> p of every point, p -> y of those that count
        ctx.record(np.full(len(power), j), fields[0], fields[1], delay, power, fields[2])
    return True


def _point_estimates(ctx: BatchState, j: int, s: FloatArray, g: dict[str, Any], mode: str) -> tuple[Any, Any]:
    """(dH, delay [s]) of the points at distances `s` [m] on segments with values `g` (`_segment_values`)."""
    uniform = ctx.medium.uniform_coefficients
    assert uniform is not None  # (connect_on_segments checked it)
    sigma_t, sigma_s = uniform
    phase = ctx.phase
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
    resp = ctx.targets.response_one(int(ctx.tgt[j]), cos_t)
    t_o = np.multiply(s, -sigma_t)
    np.exp(t_o, out=t_o)  # T(o -> p) = medium.transmittance
    n_e = np.divide(g["n_e"], d2)  # the equiangular density n_E(s) (segments.EquiangularFrame.density)
    power = scattering_point_throughput(g["w"], t_o, sigma_t, sigma_s, n_e)
    first = lobe_d = None
    if mode == "first":
        first, lobe_d = _source_factors(ctx, s, g, t_o, phase.eval)
    t_c = np.multiply(d, -sigma_t, out=t_o if mode != "second" else None)
    np.exp(t_c, out=t_c)  # T(p -> y)
    resp *= t_c
    resp /= d2  # L W_y = R_y T(p -> y) / d^2
    power *= resp
    power *= p
    if ctx.settings.both_sides:  # weights.connection_weight
        resp *= 1.0 / ctx.t_total[j]  # L
        power *= _share(s, g, resp, p, t_o, t_c, d2, inv_d, first, lobe_d, phase.eval)
    delay = np.add(s, g["length"])
    delay += d
    delay *= 1.0 / SPEED_OF_LIGHT
    return power, delay


def _source_factors(
    ctx: BatchState, s: FloatArray, g: dict[str, Any], t_o: FloatArray, phase: Callable[[Any], Any]
) -> tuple[FloatArray, FloatArray | None]:
    """At depth 0: F = R_src / W_src T(o -> p) / r^2 at the points, and the source's lobe density
    p(cos alpha) T(o -> p) / r^2, cos alpha = (u.a + s w.a) / r (None without the lobe)."""
    src: Devices
    src, _ = device_sets(ctx.scene, ctx.item.direction)
    i = ctx.item.source
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
    lobe_d = None
    if "ua" in g:  # the source's lobe p(cos alpha) T(o -> p) / r^2, cos alpha = (u.a + s w.a) / r
        lobe_d = s * g["wa"]
        lobe_d += g["ua"]
        lobe_d /= np.sqrt(r2)
        lobe_d = phase(lobe_d)
        lobe_d *= t_o
        lobe_d /= r2
    return first, lobe_d


def _share(
    s: FloatArray,
    g: dict[str, Any],
    resp: FloatArray,
    p: FloatArray,
    t_o: FloatArray,
    t_c: FloatArray,
    d2: FloatArray,
    inv_d: FloatArray,
    first: FloatArray | None,
    lobe_d: FloatArray | None,
    phase: Callable[[Any], Any],
) -> FloatArray:
    """This run's share (weights.connection_weight) from L = `resp`: F / (F + L (+ Lambda)) at depth 0
    (`first` given), else a / (a + L p (+ F L / g)). `resp` is overwritten with the share."""
    if first is not None:  # F / (F + L (+ Lambda))
        resp += first
        num = first
        if lobe_d is not None:  # + the target's lobe p(cos beta) T(p -> y) / d^2, cos beta = ((y - o).a - s w.a) / d
            cos_b = np.multiply(s, g["wa"])
            np.subtract(g["ya"], cos_b, out=cos_b)
            cos_b *= inv_d
            lobe_d += phase(cos_b) * t_c / d2
            resp += lobe_d
    else:  # a / (a + L p (+ F L / g))
        num = g["a"]
        second = "F3" in g
        if second:
            extra = resp * g["F3"]
            extra *= s
            extra *= s
            np.divide(extra, t_o, out=extra, where=extra > 0)  # F L s^2 / T(o -> p) (0 elsewhere)
        resp *= p
        resp += num
        if second:
            resp += extra
    if num.min(initial=1.0) > 0:  # then the denominator is > 0
        np.divide(num, resp, out=resp)
    else:
        np.divide(num, resp, out=resp, where=resp > 0)  # (all terms 0: power is 0)
    return resp
