"""Memory budget of a job: an estimate of its peak memory [bytes] from its settings, before it runs.

The HTTP service admits jobs against a server-wide budget with this estimate and caps each
worker's address space from it; `benchmarks/job_memory.py` compares it with the measured
peak RSS of real jobs. Every term is named (`MemoryEstimate`), so that a change of the
tally shapes (engine/tally/tally.py) is one edit here.

The terms follow the arrays the engine allocates:

- `base`: the interpreter with numpy, scipy, trimesh and Embree imported (measured RSS of a
  fresh worker, BASE_BYTES);
- `geometry`: per triangle the float64 vertices and int64 faces, reflectance, group,
  normals (two layouts), the float32 copy handed to Embree and Embree's BVH
  (BYTES_PER_TRIANGLE, about 100 B of it Embree's);
- `devices`: per transmitter and receiver its spec object (grids expanded), id and arrays;
- `accumulators`: two `tally.Accumulator`s (forward and backward): per link the per-path moments
  (s1, s2, path and sample counts, the sample sums q1, q0, N_GROUPS path-group and batch-group sums:
  ~50 numbers); per link with a
  binned CIR (the job's `outputs`; by default the explicit receivers only) n_bins x (1 + N_GROUPS,
  + (K+1) + (S+1) with the order split) numbers, and in runs that may be one batch the first batch's
  CIR per path group (at most `tally.CIR_GROUPS_MAX` numbers, in the batch too); per link with the
  order split 3 (K+1)(S+1);
  the groups' channels G x n_rx x 18;
- `batch`: batches in flight (1 serial, 2 x workers in a pool); a batch holds paths x targets capped
  by `simulate.PATH_TARGET_BUDGET` (dense per-path tallies: 3 arrays and temporaries, ~10 numbers
  per pair), one step's next-event estimates capped by `simulate.ESTIMATE_BUDGET` (~60 B each) and,
  with quasi-random blocks, the order split's (sample, cell) table (at most `tally.SAMPLE_TABLE_MAX`);
- `photometry`: the transmitters' photometric files: while parsed, per number of the file its text token,
  (token, line) pair, list slot and float (BYTES_PER_PHOTOMETRY_VALUE; the numbers counted in the file),
  the file's base64 text, its bytes and its decoded text (3 bytes per base64 character), and the
  expanded table's intensities, CDF and copies (BYTES_PER_PHOTOMETRY_CELL per cell, when known);
- `result`: the result document: ~40 numbers per link (~70 B each as Python floats and JSON text),
  plus the CIR links' bins x (K+S+4) and the maps (~12 quantities per grid point and channel).

When K, S or the time window are "auto", the estimate takes the most the engine may choose
(pilot.PILOT_CAP orders; the pilot's longest window), i.e. an upper bound.
"""

from __future__ import annotations

import base64
import math
from dataclasses import asdict, dataclass
from typing import Any

import numpy as np

from owcsim.engine.core.constants import SPEED_OF_LIGHT
from owcsim.engine.core.qmc import BLOCK
from owcsim.engine.run.pilot import PILOT_CAP
from owcsim.engine.tally.plan import N_GROUPS
from owcsim.engine.tally.tally import CIR_GROUPS_MAX, SAMPLE_TABLE_MAX
from owcsim.schemas import SceneSpec
from owcsim.schemas.algorithms import ALGORITHMS, Direction
from owcsim.schemas.frames import InlineFramesSpec

#: The batch caps of engine/run/simulate.py (copied: simulate imports the whole engine, this module stays light).
PATH_TARGET_BUDGET = 1 << 20
ESTIMATE_BUDGET = 1 << 22

#: Peak RSS of a worker process with the engine imported that runs a 1-link, 50-bin job and renders
#: its result [B] (benchmarks/job_memory.py: 114 MB measured; rounded up).
BASE_BYTES = 128 * 2**20
#: Bytes per scene triangle: vertices and faces (~72 + 24), reflectance, group, normals (2 x 24),
#: float32 copy for Embree (36) and Embree's BVH (~100) [B].
BYTES_PER_TRIANGLE = 320
#: Bytes per device: pydantic spec object of a (grid-expanded) receiver, its id, its array rows [B].
BYTES_PER_DEVICE = 3_000
#: Bytes per next-event estimate of a step (target, k, s, delay, power, path and temporaries) [B].
BYTES_PER_CONTRIBUTION = 60
#: Bytes per number of the result document (Python float in a list + JSON text) [B].
BYTES_PER_RESULT_NUMBER = 70
#: Bytes per number of a photometric file while it is parsed (~170-200 measured for IES files of 10^5 to
#: 10^6 values, tests/server/test_hostile_bodies.py) [B].
BYTES_PER_PHOTOMETRY_VALUE = 256
#: Bytes per cell of an expanded photometric table: intensity, CDF and the arrays they come from [B].
BYTES_PER_PHOTOMETRY_CELL = 32
#: Bytes that separate the numbers of a photometric file.
_SEPARATORS = np.frombuffer(b" \t\r\n,;", np.uint8)
#: Extent assumed for the automatic time window when the scene's is unknown [m] (as engine/run/auto.py).
DEFAULT_EXTENT_M = 10.0


