"""Path state and the kernel's configuration: what every event of the integrator reads and writes.

`KernelSettings` (one algorithm's kernel configuration, its flags from the registry
schemas/algorithms.py), `WorkItem` (one batch of paths from one device), `Paths` (the path state as
a structure of arrays, as pbrt-v4's wavefront integrator keeps it) and the small array helpers the
events share. Nothing here imports another integrator module.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from owcsim.engine.core import qmc
from owcsim.engine.core.arrays import FloatArray, IntArray
from owcsim.engine.media.frame_ratios import PathRatios
from owcsim.engine.media.medium import Medium
from owcsim.engine.media.phase import PhaseFunction
from owcsim.engine.scene.scene import Scene
from owcsim.engine.sources.devices import Devices
from owcsim.engine.tally.plan import TallyPlan, TimeBins
from owcsim.schemas.algorithms import Direction


@dataclass(frozen=True)
class KernelSettings:
    max_reflections: int  # K
    russian_roulette: bool
    rr_start_depth: int
    tally: TallyPlan
    max_scattering: int = 0  # S: 0 for algorithm 1, 1 for 2-4, S for 5
    free_flight: bool = False  # algorithm 5
    segment_scatter: bool = False  # algorithms 2-4
    strata_length: float = 0.0  # [m] path-length width of the time strata (c dt)
    max_strata: int = 64
    equiangular_points: int = 2  # per segment and target, combined with the time strata (balance heuristic)
    #: algorithms 2-4 run from both devices: balance heuristic on the family both directions sample
    #: (k = 0), path partition of unity on the others (weights.py)
    mis: bool = False
    #: the single-scattering families algorithms 2-4 estimate (both in one-sided runs; from both devices
    #: algorithm 2 keeps only `scatter_then_reflect`, algorithm 3 only `reflect_then_scatter`, algorithm 4 both):
    #: Tx -> p -> (k reflections) -> Rx, algorithm 2's family (the receiver's own: points on its segments)
    scatter_then_reflect: bool = True
    #: Tx -> (k reflections) -> p -> Rx, algorithm 3's family (the transmitter's own)
    reflect_then_scatter: bool = True
    #: algorithm 5 run from both devices: every connection is weighted by the path partition of unity
    #: of weights.side_weight (bounded weights near point devices)
    both_sides: bool = False
    #: roulette threshold theta: survival min(1, w / (theta w0)); paths above theta w0 always survive
    rr_threshold: float = 0.25  # measured: benchmarks/replicate_study.py --study roulette (docs/smoke-error-bars.md)
    #: a peaked phase function: the source also samples the phase lobe about the axis toward each target for
    #: Tx -> p -> Rx (lobe.lobe_connections, balance heuristic): algorithm 5 (from either side or both),
    #: algorithms 2-4 from both devices
    phase_lobe: bool = False
    #: paths per block of randomly shifted Sobol points for the first dimensions of each path (emission
    #: direction, first free-flight distance, first bounce direction; engine/core/qmc.py); a batch that is not a
    #: whole number of blocks, or qmc_block <= 1, draws pseudo-random numbers. Blocks are independent, the
    #: paths in a block are not: the tallies take a block as one sample of the standard errors (tally.py).
    qmc_block: int = qmc.BLOCK
    #: tallies per target: 1, or 1 + the channels of a spectral scene (engine/spectral/spectra.py); bounds batch memory
    tally_channels: int = 1

    @property
    def in_then_out(self) -> bool:
        """Algorithm 4 with S = 2: the double-scattering family Tx -> p_in -> (k) -> p_out -> Rx (single_scatter.py)."""
        return self.segment_scatter and self.mis and self.max_scattering >= 2

    @property
    def n_scatter_orders(self) -> int:
        return self.max_scattering + 1

    @property
    def bins(self) -> TimeBins:
        return self.tally.bins

    def own_family(self, forward: bool) -> bool:
        """Is the family whose points lie on this side's own segments estimated (forward: Tx -> (k) -> p -> Rx,
        backward: Tx -> p -> (k) -> Rx)?"""
        return self.reflect_then_scatter if forward else self.scatter_then_reflect

    def other_family(self, forward: bool) -> bool:
        """Is the other side's family estimated (from here by scattering on the first segment)?"""
        return self.scatter_then_reflect if forward else self.reflect_then_scatter


