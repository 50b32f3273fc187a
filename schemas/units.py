"""Values that are valid but plausible only in another unit: warnings, not errors.

The document is in SI units (metres, seconds) with angles in degrees (`_deg`). A user who writes a
room in centimetres (500 x 400 x 300), a field of view in radians (`fov_deg: 1.48`) or a half-power
semi-angle in radians (`half_power_semi_angle_deg: 1.047`) gets a valid scene that runs and returns
the wrong numbers without a word. These rules flag such values, one sentence per suspicious value
(devices sharing it are named together); the engine puts the sentences in the result's `warnings`,
the command line prints them (`owcsim run`, `owcsim validate`). A value past a threshold can be
intended (a 1.5 deg detector behind a lens, a 150 m hall): the scene still runs.

Thresholds (documented in docs/scene.md and the fields' descriptions):
- an angle in degrees under ANGLE_MIN_DEG = 2 deg (`fov_deg`, `half_power_semi_angle_deg`): indoor
  links use tens of degrees, and every value up to pi/2 = 1.571 is also a valid angle in radians;
- a length over LENGTH_MAX_M = 100 m (a room side, a furniture box or inline mesh extent, the
  surfaces' extent): larger than a sports hall, and 100 times a plausible size in centimetres;
- a time bin over TIME_BIN_MAX_S = 1 us (light travels 300 m in it) or a window end over
  T_MAX_MAX_S = 1 ms: nanoseconds meant.
"""

from __future__ import annotations

import math
from collections import defaultdict
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from .scene import SceneSpec

#: Angles given in degrees below this [deg] are flagged (radians meant?).
ANGLE_MIN_DEG = 2.0
#: Lengths above this [m] are flagged (centimetres or millimetres meant?).
LENGTH_MAX_M = 100.0
#: A CIR bin above this [s] is flagged (nanoseconds meant?).
TIME_BIN_MAX_S = 1e-6
#: A time window ending after this [s] is flagged.
T_MAX_MAX_S = 1e-3


def _names(where: list[str]) -> str:
    return ", ".join(where[:3]) + (f" and {len(where) - 3} more" if len(where) > 3 else "")


def _lambertian_order(half_angle_deg: float) -> float:
    """m = -ln 2 / ln cos(Phi_1/2) (physics.md section 2)."""
    return -math.log(2.0) / math.log(math.cos(math.radians(half_angle_deg)))


def _angle_warnings(spec: SceneSpec) -> list[str]:
    fov: dict[float, list[str]] = defaultdict(list)
    for i, r in enumerate(spec.receivers):
        if r.fov_deg < ANGLE_MIN_DEG:
            fov[r.fov_deg].append(f"receivers[{i}]" + (f" ({r.id})" if r.id else ""))
    for i, g in enumerate(spec.receiver_grids):
        if g.fov_deg < ANGLE_MIN_DEG:
            fov[g.fov_deg].append(f"receiver_grids[{i}] ({g.id_prefix})")
    out = []
    for value, where in fov.items():
        radians = (
            f" ({value:g} rad would be {math.degrees(value):.4g} deg)" if value <= math.pi / 2 else ""
        )  # a valid half-angle in radians
        out.append(
            f"fov_deg = {value:g} of {_names(where)}: a field of view under {ANGLE_MIN_DEG:g} deg is unusual; "
            f"the field is in degrees{radians}"
        )
    half: dict[float, list[str]] = defaultdict(list)
    for i, t in enumerate(spec.transmitters):
        if t.half_power_semi_angle_deg is not None and t.half_power_semi_angle_deg < ANGLE_MIN_DEG:
            half[t.half_power_semi_angle_deg].append(f"transmitters[{i}]" + (f" ({t.id})" if t.id else ""))
    for value, where in half.items():
        radians = ""
        if value < math.pi / 2:
            deg = math.degrees(value)
            radians = f" ({value:g} rad would be {deg:.4g} deg, order {_lambertian_order(deg):.3g})"
        out.append(
            f"half_power_semi_angle_deg = {value:g} of {_names(where)}: a half-power semi-angle under "
            f"{ANGLE_MIN_DEG:g} deg (Lambertian order {_lambertian_order(value):.3g}) is unusual; the field is in "
            f"degrees{radians}"
        )
    return out


def _sides(lo, hi) -> str:
    return " x ".join(f"{b - a:g}" for a, b in zip(lo, hi))


def _length_warnings(spec: SceneSpec, extent_m: float | None) -> list[str]:
    out = []
    tail = "lengths are in metres (were centimetres or millimetres meant?)"
    if spec.room is not None and max(spec.room.size) > LENGTH_MAX_M:
        out.append(
            f"room.size = {_sides(spec.room.lo, spec.room.hi)} m: a room side over {LENGTH_MAX_M:g} m is "
            f"unusual; {tail}"
        )
    big = [
        f"furniture[{i}]" + (f" ({b.name})" if b.name else "")
        for i, b in enumerate(spec.furniture)
        if max(h - lo for lo, h in zip(b.min, b.max)) > LENGTH_MAX_M
    ]
    for i, m in enumerate(spec.meshes):
        if m.vertices:
            lo = [min(v[a] for v in m.vertices) for a in range(3)]
            hi = [max(v[a] for v in m.vertices) for a in range(3)]
            if max(h - low for low, h in zip(lo, hi)) > LENGTH_MAX_M:
                big.append(f"meshes[{i}]" + (f" ({m.name})" if m.name else ""))
    if big:
        verb = "spans" if len(big) == 1 else "span"
        out.append(f"{_names(big)} {verb} over {LENGTH_MAX_M:g} m: unusual for furniture or an object; {tail}")
    if not out and extent_m is not None and extent_m > LENGTH_MAX_M:  # meshes read from files
        out.append(
            f"the surfaces span {extent_m:.4g} m, over {LENGTH_MAX_M:g} m: unusual for an indoor scene; mesh "
            "coordinates are read as metres (were millimetres or centimetres meant?)"
        )
    return out


def _time_warnings(spec: SceneSpec) -> list[str]:
    sim, out = spec.simulation, []
    if sim.time_bin_s > TIME_BIN_MAX_S:
        out.append(
            f"simulation.time_bin_s = {sim.time_bin_s:g} s: light travels {sim.time_bin_s * 299_792_458:.3g} m in "
            f"one bin, over {TIME_BIN_MAX_S:g} s is unusual; times are in seconds (0.25 ns is 2.5e-10)"
        )
    if sim.t_max_s is not None and sim.t_max_s > T_MAX_MAX_S:
        out.append(
            f"simulation.t_max_s = {sim.t_max_s:g} s: a window over {T_MAX_MAX_S:g} s is unusual; times are in "
            "seconds (100 ns is 1e-7)"
        )
    return out


def unit_warnings(spec: SceneSpec, extent_m: float | None = None) -> list[str]:
    """One sentence per value plausible only in another unit (module docstring); `extent_m` [m]: the largest
    side of the built surfaces' bounding box, checked for scenes whose meshes come from files."""
    return _angle_warnings(spec) + _length_warnings(spec, extent_m) + _time_warnings(spec)
