"""Simulation settings: algorithm, depth, time binning, path budget or target accuracy."""

from __future__ import annotations

import math
from enum import StrEnum
from typing import Literal

from pydantic import Field, model_validator

from .algorithms import algorithm
from .base import SpecModel

#: Most time bins a job may ask for.
MAX_BINS = 1_000_000


def check_bin_budget(t_min_s: float, t_max_s: float, time_bin_s: float, automatic: bool = False) -> None:
    """ValueError when the window t_min_s..t_max_s [s] needs more than MAX_BINS bins of time_bin_s [s]."""
    ratio = (t_max_s - t_min_s) / time_bin_s  # may overflow to inf for a denormal bin width: still compared
    if ratio - 1e-9 > MAX_BINS:
        where = "the automatic time window" if automatic else "time window"
        fix = "widen `time_bin_s` or give a shorter `t_max_s`" if automatic else "widen `time_bin_s`"
        raise ValueError(
            f"{where} {t_min_s:g}..{t_max_s:g} s at {time_bin_s:g} s per bin needs {ratio:.4g} bins, "
            f"more than the budget of {MAX_BINS:,}: {fix}"
        )


class TargetScope(StrEnum):
    """What an accuracy run's `target_rel_error` must hold on (a `str` enum: `TargetScope.LINKS == "links"`).

    On a map each point counts on its own (engine/run/allocation.py): LINKS, the point's link to each
    transmitter; CHANNELS, the point's channel of each transmitter group (and its links to transmitters in no
    group); BOTH, all of these."""

    CHANNELS = "channels"
    LINKS = "links"
    BOTH = "both"


#: Paths used when neither `paths` nor `target_rel_error` is given.
DEFAULT_PATHS = 100_000


