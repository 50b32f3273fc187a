"""The job's receivers on a built scene: the scene with other receivers, and the receivers no light can reach.

`with_receivers` gives the truncation pilot (engine/run/pilot.py) and a worker that reuses a built
geometry (engine/run/execution.py) the scene of their own receivers without building the surfaces or
the medium again; `unreachable_receivers` finds the receivers that face into a solid or lie flush
against a surface (reported, not simulated); `extreme_receivers` bounds the longest direct path.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from owcsim.engine.core.arrays import BoolArray
from owcsim.engine.core.sampling import sample_cosine_cone, to_world
from owcsim.engine.scene.scene import Scene, _far_distance, mask_reasons, receivers_from_scene
from owcsim.engine.spectral import spectra
from owcsim.schemas import SceneSpec
from owcsim.schemas.devices import ReceiverSpec

#: Receivers whose field of view is tested in one call of `unreachable_receivers` (x n_rays rays).
RECEIVER_CHUNK = 4096


def with_receivers(scene: Scene, spec: SceneSpec) -> Scene:
    """The built scene with the receivers of `spec` (same surfaces, transmitters and medium): what
    build_scene(spec) would give, without building the geometry or the medium again (a spectral scene's
    receiver tables follow the receivers: spectra.with_receivers)."""
    receivers, grid_slices = receivers_from_scene(spec)
    tables = scene.spectra
    if tables is not None:
        tables = spectra.with_receivers(tables, spec, len(scene.transmitters), len(receivers))
    return dataclasses.replace(
        scene,
        spec=spec,
        receivers=receivers,
        grid_slices=grid_slices,
        masked=mask_reasons(spec, receivers, len(spec.receivers)),
        medium_far_distance=_far_distance(spec, scene.geometry, scene.medium, receivers.positions),
        spectra=tables,
    )


def extreme_receivers(spec: SceneSpec) -> list[ReceiverSpec]:
    """The explicit receivers, the corners of every grid and the angle-diversity receivers: the farthest point
    from any transmitter is one of them (the distance to a point is convex over a grid's rectangle)."""
    out = list(spec.receivers)
    for g in spec.receiver_grids:
        nu, nv = g.shape
        out += [g.point(i, j) for i in {0, nu - 1} for j in {0, nv - 1}]
    for a in spec.angle_diversity_receivers:  # its photodiodes sit at its one point
        out.append(ReceiverSpec(id=a.id, position=a.position, **a.expanded()[0].model_dump()))
    return out


def unreachable_receivers(scene: Scene, seen: BoolArray | None = None, n_rays: int = 64) -> list[int]:
    """Receivers that no light can reach: their whole field of view is blocked at their position.

    A receiver whose front (its position plus one ray offset along its normal) lies inside
    a furniture box or outside the room looks into a solid. Otherwise `n_rays` stratified
    directions over its FOV cone are cast from just off the receiver along each ray (a
    surface it sits on is not an obstacle); if every one hits a surface within 10 ray
    offsets (~1e-5 of the scene's extent), it is flush against that surface. Either way it
    is reported, not simulated. Receivers in `seen` (a transmitter sees them directly: they
    are reachable) are not tested. Receivers enclosed by a user mesh are not detected (its
    orientation is unknown).
    """
    isect, rx = scene.intersector, scene.receivers
    if isect.empty:
        return []
    side = int(math.ceil(math.sqrt(n_rays)))
    u = (np.stack(np.meshgrid(np.arange(side), np.arange(side), indexing="ij"), -1).reshape(-1, 2) + 0.5) / side
    front = rx.positions + isect.offset * rx.normals
    spec = scene.spec
    in_solid = np.zeros(len(rx), bool)
    for box in spec.furniture:  # a loop over boxes, each test vectorized over receivers
        in_solid |= np.all((front > box.min) & (front < box.max), axis=1)
    if spec.room is not None:
        in_solid |= ~np.all((front >= spec.room.lo) & (front <= spec.room.hi), axis=1)
    candidates = np.flatnonzero(~in_solid if seen is None else ~in_solid & ~np.asarray(seen, bool))
    flush = np.zeros(len(rx), bool)
    for lo in range(0, len(candidates), RECEIVER_CHUNK):  # chunks bound memory; each one vectorized call
        j = candidates[lo : lo + RECEIVER_CHUNK]
        local = sample_cosine_cone(rx.cos_fov[j][:, None], u[None, :, 0], u[None, :, 1])  # (J, n_rays, 3)
        dirs = to_world(local, rx.normals[j][:, None, :]).reshape(-1, 3)
        origins = np.repeat(front[j], len(u), axis=0) + 2.0 * isect.offset * dirs
        prim, t = isect.intersect(origins, dirs)
        flush[j] = np.all(((prim >= 0) & (t <= 10.0 * isect.offset)).reshape(len(j), len(u)), axis=1)
    solid = in_solid if seen is None else in_solid & ~np.asarray(seen, bool)
    return np.flatnonzero(solid | flush).tolist()