@dataclass(frozen=True)
class MemoryEstimate:
    """The terms of a job's peak memory [B]; `total` is their sum."""

    base: int
    geometry: int
    devices: int
    accumulators: int
    batch: int
    result: int
    photometry: int = 0
    frames: int = 0

    @property
    def total(self) -> int:
        return sum(asdict(self).values())


def _triangles(spec: SceneSpec) -> int:
    """Triangles of the room, furniture and inline meshes (file/base64 meshes: pass `triangles`)."""
    inline = sum(len(m.faces or ()) for m in spec.meshes)
    return (12 if spec.room is not None else 0) + 12 * len(spec.furniture) + inline


def _photometry(spec: SceneSpec, cells: int | None) -> int:
    """Memory of the transmitters' photometric files [B]: their numbers while parsed, their text and their
    expanded tables; `cells`: the tables' cells if known (the scene built), else 4 per number of the file
    (a quadrant-symmetric file stores a quarter of its table)."""
    total, numbers = 0, 0
    for t in spec.transmitters:
        if t.photometry is not None and t.photometry.data_base64 is not None:
            text = np.frombuffer(base64.b64decode(t.photometry.data_base64), np.uint8)
            is_token = ~np.isin(text, _SEPARATORS)
            n = int(np.count_nonzero(is_token[1:] & ~is_token[:-1])) + int(is_token[:1].sum())
            total += n * BYTES_PER_PHOTOMETRY_VALUE + 3 * len(t.photometry.data_base64)
            numbers += n
    return total + BYTES_PER_PHOTOMETRY_CELL * (cells if cells is not None else 4 * numbers)


def _extent(spec: SceneSpec) -> float:
    if spec.room is not None:
        return float(max(spec.room.size))
    return DEFAULT_EXTENT_M


def _orders(spec: SceneSpec, extent_m: float | None) -> tuple[Any, int, int, int]:
    """(algorithm or None for auto, K, S, time bins) the run's tallies are sized for: the pilot's caps where
    the document leaves them to the engine, the pilot's window where it leaves the window (auto.resolve)."""
    sim = spec.simulation
    k = sim.max_reflections if sim.max_reflections is not None else PILOT_CAP
    alg = ALGORITHMS.get(sim.algorithm) if sim.algorithm != "auto" else None  # (schemas/algorithms.py)
    if alg is None:  # auto: the pilot's S cap in a medium
        s = PILOT_CAP if spec.medium is not None or spec.timeline is not None else 1
    elif alg.scattering_orders is None:  # S chosen (algorithm 5)
        s = sim.max_scattering if sim.max_scattering is not None else PILOT_CAP
    else:
        s = alg.S(sim.max_scattering)
    if sim.t_max_s is not None:
        return alg, k, s, sim.n_bins
    extent = extent_m if extent_m is not None else _extent(spec)
    t_long = (k + s + 3) * 1.8 * extent / SPEED_OF_LIGHT
    return alg, k, s, max(1, math.ceil(t_long / sim.time_bin_s))


def _frames(spec: SceneSpec) -> tuple[int, int]:
    """(memory of a timeline's frames [B], tallies held at once). Inline frames: the frames, the frames at the
    evaluation times and the carrier, sigma_a and sigma_s of every cell in float64; file frames (FDS, netCDF,
    sent as base64): 8 bytes per base64 character (float32 files become two float64 fields, copied at the
    times). A timeline `reweighted` (asked, or `auto` from 3 times with no device moving and no grid) keeps one
    tally per time (engine/run/timeline.py `frames_method`)."""
    tl = spec.timeline
    if tl is None or tl.frames is None:
        return 0, 1
    frames = tl.frames
    times = tl.times_s
    if isinstance(frames, InlineFramesSpec):
        n_times = len(times) if times is not None else len(frames.times)
        memory = 2 * 8 * math.prod(frames.shape) * (len(frames.times) + n_times + 1)
    else:
        data = getattr(frames, "data_base64", None) or ""
        n_times = len(times) if times is not None else len(getattr(frames, "times_s", None) or ()) or 1
        memory = 8 * len(data)
    auto = tl.method.value == "auto" and n_times >= 3 and not tl.trajectories and not spec.receiver_grids
    return memory, n_times if tl.method.value == "reweighted" or auto else 1


