"""The truncation estimate: the power of the orders past the last one a run measured (a geometric tail).

Past the last measured reflection (scattering) order, each further order is assumed to keep at
most a ratio r of the one before: the tail is g_L r / (1 - r) (`geometric_tail`). `tail_ratio`
fits r to the measured orders and caps it by rho_max (albedo_max) when below 1. The result's
`truncated_gain_estimate` (result_parts.order_block) and the automatic choice of K and S
(engine/run/auto.py, engine/run/tail.py) both read these two functions.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from owcsim.engine.core.arrays import FloatArray


def tail_ratio(
    gains: Sequence[float] | FloatArray,
    errors: Sequence[float | None] | FloatArray,
    bound: float,
    last: int = 8,
) -> tuple[float, str]:
    """Per-order decay ratio for the geometric tail past the pilot's last measured order, and how it was chosen.

    The pilot's own decay: a weighted least-squares fit of log(gain) against the order
    over its `last` highest orders measured to 30 % (at least 4), ratio = exp(slope +
    2 se(slope)). `bound` (rho_max for reflections, albedo_max for scattering) caps it when
    below 1 (each further order keeps at most that fraction: the diffuse-field
    assumption), and is used alone when too few orders are measured. With bound = 1 (a
    white room, or sigma_a = 0) the fit is the only estimate; infinity (no finite bound
    is stated) when it is not below 1 or too few orders are measured. The reason contains
    `{what}` for the caller to name the bound.
    """
    g = np.asarray(gains, float)
    e = np.asarray([x or 0.0 for x in errors], float)
    good = np.flatnonzero((g > 0) & (e <= 0.3 * np.where(g > 0, g, 1.0)))
    good = good[good >= 1][-last:]
    a_priori = (bound, f"at most {bound:.3g} per order (the largest {{what}})")
    if len(good) < 4:
        return (
            a_priori
            if bound < 1.0
            else (math.inf, "unbounded: {what} is 1 and the pilot measured too few orders to fit their decay")
        )
    y = np.log(g[good])
    w = 1.0 / np.maximum(e[good] / g[good], 1e-3) ** 2  # var(log g) ~ (se / g)^2
    x = good.astype(float)
    xm = (w * x).sum() / w.sum()
    slope = (w * (x - xm) * (y - (w * y).sum() / w.sum())).sum() / (w * (x - xm) ** 2).sum()
    se = math.sqrt(1.0 / (w * (x - xm) ** 2).sum())
    r = math.exp(slope + 2.0 * se)
    if bound < 1.0 and r >= bound:
        return a_priori
    if bound < 1.0:
        return r, (
            f"{r:.3g} per order, the upper bound (2 se) of a fit to the pilot's orders {good[0]}-{good[-1]} "
            f"(below {{what}} = {bound:.3g}; an estimate that assumes geometric decay past them)"
        )
    if r >= 1.0:
        return math.inf, (
            f"unbounded: {{what}} is 1 and the pilot's last orders show no decay (fitted ratio "
            f"{math.exp(slope):.3g}, upper bound {r:.3g})"
        )
    return r, (
        f"{r:.3g} per order, the upper bound (2 se) of a fit to the pilot's orders {good[0]}-{good[-1]} "
        f"({{what}} is 1: no a-priori bound; an estimate that assumes geometric decay past them)"
    )


def geometric_tail(gain: float, ratio: float) -> float:
    """Power of the orders past the last one [per watt], g r / (1 - r), if each keeps at most `ratio` of the one
    before (inf: no bound); 0 when the last order's `gain` is 0."""
    if gain == 0:
        return 0.0
    return gain * ratio / (1.0 - ratio) if ratio < 1.0 else float("inf")
