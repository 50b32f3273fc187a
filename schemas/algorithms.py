"""The five estimators (physics.md section 4), in one place: what each is, and the enums around them.

`ALGORITHMS[n]` is the record of `simulation.algorithm = n`: its name, the path families it
estimates and what it leaves out, the KernelSettings flags it sets (by name: this layer does not
import the engine), the scattering order it fixes, the direction it runs in, whether it runs from
both devices in a medium, the outputs it fills, the medium it needs and its warning. The engine's planner
(engine/run/simulate.py), the automatic settings (engine/run/auto.py) and the result (engine/results/result.py)
read these records; nothing else lists per-algorithm facts.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from enum import StrEnum
from types import MappingProxyType


class Direction(StrEnum):
    """The side a link's paths start from. A `str` enum: `Direction.FORWARD == "forward"` holds, and it hashes
    as its value, so code that compares or keys by the string keeps working.

    Per-link arrays hold `Direction.code` (an int: vectorized masks), read back with `Direction.of_code`."""

    FORWARD = "forward"  # from the transmitter
    BACKWARD = "backward"  # from the receiver
    BOTH = "both"  # from both devices (algorithm 4, and two-sided runs in a medium)
    NONE = "none"  # not simulated: exact, unreachable or masked

    @property
    def code(self) -> int:
        """Position in the definition order: 0 forward, 1 backward, 2 both, 3 none."""
        return _CODES[self]

    @classmethod
    def of_code(cls, code: int) -> "Direction":
        return _MEMBERS[int(code)]


_MEMBERS = tuple(Direction)
_CODES = {d: i for i, d in enumerate(_MEMBERS)}


class TwoSided(StrEnum):
    """When an algorithm runs every link from both devices in a medium (engine/integrator/weights.py)."""

    NEVER = "never"
    ALWAYS = "always"
    AUTO_DIRECTION = "when direction is auto"  # unless a direction is requested


@dataclass(frozen=True)
class BothDevicesKernel:
    """The KernelSettings flags (field name -> value) a run of every link from both devices sets on top of
    `Algorithm.kernel` (engine/integrator/weights.py: the partition of unity between the two sides; the
    planner must then run every such link both ways, or it counts about half)."""

    in_medium: Mapping[str, object]
    in_vacuum: Mapping[str, object]


#: Outputs every algorithm fills.
BASE_OUTPUTS = ("dc_gain", "delays", "cir", "dc_gain_by_reflection_order")


@dataclass(frozen=True)
class Algorithm:
    """One estimator. `kernel` holds the KernelSettings flags it sets (field name -> value)."""

    number: int  # the value of `simulation.algorithm`
    name: str
    families: str  # the path families it estimates, in the report's notation
    left_out: tuple[str, ...]  # scattered families it does not estimate (in a scattering medium)
    kernel: Mapping[str, object]
    #: highest scattering order S it tallies when `max_scattering` is left out; None: chosen automatically
    #: (algorithm 5)
    scattering_orders: int | None
    #: the direction it always runs in; None: the planner chooses (requested, amortized, or by a pilot)
    direction: Direction | None
    direction_reason: str
    two_sided: TwoSided
    #: the medium it needs: does it estimate scattered light (sigma_s > 0)?
    counts_scattering: bool
    outputs: tuple[str, ...] = field(default=BASE_OUTPUTS)
    #: the result's warning when the scene's medium scatters ("" for none)
    warning_in_scattering_medium: str = ""
    #: the values of `max_scattering` it honours, lowest and highest (`scattering_refusal`)
    scattering_range: tuple[int, int] = (1, 1000)
    #: what its S means and what to do instead, in the words of the refusal (`scattering_refusal`)
    scattering_meaning: str = ""
    scattering_fix: str = ""
    #: (families, left_out) when `max_scattering` asks for single scattering only (algorithm 4 with S = 1)
    at_single_scattering: tuple[str, tuple[str, ...]] | None = None
    #: the flags of its run from both devices; None: it has none (it runs one side only)
    both_devices: BothDevicesKernel | None = None

    def S(self, max_scattering: int | None) -> int:
        """Highest scattering order tallied: `max_scattering` where the algorithm lets it choose (4: 1 or 2,
        5: any), else its own (1: 0, 2-3: 1, 4: 2 by default; 5 left out: 0 until chosen automatically)."""
        lo, hi = self.scattering_range
        if lo == hi or max_scattering is None:
            return self.scattering_orders if self.scattering_orders is not None else int(max_scattering or 0)
        return min(max(int(max_scattering), lo), hi)

    def both_devices_kernel(self, has_medium: bool) -> Mapping[str, object]:
        """KernelSettings flags of a run of every link from both devices (in a medium or not)."""
        if self.both_devices is None:
            raise ValueError(f"algorithm {self.number} has no two-sided form")
        return self.both_devices.in_medium if has_medium else self.both_devices.in_vacuum

    def families_at(self, S: int) -> tuple[str, tuple[str, ...]]:
        """(families, left_out) of a run that tallies scattering orders up to S."""
        if S == 1 and self.at_single_scattering is not None:
            return self.at_single_scattering
        return self.families, self.left_out

    def scattering_refusal(self, max_scattering: int | None) -> str | None:
        """The one sentence that refuses a `max_scattering` this algorithm cannot honour, or None."""
        lo, hi = self.scattering_range
        if max_scattering is None or lo <= max_scattering <= hi:
            return None
        return (
            f"algorithm {self.number} {self.scattering_meaning}, so `max_scattering` {max_scattering} "
            f"cannot be honoured: {self.scattering_fix}"
        )


def _mis_on_families(scatter_then_reflect: bool, reflect_then_scatter: bool) -> BothDevicesKernel:
    """Algorithms 2-4 from both devices, with a medium or without: the balance heuristic on the family both
    sides sample, the partition of unity on the others, and which single-scattering families are estimated:
    Tx -> p -> (k) -> Rx (`scatter_then_reflect`, algorithm 2's), Tx -> (k) -> p -> Rx (`reflect_then_scatter`,
    algorithm 3's)."""
    flags = MappingProxyType(
        {"mis": True, "scatter_then_reflect": scatter_then_reflect, "reflect_then_scatter": reflect_then_scatter}
    )
    return BothDevicesKernel(in_medium=flags, in_vacuum=flags)


_SCATTERED = BASE_OUTPUTS + ("dc_gain_by_scattering_order",)
_ONE_SIDED = {"free_flight": False, "segment_scatter": False, "mis": False}

ALGORITHMS: Mapping[int, Algorithm] = MappingProxyType(
    {
        a.number: a
        for a in (
            Algorithm(
                number=1,
                name="unscattered paths",
                families="paths without scattering (s = 0), reflection orders 0..K; extinction on every segment",
                left_out=("scattered light (s >= 1)",),
                kernel=_ONE_SIDED,
                scattering_orders=0,
                direction=None,
                direction_reason="",
                two_sided=TwoSided.NEVER,
                counts_scattering=False,
                warning_in_scattering_medium=(
                    "algorithm 1 counts only unscattered light: with sigma_s > 0 it underestimates "
                    "(use algorithm 4 or 5 for scattered light)"
                ),
                scattering_range=(0, 0),
                scattering_meaning="counts only unscattered light (S = 0)",
                scattering_fix="leave it out (or give 0), or use algorithm 4 or 5 for scattered light",
            ),
            Algorithm(
                number=2,
                name="in-scattering from the receiver side",
                families="s = 0 paths up to K reflections, plus single scattering lit directly by the transmitter: "
                "Tx -> p -> (k <= K reflections) -> Rx",
                left_out=(
                    "single scattering reached after reflections from the transmitter (Tx -> k >= 1 -> p -> Rx)",
                    "scattering orders s >= 2",
                ),
                kernel={**_ONE_SIDED, "segment_scatter": True},
                scattering_orders=1,
                direction=Direction.BACKWARD,
                direction_reason="algorithm 2 samples in-scattering from the receiver side",
                two_sided=TwoSided.ALWAYS,
                both_devices=_mis_on_families(scatter_then_reflect=True, reflect_then_scatter=False),
                counts_scattering=True,
                outputs=_SCATTERED,
                scattering_range=(1, 1),
                scattering_meaning="counts single scattering only (S = 1)",
                scattering_fix="leave it out (or give 1), or use algorithm 5 for higher orders",
            ),
            Algorithm(
                number=3,
                name="out-scattering from the transmitter side",
                families="s = 0 paths up to K reflections, plus single scattering seen directly by the receiver: "
                "Tx -> (k <= K reflections) -> p -> Rx",
                left_out=(
                    "single scattering lit after reflections (Tx -> p -> k >= 1 -> Rx)",
                    "scattering orders s >= 2",
                ),
                kernel={**_ONE_SIDED, "segment_scatter": True},
                scattering_orders=1,
                direction=Direction.FORWARD,
                direction_reason="algorithm 3 samples out-scattering from the transmitter side",
                two_sided=TwoSided.ALWAYS,
                both_devices=_mis_on_families(scatter_then_reflect=False, reflect_then_scatter=True),
                counts_scattering=True,
                outputs=_SCATTERED,
                scattering_range=(1, 1),
                scattering_meaning="counts single scattering only (S = 1)",
                scattering_fix="leave it out (or give 1), or use algorithm 5 for higher orders",
            ),
            Algorithm(
                number=4,
                name="both single-scattering families and in-then-out double scattering",
                families=(
                    "s = 0 paths up to K reflections, plus Tx -> p -> (k <= K) -> Rx and Tx -> (k <= K) -> p -> Rx, "
                    "the shared family Tx -> p -> Rx counted once, and the report's in-then-out double scattering "
                    "Tx -> p_in -> (k <= K) -> p_out -> Rx (s = 2)"
                ),
                left_out=(
                    "single scattering with reflections on both sides of p",
                    "double scattering with reflections before p_in or after p_out",
                    "scattering orders s >= 3",
                ),
                kernel={**_ONE_SIDED, "segment_scatter": True, "mis": True},
                scattering_orders=2,
                direction=Direction.BOTH,
                direction_reason="algorithm 4 runs both sides and weights their shared family by MIS",
                two_sided=TwoSided.ALWAYS,
                both_devices=_mis_on_families(scatter_then_reflect=True, reflect_then_scatter=True),
                counts_scattering=True,
                outputs=_SCATTERED,
                scattering_range=(1, 2),
                scattering_meaning=(
                    "counts single scattering (S = 1) or single and in-then-out double scattering (S = 2, the default)"
                ),
                scattering_fix="give 1 or 2, or use algorithm 5 for higher orders",
                at_single_scattering=(
                    "s = 0 paths up to K reflections, plus Tx -> p -> (k <= K) -> Rx and Tx -> (k <= K) -> p -> Rx, "
                    "the shared family Tx -> p -> Rx counted once (S = 1: no double scattering)",
                    (
                        "single scattering with reflections on both sides of p",
                        "scattering orders s >= 2 (S = 1 asked)",
                    ),
                ),
            ),
            Algorithm(
                number=5,
                name="free-flight paths with next-event estimation",
                families="all paths with at most K reflections and S scattering events, in any order",
                left_out=(),
                kernel={**_ONE_SIDED, "free_flight": True},
                scattering_orders=None,
                direction=None,
                direction_reason="",
                two_sided=TwoSided.AUTO_DIRECTION,
                # in a medium the partition weights every connection; in vacuum each side counts half (mis)
                both_devices=BothDevicesKernel(in_medium={"both_sides": True}, in_vacuum={"mis": True}),
                counts_scattering=True,
                outputs=_SCATTERED,
                scattering_meaning="counts scattering orders 1 to S (S >= 1)",
                scattering_fix="give at least 1, or use algorithm 1 for unscattered light only",
            ),
        )
    }
)


def algorithm(number: int | str) -> Algorithm:
    """The record of `simulation.algorithm = number` (a resolved setting, not "auto")."""
    try:
        return ALGORITHMS[int(number)]
    except (KeyError, ValueError, TypeError):
        raise ValueError(f"no algorithm {number!r}; the algorithms are {sorted(ALGORITHMS)}") from None
