"""Multi-cell LiFi: serving cell, SINR, rates and handover boundaries of every receiver (docs/link-budget.md).

A cell is a transmitter group (its members send one signal), or a transmitter in no group. At receiver j
cell c delivers P_cj = sum_{i in c} P_i H0_ij [W]; the serving cell s is the argmax (ties: the first cell),
the others interfere. With a link budget (Komine & Nakagawa 2004 noise, engine/results/link_budget.py):

    SINR = (gamma P_s)^2 / (sum_{k != s} (gamma P_k)^2 + sigma_shot^2(P_total) + sigma_thermal^2)

with the shot noise of all the light received, P_total = sum_c P_c. DCO-OFDM sees the AC part of each cell's
signal, (gamma P)^2 / k^2 for a bias of k standard deviations, so SINR_ac = (gamma P_s)^2 / (I + k^2 sigma^2).
Standard errors by the delta method: Var SINR = sum_c (dSINR/dP_c)^2 Var P_c where the cells' estimates are
independent (every link of the receiver traced forward: each transmitter's own paths, or exact); where
backward paths serve several cells at once their covariance is not tallied, and the error given is the
bound (sum_c |dSINR/dP_c| sigma_c)^2, valid for any correlation.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from owcsim.engine.core.arrays import BoolArray, FloatArray, IntArray
from owcsim.engine.results import link_budget as lb
from owcsim.engine.results.result_parts import column, document_rows, group_power
from owcsim.schemas.algorithms import Direction
from owcsim.schemas.cells import CELL_QUANTITIES

__all__ = ["CellPowers", "CellFigures", "boundaries", "cell_figures", "cell_powers", "cells_block"]


@dataclass(frozen=True, slots=True)
class CellPowers:
    """Per cell (C) and receiver (R): received optical power [W], its standard error [W] (NaN: none), and per
    receiver whether the cells' estimates are independent (`independent`, R)."""

    names: list[str]
    members: list[list[str]]
    power: FloatArray  # (C, R)
    stderr: FloatArray  # (C, R)
    independent: BoolArray  # (R,)


def _floats(values) -> FloatArray:
    return np.array(values, dtype=float)  # None becomes NaN


def cell_powers(spec, scene, plan, link_cols: dict, channel_cols: dict, directions: IntArray) -> CellPowers:
    """The cells of a scene and the power each delivers to each receiver, from the result's columns."""
    tx = scene.transmitters
    n_tx, n_rx = len(tx), len(scene.receivers)
    w = plan.group_weights
    grouped = (w > 0).any(axis=0) if w.size else np.zeros(n_tx, bool)
    solo = np.flatnonzero(~grouped)
    names = [g.name for g in spec.transmitter_groups] + [tx.ids[i] for i in solo]
    members = [list(g.transmitters) for g in spec.transmitter_groups] + [[tx.ids[i]] for i in solo]
    power, stderr = [], []
    if w.size:
        g_power = group_power(w, tx.power)
        n_groups = len(w)
        power.append(_floats(channel_cols["dc_gain"]).reshape(n_groups, n_rx) * g_power[:, None])
        stderr.append(_floats(channel_cols["dc_gain_stderr"]).reshape(n_groups, n_rx) * g_power[:, None])
    h0 = _floats(link_cols["dc_gain"]).reshape(n_tx, n_rx)[solo]
    h0_se = _floats(link_cols["dc_gain_stderr"]).reshape(n_tx, n_rx)[solo]
    power.append(h0 * tx.power[solo, None])
    stderr.append(h0_se * tx.power[solo, None])
    codes = np.asarray(directions).reshape(n_tx, n_rx)
    independent = np.asarray(np.isin(codes, [Direction.FORWARD.code, Direction.NONE.code]).all(axis=0))
    return CellPowers(names, members, np.concatenate(power), np.concatenate(stderr), independent)


@dataclass(frozen=True, slots=True)
class CellFigures:
    """Per receiver (R): serving cell index (-1: none, masked or dark), the serving and interfering power [W],
    and with a link budget each quantity of schemas.cells.CELL_QUANTITIES with its standard error (NaN: none)."""

    serving: IntArray
    serving_power: FloatArray
    interference_power: FloatArray
    values: dict[str, FloatArray]
    stderr: dict[str, FloatArray]


