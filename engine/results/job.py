"""A finished job as the result builder reads it: what ran, on which scene, and what it tallied.

The planner (engine/run/simulate.py) fills a `RunInfo` while it runs and hands one `FinishedJob` to
`build_result` (engine/results/result.py); both live here, below the run layer, so the result never
imports the planner.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field

from owcsim.engine.core.arrays import FloatArray, IntArray
from owcsim.engine.integrator.path import KernelSettings
from owcsim.engine.scene.los import LosGeometry
from owcsim.engine.scene.scene import Scene
from owcsim.engine.tally.tally import Accumulator
from owcsim.schemas import SceneSpec
from owcsim.schemas.algorithms import Direction
from owcsim.schemas.results import DirectionChoicePublic, ModeledPublic, StopReason


@dataclass
class RunInfo:
    """What the run did, filled in as it goes (the result's `run` section)."""

    stop_reason: StopReason = StopReason.PATHS
    wall_time_s: float = 0.0  # [s]
    workers: int = 1
    batches: int = 0
    #: how the directions were chosen: the rule, or the direction pilot's measurements
    direction_choice: DirectionChoicePublic = field(default_factory=lambda: DirectionChoicePublic(rule=""))


@dataclass(frozen=True, slots=True)
class LineOfSight:
    """The direct paths of every link, in closed form (engine/scene/los.py), flat in link order tx * n_rx + rx."""

    gain: FloatArray  # per watt
    delay: FloatArray  # [s]
    #: cosines, distances and clear fractions; None: not computed (no lighting figures in the result)
    geometry: LosGeometry | None = None


@dataclass(frozen=True, slots=True)
class FinishedJob:
    """One job after its last batch: the document, the built scene, the kernel settings, the per-link
    directions (Direction.code), the merged tallies per direction, the line of sight and the run's record."""

    spec: SceneSpec  # the resolved document that ran
    scene: Scene
    settings: KernelSettings
    los: LineOfSight
    directions: IntArray  # per link, Direction.code
    accs: Mapping[Direction, Accumulator]
    info: RunInfo
    original: SceneSpec | None = None  # the document as given (automatic settings unresolved)
    modeled: ModeledPublic | None = None  # what the automatic settings said (engine/run/auto.py)
    unreachable: IntArray | Sequence[int] = ()  # receivers no light reaches (not simulated)