class SimulationSpec(SpecModel):
    """How to estimate the channel.

    `algorithm` 1..5 names the report's estimators (physics.md section 4); `direction`
    chooses the transmitter-side ("forward") or receiver-side ("backward") estimator of
    algorithms 1 and 5, or lets the planner pick per link ("auto": in a medium algorithm 5
    runs from both devices, else a pilot run or the device counts decide); algorithms 2-4
    ignore it (in a medium they run from both devices; without one 2 runs backward, 3
    forward, 4 both). `max_scattering` S: what each algorithm honours is in its record
    (schemas/algorithms.py: 1: 0, 2-3: 1, 4: 1 or 2, 5: 1..1000); other values are refused.
    Give `paths` (per source device and direction) or `target_rel_error` on H0 (with
    `time_budget_s`), not both.
    """

    algorithm: Literal[1, 2, 3, 4, 5, "auto"] = "auto"
    direction: Literal["auto", "forward", "backward"] = "auto"
    max_reflections: int | None = Field(
        None, ge=0, le=1000, description="highest reflection order K (default: from the accuracy asked)"
    )
    max_scattering: int | None = Field(
        None,
        ge=0,
        le=1000,
        description="highest scattering order S tallied: algorithm 5 counts orders 1..S (default: from the "
        "accuracy asked), algorithm 4 single scattering (S = 1) or single and in-then-out double scattering "
        "(S = 2, the default), algorithms 2-3 S = 1 and algorithm 1 S = 0 only; a value the algorithm cannot "
        "honour is refused",
    )
    segment_time_step_s: float | None = Field(
        None, ge=1e-15, description="time strata of the points along segments, algorithms 2-4 [s] (default: time_bin_s)"
    )
    max_strata: int = Field(64, ge=1, le=4096, description="most time strata per segment and target, algorithms 2-4")
    equiangular_points: int = Field(
        2,
        ge=0,
        le=256,
        description="equiangular points per segment and target (algorithms 2-5), combined with "
        "the time strata (2-4) or the free-flight collisions (5) by the balance heuristic",
    )
    time_bin_s: float = Field(
        0.25e-9,
        ge=1e-15,
        description="CIR bin width dt [s] (at least 1 fs: light travels 0.3 um in it; over 1 us warns: ns meant?)",
    )
    t_min_s: float = Field(
        0.0, ge=0.0, le=1.0, description="start of the time window [s] (at most 1 s: light travels 300,000 km in it)"
    )
    t_max_s: float | None = Field(
        None,
        gt=0.0,
        description="end of the time window [s], rounded up to a whole number of bins (default: from the accuracy; "
        "over 1 ms warns)",
    )
    truncation_tolerance: float | None = Field(
        None,
        gt=0.0,
        lt=1.0,
        description="largest truncated power (reflection and scattering orders beyond K and S, "
        "arrivals after t_max_s) relative to H0 when K, S or t_max_s are chosen automatically (default: 0.1 x "
        "target_rel_error in an accuracy run, 1e-4 otherwise)",
    )
    paths: int | None = Field(
        None,
        ge=1,
        le=10**12,
        description="paths per source device and direction (links run from both devices get it from each); "
        "default 100 000 unless `target_rel_error` is given",
    )
    target_rel_error: float | None = Field(
        None,
        gt=0.0,
        lt=1.0,
        description="an accuracy run: stop when stderr(H0)/H0 <= this on every quantity `target_scope` names",
    )
    target_scope: TargetScope = Field(
        TargetScope.CHANNELS,
        description="what `target_rel_error` must hold on: 'channels' (default) what the result reports as "
        "channels, every transmitter group's summed channel at each receiver (per watt of group power) and "
        "every link of a transmitter in no group; 'links' every link (transmitter, receiver), grouped or not; "
        "'both' all of these. Without transmitter_groups the three are the same: every link. On a map each "
        "point stops on its own when its quantities meet the target: its links, its group channels, or both",
    )
    time_budget_s: float = Field(600.0, gt=0.0, description="wall-time limit of an accuracy run [s]")
    seed: int = Field(
        0,
        ge=0,
        lt=2**63,
        description="random seed: the same document and seed give the same bits for any number of workers "
        "(every batch has its own stream, keyed by the seed, the direction, the source device and the batch)",
    )
    batch_size: int = Field(16384, ge=64, le=1_048_576, description="paths per batch (memory bound)")
    russian_roulette: bool = True
    rr_start_depth: int = Field(
        3,
        ge=1,
        le=1000,
        description="first event count k + s (reflections plus scattering events) at which roulette may end a path",
    )
    pilot_paths: int = Field(4096, ge=256, le=1_000_000, description="paths per direction of the auto pilot")
    quasi_random: bool = Field(
        True,
        description="draw each path's first five numbers (emission direction, first free flight, first bounce) "
        "from randomly shifted Sobol blocks of 256 paths: lower variance per path (about 0.5x), standard errors "
        "from the independent blocks; used by accuracy runs and by jobs of at least 64 blocks (16 384 paths) "
        "per source device; false: pseudo-random paths",
    )

    @model_validator(mode="after")
    def _consistent(self) -> "SimulationSpec":
        if self.paths is not None and self.target_rel_error is not None:
            raise ValueError("give `paths` or `target_rel_error`, not both")
        if self.algorithm != "auto":
            refusal = algorithm(self.algorithm).scattering_refusal(self.max_scattering)
            if refusal is not None:
                raise ValueError(refusal)
        elif self.max_scattering == 0:
            raise ValueError(
                "`max_scattering` 0 (no scattering) needs `algorithm` 1: the automatic choice may pick "
                "algorithm 5, which counts orders 1 to S"
            )
        if self.t_max_s is not None and not self.t_max_s > self.t_min_s:
            raise ValueError("`t_max_s` must exceed `t_min_s`")
        if self.t_max_s is not None:
            check_bin_budget(self.t_min_s, self.t_max_s, self.time_bin_s)
        return self

    @property
    def is_resolved(self) -> bool:
        """True when the algorithm, K, S (algorithm 5) and the window are all explicit."""
        if self.algorithm == "auto" or self.max_reflections is None or self.t_max_s is None:
            return False
        return algorithm(self.algorithm).scattering_orders is not None or self.max_scattering is not None

    @property
    def scattering_orders(self) -> int:
        """Highest scattering order S the algorithm tallies (resolved settings only)."""
        return algorithm(self.algorithm).S(self.max_scattering)

    @property
    def tolerance(self) -> float:
        """Truncated power allowed, relative to H0 (see `truncation_tolerance`)."""
        if self.truncation_tolerance is not None:
            return self.truncation_tolerance
        return 0.1 * self.target_rel_error if self.target_rel_error is not None else 1e-4

    @property
    def n_bins(self) -> int:
        """Time bins of the window (resolved settings only: t_max_s given or chosen)."""
        assert self.t_max_s is not None, "the time window is chosen when the job runs"
        return max(1, math.ceil((self.t_max_s - self.t_min_s) / self.time_bin_s - 1e-9))

    @property
    def n_paths(self) -> int | None:
        """Paths per source device for a fixed-budget run (None in accuracy mode)."""
        if self.target_rel_error is not None:
            return None
        return self.paths if self.paths is not None else DEFAULT_PATHS