def _serving(power: FloatArray) -> IntArray:
    """argmax over cells (ties: the first), -1 where a cell's power is unknown (masked) or all are 0."""
    known = np.isfinite(power).all(axis=0)
    s = np.argmax(np.where(np.isfinite(power), power, -np.inf), axis=0)
    dark = np.take_along_axis(np.nan_to_num(power), s[None], axis=0)[0] <= 0
    return np.where(known & ~dark, s, -1)


def _sinr(budget: lb.LinkBudget, area, power: FloatArray, s: IntArray, noise_factor: float):
    """(SINR (R,), dSINR/dP_c (C, R)) of SINR = (g P_s)^2 / (sum_{k != s} (g P_k)^2 + f sigma^2(P_total)).

    f = 1 for the SINR, k^2 for DCO-OFDM's AC part. sigma^2 = shot + thermal (lb.noise_variances), whose
    derivative in P_total is 2 q g B. s must index a cell at every receiver (callers mask the others).
    """
    g = budget.responsivity
    others = np.arange(len(power))[:, None] != s[None, :]
    p_s = np.take_along_axis(power, s[None], axis=0)[0]
    interference = g * g * np.where(others, power**2, 0.0).sum(axis=0)
    shot, thermal = lb.noise_variances(budget, area, power.sum(axis=0))
    denom = interference + noise_factor * (shot + thermal)
    x = (g * p_s) ** 2 / denom
    slope = noise_factor * 2.0 * lb.Q_E * g * budget.noise_bandwidth
    grad = -x * (2.0 * g * g * power + slope) / denom
    grad = np.where(others, grad, (2.0 * g * g * p_s - x * slope) / denom)
    return x, grad


def _propagate(grad: FloatArray, sigma: FloatArray, independent: BoolArray) -> FloatArray:
    """Standard error of f(P) from dF/dP_c (C, R) and sigma_c (C, R): sqrt(sum (d sigma)^2) for independent
    cells, else sum |d| sigma (the bound for any correlation)."""
    terms = np.abs(grad) * sigma
    return np.where(independent, np.sqrt((terms**2).sum(axis=0)), terms.sum(axis=0))


#: Largest relative error of the OOK allowance (g P_s)^2 / SNR_req - I for which the rate's first-order error is
#: given (beyond it the rate's cliff at allowance 0 makes the delta method meaningless: null).
DELTA_LIMIT = 0.2


def _ook(budget: lb.LinkBudget, area, power: FloatArray, s: IntArray, cp: CellPowers):
    """OOK-NRZ rate (lb.ook_rate) and its standard error (implicit differentiation of its cubic)."""
    g = budget.responsivity
    required = lb.ook_required_snr(budget.ber_target)
    others = np.arange(len(power))[:, None] != s[None, :]
    p_s = np.take_along_axis(power, s[None], axis=0)[0]
    p_tot = power.sum(axis=0)
    interference = g * g * np.where(others, power**2, 0.0).sum(axis=0)
    root = lb.ook_rate(budget, area, p_s, interference, p_tot, required)
    rate = np.minimum(root, budget.noise_bandwidth)  # NRZ needs a bandwidth ~ R_b: at most the receiver's B
    # F(R, P) = c1(P) R + c2 R^2 + c3 R^3 - Y(P) = 0: dR/dP_c = (dY/dP_c - 2 q g R) / (dF/dR)
    c1 = 2.0 * lb.Q_E * (g * p_tot + budget.background_current * budget.i2)
    c2, c3 = lb.thermal_coefficients(budget, area)
    d_rate = c1 + 2.0 * c2 * rate + 3.0 * c3 * rate**2
    d_y = np.where(others, -2.0 * g * g * power, 2.0 * g * g * power / required)
    grad = np.where(rate > 0, (d_y - 2.0 * lb.Q_E * g * rate) / d_rate, 0.0)
    se_root = _propagate(grad, cp.stderr, cp.independent)
    capped = root > budget.noise_bandwidth  # the rate is B, surely so when the root is 2 errors above it
    se = np.where(capped, np.where(root - budget.noise_bandwidth >= 2.0 * se_root, 0.0, np.nan), se_root)
    # the linearization holds while the allowance Y = (g P_s)^2 / SNR_req - I is well away from 0 (the rate's
    # cliff): null where its own relative error exceeds DELTA_LIMIT, or where the rate is 0 by a margin of less
    y = (g * p_s) ** 2 / required - interference
    se_y = _propagate(d_y, cp.stderr, cp.independent)
    exact = np.nan_to_num(se_y) == 0
    return rate, np.where(exact | (se_y < DELTA_LIMIT * np.abs(y)), se, np.nan)