@dataclass(frozen=True)
class WorkItem:
    """A batch: `n_paths` paths from device `source` of the `direction`'s source set.

    `targets` are indices in the other set; `batch` the batch index for this source;
    `seed_key` spawns the batch's independent random stream (fixed by the job).
    """

    direction: Direction  # FORWARD or BACKWARD (its value is accepted too)
    source: int
    targets: tuple[int, ...]
    batch: int
    n_paths: int
    seed: int
    phase: int = 0  # 0 = main run, 1 = pilot
    #: a packed batch (maps, engine/run/allocation.py): paths of several sources of one device kind, `counts[m]`
    #: paths from `sources[m]`, in that order (`n_paths` is their sum; `source` is sources[0]); empty: one source
    sources: tuple[int, ...] = ()
    counts: tuple[int, ...] = ()
    part: int = 0  # a packed batch's index among the round's packed batches (its random stream)

    def __post_init__(self) -> None:
        object.__setattr__(self, "direction", Direction(self.direction))  # one spelling: the enum

    @property
    def packed(self) -> bool:
        """True for a batch of several sources' paths (`sources`, `counts`)."""
        return len(self.sources) > 0

    def rng(self) -> np.random.Generator:
        key: tuple[int, ...] = (self.phase, self.direction.code, self.source, self.batch)
        if self.packed:  # its own streams: a packed batch's first source may run a batch of that index alone
            key += (len(self.sources), self.part)
        return np.random.default_rng(np.random.SeedSequence(self.seed, spawn_key=key))


def device_sets(scene: Scene, direction: Direction) -> tuple[Devices, Devices]:
    """(sources, targets) of paths run in `direction` (forward: from the transmitters)."""
    if direction is Direction.FORWARD:
        return scene.transmitters, scene.receivers
    return scene.receivers, scene.transmitters


def item_links(scene: Scene, item: WorkItem) -> IntArray:
    """Global link index of each of the item's targets; a packed batch: of each (target, source) pair, (T * M,)
    in target-major order."""
    t = np.asarray(item.targets)
    if item.packed:
        src = np.asarray(item.sources, np.int64)[None, :]
        if item.direction is Direction.FORWARD:
            return np.asarray(scene.link(src, t[:, None])).ravel()
        return np.asarray(scene.link(t[:, None], src)).ravel()
    if item.direction is Direction.FORWARD:
        return scene.link(item.source, t)
    return scene.link(t, item.source)


def dot(a: FloatArray, b: FloatArray) -> FloatArray:
    """Row-wise dot product of (3, n) component arrays (a[0] b[0] + a[1] b[1] + a[2] b[2], two temporaries)."""
    out = a[0] * b[0]
    term = a[1] * b[1]
    out += term
    np.multiply(a[2], b[2], out=term)
    out += term
    return out


def dot3(a: Any, b: Any) -> Any:
    """Row-wise dot product a[0] b[0] + a[1] b[1] + a[2] b[2] of (3, ...) arrays that may broadcast
    ((3, n) with (3, 1), or vectors (3,)); the same sum, in the same order, as `dot`."""
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]


def dot_vector(a: FloatArray, v: FloatArray) -> FloatArray:
    """dot(a, v) of (3, n) component rows with one vector v (3,), its zero components skipped (devices
    facing along an axis: one pass instead of five; x * 0 adds exactly nothing to a finite sum)."""
    terms = [(a[i], float(v[i])) for i in range(3) if v[i] != 0.0]
    if not terms:
        return np.zeros(a.shape[1])
    row, c = terms[0]
    out = row * c if c != 1.0 else row.copy()
    for row, c in terms[1:]:
        out += row * c if c != 1.0 else row
    return out


def rows(a: Any, idx: IntArray | None) -> Any:
    """a[..., idx], or `a` itself when idx is None (every row)."""
    return a if idx is None else a.take(idx, axis=-1)


