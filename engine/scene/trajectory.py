"""Moving receivers: position and normal of a device at given times, from its trajectory (schemas/timeline.py).

A trajectory is a table of knots (time [s], position [m]) interpolated linearly, the device standing at
the first knot before it and at the last after it. Waypoints walked at speed v become such a table: leg i
takes |p_{i+1} - p_i| / v seconds, and every inner waypoint is held `pause_s` seconds. With the heading
orientation the document normal is read in the walker's frame (+x forward, +z up) and turned about +z by
the heading, the azimuth atan2(dy, dx) of the knot interval being walked (kept while standing still).
"""

from __future__ import annotations

import numpy as np

from owcsim.engine.core.arrays import FloatArray
from owcsim.schemas.timeline import TrajectoryOrientation, TrajectorySpec


def knots(traj: TrajectorySpec) -> tuple[FloatArray, FloatArray]:
    """The trajectory as a table: times (N,) [s], increasing, and positions (N, 3) [m]."""
    if traj.waypoints is None:
        assert traj.times_s is not None and traj.positions is not None
        return np.asarray(traj.times_s, np.float64), np.asarray(traj.positions, np.float64)
    assert traj.speed_m_s is not None
    points = np.asarray(traj.waypoints, np.float64)
    legs = np.linalg.norm(np.diff(points, axis=0), axis=1) / traj.speed_m_s  # (W - 1,) [s]
    n = len(points)
    hold = traj.pause_s if traj.pause_s > 0 else 0.0
    # per waypoint: arrival, then (inner waypoints, with a pause) departure
    times, where = [traj.start_s], [points[0]]
    t = traj.start_s
    for i in range(1, n):  # a loop over the few waypoints of one document, not over paths
        t += float(legs[i - 1])
        times.append(t)
        where.append(points[i])
        if hold and i < n - 1:
            t += hold
            times.append(t)
            where.append(points[i])
    t_arr, p_arr = np.asarray(times), np.asarray(where)
    keep = np.concatenate([[True], np.diff(t_arr) > 0])  # a zero-length leg adds no knot
    return t_arr[keep], p_arr[keep]


def positions_at(traj: TrajectorySpec, times: FloatArray) -> FloatArray:
    """(T, 3) positions [m] at `times` [s]."""
    t, p = knots(traj)
    times = np.asarray(times, np.float64)
    return np.stack([np.interp(times, t, p[:, ax]) for ax in range(3)], axis=1)


def _headings(t: FloatArray, p: FloatArray) -> FloatArray:
    """(N - 1,) azimuth [rad] of each knot interval, carried over intervals without horizontal motion."""
    d = np.diff(p, axis=0)
    moving = np.hypot(d[:, 0], d[:, 1]) > 1e-12
    if not moving.any():
        return np.zeros(len(d))
    idx = np.where(moving, np.arange(len(d)), -1)
    idx = np.maximum.accumulate(idx)  # forward fill: the last interval that moved
    idx = np.where(idx < 0, int(np.flatnonzero(moving)[0]), idx)  # before any move: the first one
    return np.arctan2(d[idx, 1], d[idx, 0])


def normals_at(traj: TrajectorySpec, normal: tuple[float, float, float], times: FloatArray) -> FloatArray:
    """(T, 3) unit normals at `times` [s]; `normal` is the device's document normal."""
    times = np.asarray(times, np.float64)
    if traj.normals is not None:
        assert traj.times_s is not None
        tn = np.asarray(traj.normals, np.float64)
        tn = tn / np.linalg.norm(tn, axis=1, keepdims=True)
        n = np.stack([np.interp(times, traj.times_s, tn[:, ax]) for ax in range(3)], axis=1)
        return n / np.linalg.norm(n, axis=1, keepdims=True)
    base = np.asarray(normal, np.float64) / np.linalg.norm(normal)
    if traj.orientation is TrajectoryOrientation.FIXED:
        return np.tile(base, (len(times), 1))
    t, p = knots(traj)
    if len(t) < 2:
        return np.tile(base, (len(times), 1))
    heading = _headings(t, p)[np.clip(np.searchsorted(t, times, side="right") - 1, 0, len(t) - 2)]
    c, s = np.cos(heading), np.sin(heading)
    return np.stack([c * base[0] - s * base[1], s * base[0] + c * base[1], np.full(len(times), base[2])], axis=1)