def cell_figures(cp: CellPowers, budget: lb.LinkBudget | None, area: FloatArray) -> CellFigures:
    """Serving cell, SINR and rates of every receiver (module docstring); area (R,) [m^2]."""
    s = _serving(cp.power)
    has = s >= 0
    s0 = np.where(has, s, 0)
    power = np.where(has[None, :], np.nan_to_num(cp.power), 0.0)
    p_s = np.take_along_axis(power, s0[None], axis=0)[0]
    nan = np.full(len(s), np.nan)
    serving_power = np.where(has, p_s, np.nan)
    interference_power = np.where(has, power.sum(axis=0) - p_s, np.nan)
    values: dict[str, FloatArray] = {}
    stderr: dict[str, FloatArray] = {}
    if budget is not None:
        b = budget.noise_bandwidth
        with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
            x, grad = _sinr(budget, area, power, s0, 1.0)
            se_x = _propagate(grad, cp.stderr, cp.independent)
            k2 = budget.dco_ofdm_bias**2
            x_ac, grad_ac = _sinr(budget, area, power, s0, k2)
            se_ac = _propagate(grad_ac, cp.stderr, cp.independent)
            n = budget.dco_ofdm_subcarriers
            values["sinr_db"] = lb.to_db(x)
            stderr["sinr_db"] = 10.0 / math.log(10.0) * se_x / x
            values["rate_shannon_bps"] = lb.shannon_rate(b, x)
            stderr["rate_shannon_bps"] = b / math.log(2.0) * se_x / (1.0 + x)
            values["rate_dco_ofdm_bps"] = lb.dco_ofdm_rate(b, x_ac, n)
            stderr["rate_dco_ofdm_bps"] = b * (n - 2.0) / (2.0 * n) / math.log(2.0) * se_ac / (1.0 + x_ac)
            values["rate_ook_bps"], stderr["rate_ook_bps"] = _ook(budget, area, power, s0, cp)
        for q in CELL_QUANTITIES:
            values[q] = np.where(has, values[q], nan)
            stderr[q] = np.where(has & np.isfinite(stderr[q]), stderr[q], nan)
    return CellFigures(s, serving_power, interference_power, values, stderr)


def boundaries(positions: FloatArray, serving: IntArray) -> list[tuple[FloatArray, FloatArray, int, int]]:
    """Handover boundary segments of one grid: (start [m], end [m], cell a, cell b) with a < b.

    positions (nu, nv, 3) of a regular grid (point (i, j) = p00 + i du + j dv), serving (nu, nv) cell indices
    (-1: none). Where points (i, j) and (i + 1, j) are served by different cells, the segment crosses their
    midpoint along v, from j - 1/2 to j + 1/2 (clipped to the grid); likewise along u between (i, j) and
    (i, j + 1): the edges of the grid's dual cells between the two cells.
    """
    nu, nv = serving.shape
    p00 = positions[0, 0]
    du = positions[1, 0] - p00 if nu > 1 else np.zeros(3)
    dv = positions[0, 1] - p00 if nv > 1 else np.zeros(3)
    out = []
    for axis in (0, 1):  # two directions of neighbours, each vectorized over the grid
        a = serving[:-1, :] if axis == 0 else serving[:, :-1]
        b = serving[1:, :] if axis == 0 else serving[:, 1:]
        i, j = np.nonzero((a >= 0) & (b >= 0) & (a != b))
        if axis == 0:
            ci, lo, hi = i + 0.5, np.maximum(j - 0.5, 0.0), np.minimum(j + 0.5, nv - 1.0)
            start = p00 + ci[:, None] * du + lo[:, None] * dv
            end = p00 + ci[:, None] * du + hi[:, None] * dv
        else:
            cj, lo, hi = j + 0.5, np.maximum(i - 0.5, 0.0), np.minimum(i + 0.5, nu - 1.0)
            start = p00 + lo[:, None] * du + cj[:, None] * dv
            end = p00 + hi[:, None] * du + cj[:, None] * dv
        ca, cb = a[i, j], b[i, j]
        out += list(zip(start, end, np.minimum(ca, cb).tolist(), np.maximum(ca, cb).tolist()))
    return out


