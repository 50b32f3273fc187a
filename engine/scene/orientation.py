"""Receivers as people hold them: the hidden receivers of orientation requests and angle-diversity receivers.

A point with an `orientation` (schemas/orientation.py) becomes `samples` ordinary receivers at its
position, with the normals of the stratified rule over the polar law x uniform azimuth; an
angle-diversity receiver becomes one receiver per photodiode. They are appended after the document's
own receivers (explicit, then grid points), in the order of `schemas.orientation.hidden_blocks`, so
the maps' grid slices and ids do not move; the results aggregate them per point
(engine/results/orientation.py). The kernel sees ordinary receivers: the line of sight is exact and
the reflections and the medium are estimated as for any other receiver.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from owcsim.engine.sources.devices import Devices, concentrator_gain
from owcsim.schemas import SceneSpec
from owcsim.schemas.orientation import HiddenBlock, hidden_blocks


def _block_arrays(block: HiddenBlock, base: Devices, fov_deg: np.ndarray, gain: np.ndarray) -> dict[str, np.ndarray]:
    """positions, normals, fov [rad], gain A T_s g [m^2] and area [m^2] of one block's receivers (vectorized
    over its points: a grid's points share the rule's normals, tilted from the grid's normal)."""
    if block.diversity is not None:
        pds = block.diversity.expanded()
        fov = np.radians([p.fov_deg for p in pds])
        return {
            "positions": np.repeat(np.asarray([block.diversity.position], float), len(pds), axis=0),
            "normals": np.asarray([p.normal for p in pds], float),
            "fov": fov,
            "gain": np.array(
                [p.area * p.filter_gain * concentrator_gain(f, p.concentrator_index) for p, f in zip(pds, fov)]
            ),
            "area": np.array([p.area for p in pds], float),
        }
    assert block.orientation is not None
    pts = np.asarray(block.points)
    k = block.per_point
    reference = tuple(base.normals[pts[0]].tolist())  # the points of one block share the normal
    normals = np.asarray(block.orientation.normals(reference), float)
    return {
        "positions": np.repeat(base.positions[pts], k, axis=0),
        "normals": np.tile(normals, (len(pts), 1)),
        "fov": np.repeat(np.radians(fov_deg[pts]), k),
        "gain": np.repeat(gain[pts], k),
        "area": np.repeat(base.area[pts], k),
    }


def with_hidden_receivers(spec: SceneSpec, base: Devices) -> Devices:
    """`base` (the document's receivers as built by scene.receivers_from_scene) with the hidden receivers
    appended; `base` itself when the document asks for none."""
    blocks = hidden_blocks(spec)
    if not blocks:
        return base
    fov_deg = np.degrees(np.arccos(np.clip(base.cos_fov, -1.0, 1.0)))
    parts = [_block_arrays(b, base, fov_deg, base.gain) for b in blocks]
    cat = {key: np.concatenate([p[key] for p in parts]) for key in parts[0]}
    n = len(cat["area"])
    fov = cat["fov"]
    normals = cat["normals"] / np.linalg.norm(cat["normals"], axis=1, keepdims=True)
    ids = spec.receiver_ids()[len(base) :]
    assert len(ids) == n, "hidden receiver ids and arrays agree (schemas.orientation.hidden_blocks)"
    return replace(
        base,
        ids=list(base.ids) + ids,
        positions=np.concatenate([base.positions, cat["positions"]]),
        normals=np.concatenate([base.normals, normals]),
        order=np.concatenate([base.order, np.zeros(n)]),
        # cos(90 deg) is 6e-17 in floating point, not 0: clamp so FOV = 90 deg is the full hemisphere (as scene.py)
        cos_fov=np.concatenate(
            [base.cos_fov, np.where(np.isclose(fov, np.pi / 2, rtol=0, atol=1e-12), 0.0, np.cos(fov))]
        ),
        gain=np.concatenate([base.gain, cat["gain"]]),
        power=np.concatenate([base.power, np.ones(n)]),
        area=np.concatenate([base.area, cat["area"]]),
        patterns=list(base.patterns) + [None] * n,
    )
