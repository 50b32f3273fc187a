"""EN 12464-1 figures over a task area and its immediate surround: E_avg, E_min and U0 = E_min / E_avg.

EN 12464-1:2021 sec. 4.3: the maintained illuminance E_m is the average over the task area (here E_avg of the
total illuminance of its grid points, as built: multiply by a maintenance factor for E_m), U0 = E_min / E_avg
the uniformity; the immediate surround is a band of at least 0.5 m around the task area. A point belongs to
the task area when it lies in the area's box (within 1e-6 m), to its surround when it lies in the box grown
by `surround_width` on every axis and not in the task area, to its background (EN 12464-1: a band of at least
3 m within the room) when in the box grown by `surround_width` + `background_width` and in neither.

Standard errors: delete-one-group jackknife over the path groups (engine/tally/plan.py N_GROUPS). Group g's
replicate of every link is its Monte Carlo estimate without group g, (T - c_g m_g) / (C - c_g) (T, C the sums
of c m and c over the groups, c the group's paths, m its per-path mean); the replicate maps keep the exact
direct light, and E_avg, E_min and U0 are computed on each, var = (G - 1) / G sum_g (theta_g - theta_bar)^2
(Efron & Tibshirani 1993, ch. 11). The groups hold the same paths for every point of a transmitter (forward)
or every transmitter of a point (backward), so the correlation between points is carried; the jackknife of a
minimum is rough when several points are nearly tied for it.
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np

from owcsim.engine.core.arrays import FloatArray
from owcsim.engine.scene.scene import Scene
from owcsim.engine.tally import reliability
from owcsim.engine.tally.plan import N_GROUPS

#: A point lies on a task area's box when within this distance of it [m].
AREA_TOLERANCE = 1e-6

ERRORS_NOTE = (
    "delete-one-group jackknife over the path groups, each replicate map keeping the exact direct light "
    "(engine/results/uniformity.py); null in spectral scenes (the groups hold the carrier band only)"
)


def replicate_reflected(scene: Scene, accs: Mapping, flux: FloatArray) -> FloatArray | None:
    """(G, n_tx, n_rx) reflected illuminance [lx] of every link with path group g left out; None in a spectral
    scene (its path groups hold the carrier band, not the luminous channel)."""
    if scene.spectra is not None:
        return None
    means, counts = reliability.group_means(accs.values())
    n_tx, n_rx = len(scene.transmitters), len(scene.receivers)
    if not counts.any():  # nothing traced (line of sight only): every replicate is the exact map
        return np.zeros((N_GROUPS, n_tx, n_rx))
    total, weight = (means * counts).sum(axis=0), counts.sum(axis=0)
    rest = weight[None, :] - counts
    with np.errstate(invalid="ignore", divide="ignore"):
        rep = np.where(weight[None, :] > 0, (total[None, :] - counts * means) / rest, 0.0)
    scale = np.nan_to_num(flux)[:, None] / scene.receivers.gain[None, :]  # Phi_v / (A T_s g) [lx] per unit H
    return rep.reshape(-1, n_tx, n_rx) * scale[None]


def _figures(values: FloatArray, reps: FloatArray | None, grid_ij: np.ndarray) -> dict:
    """E_avg, E_min, U0 of the finite `values` (n,) with jackknife errors from `reps` (G, n)."""
    ok = np.isfinite(values)
    points = [(int(i), int(j)) for i, j in grid_ij[ok]]
    if not ok.any():
        return dict(points=points) | {k: None for k in _KEYS}
    v = values[ok]
    avg, low = float(v.mean()), float(v.min())
    stats = np.array([avg, low, low / avg if avg > 0 else np.nan])
    se = np.full(3, np.nan)
    if reps is not None and reps.shape[0] >= 2:
        r = reps[:, ok]
        r_avg, r_min = r.mean(axis=1), r.min(axis=1)
        with np.errstate(invalid="ignore", divide="ignore"):
            theta = np.stack([r_avg, r_min, np.where(r_avg > 0, r_min / r_avg, np.nan)])  # (3, G)
        g = theta.shape[1]
        se = np.sqrt((g - 1) / g * ((theta - theta.mean(axis=1, keepdims=True)) ** 2).sum(axis=1))
    out: dict = {"points": points}
    for key, x in zip(_KEYS, (stats[0], se[0], stats[1], se[1], stats[2], se[2])):
        out[key] = float(x) if np.isfinite(x) else None
    return out


_KEYS = (
    "illuminance_avg_lx",
    "illuminance_avg_lx_stderr",
    "illuminance_min_lx",
    "illuminance_min_lx_stderr",
    "uniformity_u0",
    "uniformity_u0_stderr",
)


def area_figures(
    spec,
    scene: Scene,
    channels: list[tuple[str, FloatArray, FloatArray]],
    reps: FloatArray | None,
) -> tuple[list[dict], list[str]]:
    """Per task area (or per whole grid) and channel: the figures of the task and of its surround, and warnings.

    channels: (name, member weights (n_tx,) over the transmitters (1 in the channel, else 0), total illuminance
    per receiver (n_rx,) [lx]); reps: replicate_reflected's (G, n_tx, n_rx) or None."""
    if not scene.grid_slices:
        return [], []
    lighting = spec.lighting
    grids = {g.id_prefix: (g, sl) for g, sl in zip(spec.receiver_grids, scene.grid_slices)}
    areas = lighting.task_areas if lighting is not None else []
    width = lighting.surround_width if lighting is not None else 0.0
    back = lighting.background_width if lighting is not None else 0.0
    todo: list[tuple[str, str, FloatArray | None, FloatArray | None]] = [
        (a.name, a.grid, np.array(a.min), np.array(a.max)) for a in areas
    ] or [(name, name, None, None) for name in grids]
    out, warns = [], []
    for name, grid_id, lo, hi in todo:  # a loop over the few areas
        grid, (first, (nu, nv)) = grids[grid_id]
        idx = first + np.arange(nu * nv)
        ij = np.stack(np.divmod(np.arange(nu * nv), nv), axis=1)
        pos = scene.receivers.positions[idx]
        parts: dict[str, np.ndarray] = {}
        if lo is None or hi is None:
            parts["task"] = np.ones(len(idx), bool)
        else:
            parts["task"] = _in_box(pos, lo, hi, AREA_TOLERANCE)
            near = _in_box(pos, lo, hi, width + AREA_TOLERANCE)
            if width > 0:
                parts["surround"] = near & ~parts["task"]
            if back > 0:
                parts["background"] = _in_box(pos, lo, hi, width + back + AREA_TOLERANCE) & ~near
            if not parts["task"].any():
                warns.append(
                    f"lighting: task area {name!r} holds no point of grid {grid_id!r}: its figures are null; "
                    "make its box meet the grid's plane"
                )
        for channel, members, total in channels:  # a loop over the channels
            rep = None
            if reps is not None:
                rep = np.einsum("i,gir->gr", members, reps[:, :, idx]) + (total[idx] - _mc(members, reps, idx))[None]
            row: dict = {"name": name, "grid": grid_id, "channel": channel}
            for part, sel in parts.items():  # task, surround, background
                row[part] = _figures(total[idx][sel], None if rep is None else rep[:, sel], ij[sel])
            out.append(row)
    return out, warns


def _mc(members: FloatArray, reps: FloatArray, idx: np.ndarray) -> FloatArray:
    """The mean of the replicates' reflected part per point: total - it is the part every replicate shares."""
    return np.einsum("i,gir->r", members, reps[:, :, idx]) / reps.shape[0]


def _in_box(p: FloatArray, lo: FloatArray, hi: FloatArray, margin: float) -> np.ndarray:
    return np.all((p >= lo - margin) & (p <= hi + margin), axis=1)