def memory_estimate(
    spec: SceneSpec,
    *,
    triangles: int | None = None,
    extent_m: float | None = None,
    workers: int = 1,
    photometry_cells: int | None = None,
) -> MemoryEstimate:
    """Peak memory of `spec` run with `workers` engine processes [B], term by term.

    `triangles`: the scene's triangle count if known (meshes given as files); `extent_m`: the
    scene's largest side [m] if known (bounds the automatic window); `photometry_cells`: the cells of
    the transmitters' expanded photometric tables if known (the scene built).
    """
    sim = spec.simulation
    n_tx = len(spec.transmitters)
    n_rx = len(spec.receivers) + spec.grid_receiver_count()  # grid points and hidden receivers (orientation)
    n_links = n_tx * n_rx
    alg, k, s, n_bins = _orders(spec, extent_m)
    cells = (k + 1) * (s + 1)
    per_side = {Direction.FORWARD: n_rx, Direction.BACKWARD: n_tx}  # targets of a path from each side
    targets = max(n_rx, n_tx) if sim.direction == "auto" else per_side[Direction(sim.direction)]
    tri = triangles if triangles is not None else _triangles(spec)
    cir, orders = spec.outputs.per_receiver(len(spec.receivers), n_rx - len(spec.receivers))
    n_cir, n_ord = n_tx * sum(cir), n_tx * sum(orders)
    n_split = n_tx * sum(c and o for c, o in zip(cir, orders))
    n_groups = len(spec.transmitter_groups)
    per_cir_link = n_bins * (1 + N_GROUPS) + 2 + n_split / max(n_cir, 1) * n_bins * ((k + 1) + (s + 1))
    # the first batch's CIR per path group (tally.TallyPlan.first_batch_groups: runs that may be one batch)
    # (at most CIR_GROUPS_MAX: an automatic window may end up shorter than n_bins, within the cap)
    one_batch = sim.n_paths is None or sim.n_paths <= sim.batch_size
    first_groups = min(N_GROUPS * n_cir * n_bins, CIR_GROUPS_MAX) if one_batch else 0
    accumulators = (
        2 * 8 * (n_links * 50 + int(n_cir * per_cir_link) + n_ord * 3 * cells + n_groups * n_rx * 18 + first_groups)
    )
    frames_bytes, tallies = _frames(spec)
    accumulators *= tallies  # reweighted timelines keep one tally per frame (engine/run/frames_reweighted.py)
    n_bands = spec.spectral.n_bands if spec.spectral is not None else 0
    if n_bands:  # spectral channel sums per link and direction (engine/tally/spectral.py ChannelAccumulator)
        accumulators += 2 * 8 * n_links * ((n_bands + 10) * N_GROUPS + 2 * n_bands)
    # Paths per batch as simulate.batch_size caps them (targets x paths and estimates per step bounded).
    segment_points = alg is None or bool(alg.kernel["segment_scatter"])  # auto: as if (the largest)
    per_segment = 1 + (sim.max_strata + sim.equiangular_points if segment_points and spec.medium is not None else 0)
    batch_paths = max(
        1, min(sim.batch_size, PATH_TARGET_BUDGET // max(targets, 1), ESTIMATE_BUDGET // max(targets * per_segment, 1))
    )
    pairs = batch_paths * targets
    # the order split's (sample, cell) table of quasi-random batches (tally.BatchBuilder.sample_cells)
    table = (batch_paths // BLOCK) * min(targets, n_ord) * cells if sim.quasi_random else 0
    per_batch = (
        pairs * 14 * 8
        + min(pairs * per_segment, ESTIMATE_BUDGET) * BYTES_PER_CONTRIBUTION
        + (n_cir * n_bins * 8 * 2 if n_cir else 0)
        + 8 * first_groups
        + (8 * table if table <= SAMPLE_TABLE_MAX else 0)
    )
    in_flight = 1 if workers <= 1 else 2 * workers
    geometry = tri * BYTES_PER_TRIANGLE
    # A pool's workers each hold the scene and compute one batch at a time.
    pool = 0 if workers <= 1 else workers * (BASE_BYTES + geometry + per_batch)
    map_numbers = (n_rx - len(spec.receivers)) * max(n_groups, 1 if n_groups else n_tx) * 12
    return MemoryEstimate(
        base=BASE_BYTES,
        geometry=geometry,
        devices=(n_tx + n_rx) * BYTES_PER_DEVICE,
        accumulators=accumulators,
        batch=in_flight * per_batch + pool,
        result=(n_links * (40 + 6 * n_bands) + n_cir * n_bins * (k + s + 4) + map_numbers) * BYTES_PER_RESULT_NUMBER,
        photometry=_photometry(spec, photometry_cells),
        frames=frames_bytes,
    )


def job_memory_bytes(
    spec: SceneSpec,
    *,
    triangles: int | None = None,
    extent_m: float | None = None,
    workers: int = 1,
    photometry_cells: int | None = None,
) -> int:
    """Estimated peak memory of the job [B] (see `memory_estimate` for the terms)."""
    return memory_estimate(
        spec, triangles=triangles, extent_m=extent_m, workers=workers, photometry_cells=photometry_cells
    ).total
