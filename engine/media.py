"""Participating media: extinction along ray segments (physics.md section 3).

Algorithm 1 needs only the transmittance T = exp(-sigma_t * L_in), with L_in the
length of the segment inside the medium's region (Beer-Lambert). A ray pays the
medium only for the length it spends inside the region.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from schemas import HomogeneousMediumSpec


@dataclass
class HomogeneousMedium:
    """Constant `sigma_a`, `sigma_s` [1/m] inside a region (the whole scene, or a box lo..hi)."""

    sigma_a: float
    sigma_s: float
    box: tuple[np.ndarray, np.ndarray] | None = None
    #: number of segments the medium was evaluated on (counted, to prove unused code stays unused)
    evaluations: int = 0

    @property
    def sigma_t(self) -> float:
        return self.sigma_a + self.sigma_s

    def length_inside(self, origins: np.ndarray, directions: np.ndarray, lengths: np.ndarray) -> np.ndarray:
        """Length [m] of each segment origin + t dir, 0 <= t <= length, inside the region (slab method)."""
        if self.box is None:
            return lengths
        lo, hi = self.box
        with np.errstate(divide="ignore", invalid="ignore"):
            inv = 1.0 / directions
            t0 = (lo - origins) * inv
            t1 = (hi - origins) * inv
        # A zero direction component: inside the slab -> (-inf, inf), outside -> empty.
        par = directions == 0
        inside_slab = (origins >= lo) & (origins <= hi)
        tmin_ax = np.where(par, np.where(inside_slab, -np.inf, np.inf), np.minimum(t0, t1))
        tmax_ax = np.where(par, np.where(inside_slab, np.inf, -np.inf), np.maximum(t0, t1))
        t_enter = np.maximum(tmin_ax.max(axis=1), 0.0)
        t_exit = np.minimum(tmax_ax.min(axis=1), lengths)
        return np.maximum(t_exit - t_enter, 0.0)

    def transmittance(self, origins: np.ndarray, directions: np.ndarray, lengths: np.ndarray) -> np.ndarray:
        """Beer-Lambert T = exp(-sigma_t L_in) along each segment [-]."""
        self.evaluations += len(lengths)
        return np.exp(-self.sigma_t * self.length_inside(origins, directions, lengths))


def medium_from_spec(spec: HomogeneousMediumSpec | None) -> HomogeneousMedium | None:
    """The engine medium, or None when there is nothing to attenuate (no medium, sigma_t = 0)."""
    if spec is None:
        return None
    sigma_a, sigma_s = spec.coefficients
    if sigma_a + sigma_s == 0.0:
        return None
    box = None
    if spec.region.type == "box":
        box = (np.asarray(spec.region.min, float), np.asarray(spec.region.max, float))
    return HomogeneousMedium(sigma_a, sigma_s, box)