def _grid_maps(spec, scene, cp: CellPowers, fig: CellFigures) -> list[dict]:
    """Per receiver grid: the serving-cell map, the SINR and rates, and the handover boundaries."""
    out = []
    for grid, (first, (nu, nv)) in zip(spec.receiver_grids, scene.grid_slices):
        sl = slice(first, first + nu * nv)
        serving = fig.serving[sl].reshape(nu, nv)
        cells = [[None if c < 0 else int(c) for c in row] for row in serving.tolist()]
        segments = boundaries(scene.receivers.positions[sl].reshape(nu, nv, 3), serving)
        out.append(
            {
                "grid": grid.id_prefix,
                "shape": (nu, nv),
                "serving_cell": cells,
                "units": {q: CELL_QUANTITIES[q][0] for q in fig.values},
                "values": {q: column(v[sl].reshape(nu, nv)) for q, v in fig.values.items()},
                "stderr": {q: column(v[sl].reshape(nu, nv)) for q, v in fig.stderr.items()},
                "boundaries": [
                    {"start": tuple(a.tolist()), "end": tuple(b.tolist()), "cells": (cp.names[ca], cp.names[cb])}
                    for a, b, ca, cb in segments
                ],
            }
        )
    return out


def cells_block(spec, scene, plan, link_cols: dict, channel_cols: dict, directions: IntArray) -> dict | None:
    """The result's `cells` section (schemas.cells.CellsPublic), or None for one cell without a link budget."""
    cp = cell_powers(spec, scene, plan, link_cols, channel_cols, directions)
    if len(cp.names) < 2 and spec.link_budget is None:
        return None
    budget = lb.link_budget_from_spec(spec.link_budget) if spec.link_budget is not None else None
    notes = []
    w = plan.group_weights
    shared_tx = [scene.transmitters.ids[i] for i in np.flatnonzero((w > 0).sum(axis=0) > 1)] if w.size else []
    if shared_tx and budget is not None:  # a transmitter sends one signal: it cannot serve one cell and jam another
        budget = None
        notes.append(
            f"{', '.join(shared_tx)} belong to several transmitter groups, so the cells overlap (a transmitter "
            "sends one signal): SINR and rates are null; give each transmitter one group for the cell figures"
        )
    fig = cell_figures(cp, budget, scene.receivers.area)
    if budget is None and not shared_tx:
        notes.append("SINR and rates need `link_budget` (the receiver's noise): null here")
    shared = (~cp.independent & (fig.serving >= 0)).sum()
    if budget is not None and shared:
        notes.append(
            f"at {shared} receiver(s) backward paths serve several cells at once: their SINR and rate standard "
            "errors are the bound sum_c |dSINR/dP_c| sigma_c (the cells' covariance is not tallied)"
        )
    rx = scene.receivers
    has = fig.serving >= 0
    cols: dict[str, list] = {
        "receiver": list(rx.ids),
        "receiver_index": list(range(len(rx))),
        "serving_cell": [cp.names[c] if c >= 0 else None for c in fig.serving.tolist()],
        "serving_cell_index": [c if c >= 0 else None for c in fig.serving.tolist()],
        "serving_power_w": column(fig.serving_power),
        "interference_power_w": column(np.where(has, fig.interference_power, np.nan)),
    }
    for q in fig.values:
        cols[q] = column(fig.values[q])
        cols[q + "_stderr"] = column(fig.stderr[q])
    return {
        "cells": cp.names,
        "members": cp.members,
        "note": "; ".join(notes) or None,
        "receivers": document_rows(cols, len(rx)),
        "maps": _grid_maps(spec, scene, cp, fig),
    }