class Paths:
    """Path state as a structure of arrays: (3, n) component arrays and (n,) arrays, one row per path.

    A new per-path quantity is one more name in FIELDS (and one more keyword where the batch starts);
    `gather(idx)` compacts every field with one index array (`take`, several times faster than a mask).
    """

    #: `weights`: the path throughput (power per watt carried so far, divided by the sampling densities);
    #: `first`: the source-side density factor of the path's first vertex (weights.first_vertex_factor);
    #: `first_rho`: the direction density of leaving it (phase, or 1/pi at a surface; weights.side_weight);
    #: both None unless the run shares paths with the other device's (KernelSettings.mis, both_sides)
    #: `ratio`: (B, n) per-band throughput over the carrier's of spectral scenes, (0, n) otherwise (spectra.py)
    FIELDS = ("origins", "directions", "weights", "lengths", "path", "k", "s", "first", "first_rho", "ratio")
    origins: FloatArray  # (3, n) [m]
    directions: FloatArray  # (3, n) unit
    weights: FloatArray  # (n,) path throughput
    lengths: FloatArray  # (n,) path length so far [m]
    path: IntArray  # (n,) index of the path in the batch
    k: IntArray  # (n,) reflections so far
    s: IntArray  # (n,) scattering events so far
    first: FloatArray | None
    first_rho: FloatArray | None
    ratio: FloatArray  # (B, n) band ratios (+ a carrier-depth row), or (0, n): spectra.SceneSpectra

    def __init__(self, **arrays: Any) -> None:
        for name in self.FIELDS:
            setattr(self, name, arrays[name])

    def __len__(self) -> int:
        return len(self.weights)

    @staticmethod
    def _of(fields: dict[str, Any]) -> Paths:
        """A Paths from a complete field dict, without the keyword machinery (a step makes several)."""
        out = object.__new__(Paths)
        out.__dict__.update(fields)
        return out

    def gather(self, idx: IntArray) -> Paths:
        """The paths at rows `idx` (any order, repeats allowed), every field gathered once (None stays None)."""
        return Paths._of({f: None if a is None else a.take(idx, axis=-1) for f, a in self.__dict__.items()})

    keep = gather

    def keep_where(self, mask: Any) -> Paths:
        """The paths where `mask` holds; free when it holds everywhere."""
        if mask.all():
            return Paths._of(dict(self.__dict__))
        return self.gather(mask.nonzero()[0])

    @staticmethod
    def concat(parts: Sequence[Paths]) -> Paths:
        if len(parts) == 1:
            return parts[0]
        return Paths._of(
            {
                f: None if a is None else np.concatenate([p.__dict__[f] for p in parts], axis=-1)
                for f, a in parts[0].__dict__.items()
            }
        )


class BatchState:
    """One batch's targets and its estimate lists: what every next-event estimate reads and records into.

    The connections themselves (`context.BatchContext.connect`, the measurement equation) and the tally
    (`flush`, `reduce`) build on this; the lower parts (weights, lobe) read the targets and `record`.
    """

    KEYS = ("target", "k", "s", "delay", "power", "path")

    def __init__(self, scene: Scene, targets: Devices, tgt: IntArray, settings: KernelSettings, item: WorkItem):
        self.scene, self.targets, self.tgt, self.settings, self.item = scene, targets, tgt, settings, item
        self.t_pos = np.ascontiguousarray(targets.positions[tgt].T)  # (3, T)
        self.t_nrm = np.ascontiguousarray(targets.normals[tgt].T)
        self.t_nrm_neg = -self.t_nrm  # (3, T): cos at the target = dot(direction toward it, -normal)
        self.t_total = np.array([targets.total_response(int(t)) for t in tgt], float)
        self.t_directional = targets.directional
        #: spectral scenes: per-band tables; estimates carry their band ratios ("ratio") when paths do
        self.spectra = scene.spectra
        #: the per-path ratio rows' part: the bands of a spectral scene, or the frames of a time-varying medium
        #: (engine/media/frame_ratios.py, `Scene.path_ratios`); the events call it through `PathRatios`
        self.ratios: PathRatios | None = scene.spectra if scene.spectra is not None else scene.path_ratios
        self.keys = self.KEYS + (("ratio",) if self.ratios is not None and self.ratios.carry else ())
        self.out: dict[str, list[Any]] = {k: [] for k in self.keys}
        self.mirrors = scene.mirror_planes

    @property
    def medium(self) -> Medium:
        """The scene's medium: asked only by the parts that run in one (algorithms 2-5, two-sided weights)."""
        medium = self.scene.medium
        assert medium is not None
        return medium

    @property
    def phase(self) -> PhaseFunction:
        """The medium's phase function (`Scene.phase`, set with the medium)."""
        phase = self.scene.phase
        assert phase is not None
        return phase

    def record(
        self,
        target: IntArray,
        k: IntArray,
        s: IntArray,
        delay: FloatArray,
        power: FloatArray,
        path: IntArray,
        ratio: FloatArray | None = None,
    ) -> None:
        """One group of estimates: local target index, cell (k, s), delay [s], power [W/W], path in the batch,
        and in spectral scenes whose paths carry band ratios, those (B, m) (spectra.py)."""
        for key, value in zip(self.KEYS, (target, k, s, delay, power, path)):
            self.out[key].append(value)
        if "ratio" in self.out:
            if ratio is None:
                raise RuntimeError("an estimate of a spectral scene was recorded without its band ratios")
            self.out["ratio"].append(ratio)
