"""The frames of a time-varying medium as runs: one result per frame, with path groups shared across frames.

INDEPENDENT: frame f is its own run of the scene with the frame as its static medium (a `GridMediumSpec`
of the frame's cells, so a frame equals the same grid given as a static medium, bit for bit), every run
with the document's seed: common random numbers, so the frame-to-frame changes are smooth and the error of
a difference is small. Automatic settings ("auto" K, S, window) are resolved once, by running the frame of the
largest total extinction first, and every frame runs with them (the same plan, the same random streams).
Each run keeps its path groups' H0 estimates (engine/tally/reliability.py `group_means`, the groups
lighting's jackknife uses): group g holds the same sample indices in every frame, so the spread of the
groups' differences gives the error of a difference between frames (engine/results/timeline.py).
REWEIGHTED: one set of paths traced in a carrier medium and reweighted per frame (frames_reweighted.py,
engine/media/frame_ratios.py); the same outcome, at a fraction of the independent runs' cost.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from enum import StrEnum
from pathlib import Path

import numpy as np

from owcsim.engine.core.arrays import FloatArray, IntArray
from owcsim.engine.core.errors import SceneError
from owcsim.engine.media.frames import MediumFrames
from owcsim.engine.results.job import FinishedJob
from owcsim.engine.run.execution import Executor, ProcessExecutor, SerialExecutor
from owcsim.engine.run.frames_reweighted import simulate_reweighted
from owcsim.engine.run.job import Progress
from owcsim.engine.run.simulate import simulate
from owcsim.engine.tally import reliability
from owcsim.schemas import GridMediumSpec, SceneSpec
from owcsim.schemas.results import SimulationResultPublic


class FrameMethod(StrEnum):
    """How frames run: each its own run (same seed), or one set of paths reweighted per frame."""

    INDEPENDENT = "independent"
    REWEIGHTED = "reweighted"


@dataclass
class FramesOutcome:
    """One result per frame (fewer when stopped), and per frame, link and path group the group's H0 estimate."""

    results: list[SimulationResultPublic]
    dc_gain_groups: FloatArray | None  # (F, n_links, G): each path group's H0 (exact LOS included)
    method: FrameMethod
    group_paths: FloatArray | None = None  # (F, n_links, G): each group's paths (its weight; 0 = empty)


def frame_medium(frames: MediumFrames, f: int) -> GridMediumSpec:
    """Frame f as the document's static medium (the same cells, coefficients and phase function)."""
    return frames.grid_spec(f)


def frame_spec(spec: SceneSpec, frames: MediumFrames, f: int, keep: IntArray | None = None) -> SceneSpec:
    """The document of frame f: its medium the frame, no timeline, the explicit receivers `keep` (default all)."""
    update: dict[str, object] = {"medium": frame_medium(frames, f), "timeline": None}
    if keep is not None:
        update["receivers"] = [spec.receivers[i] for i in keep]
    return spec.model_copy(update=update)


def _receivers_of(frame_of_receiver: IntArray | None, f: int) -> IntArray | None:
    if frame_of_receiver is None:
        return None
    return np.flatnonzero((frame_of_receiver == f) | (frame_of_receiver == -1))


def _check(spec: SceneSpec, frames: MediumFrames, frame_of_receiver: IntArray | None) -> None:
    if spec.medium is not None:
        raise SceneError("a run over frames takes its medium from the frames: the document's `medium` must be absent")
    if frame_of_receiver is None:
        return
    if len(frame_of_receiver) != len(spec.receivers):
        raise SceneError(f"frame_of_receiver has {len(frame_of_receiver)} entries for {len(spec.receivers)} receivers")
    if np.any(frame_of_receiver < -1) or np.any(frame_of_receiver >= frames.n_frames):
        raise SceneError(f"frame_of_receiver: entries must be -1 or a frame index 0..{frames.n_frames - 1}")
    counts = {len(_receivers_of(frame_of_receiver, f)) for f in range(frames.n_frames)}  # type: ignore[arg-type]
    if len(counts) != 1 or 0 in counts:
        raise SceneError("frame_of_receiver: every frame needs the same number (>= 1) of receivers")


@dataclass
class _Run:
    """One frame's run: its result and its finished job (the tallies' path groups)."""

    result: SimulationResultPublic
    finished: FinishedJob


def _run(spec: SceneSpec, base_dir, executor: Executor, should_stop) -> _Run:
    finished: list[FinishedJob] = []
    result = simulate(spec, base_dir=base_dir, executor=executor, should_stop=should_stop, on_finished=finished.append)
    return _Run(result, finished[0])


def _resolved(
    spec: SceneSpec, frames: MediumFrames, frame_of_receiver, base_dir, executor, should_stop
) -> tuple[SceneSpec, dict[int, _Run]]:
    """The document with explicit settings: "auto" resolved once, by running the frame of the largest total
    extinction (kept: its main run is the run of the resolved document, the same bits)."""
    if spec.simulation.is_resolved:
        return spec, {}
    heavy = int(np.argmax(frames.sigma_t.reshape(frames.n_frames, -1).sum(axis=1)))
    run = _run(
        frame_spec(spec, frames, heavy, _receivers_of(frame_of_receiver, heavy)), base_dir, executor, should_stop
    )
    return spec.model_copy(update={"simulation": run.finished.spec.simulation}), {heavy: run}


def simulate_frames(
    spec: SceneSpec,
    frames: MediumFrames,
    *,
    frame_of_receiver: IntArray | None = None,
    method: FrameMethod = FrameMethod.INDEPENDENT,
    base_dir: str | Path | None = None,
    workers: int = 1,
    progress: Callable[[int, int], None] | None = None,
    should_stop: Callable[[], bool] | None = None,
) -> FramesOutcome:
    """Run the scene once per frame (see the module docstring); `frame_of_receiver[r]` is the frame whose time
    receiver r (of `spec.receivers`) belongs to, -1 every frame. `progress(done, F)` after every frame;
    `should_stop` is asked after every batch (a stopped frame ends the runs: its result is the last)."""
    for_rx = None if frame_of_receiver is None else np.asarray(frame_of_receiver, np.int64)
    _check(spec, frames, for_rx)
    if method is FrameMethod.REWEIGHTED:
        return _reweighted(spec, frames, for_rx, base_dir, workers, progress, should_stop)
    executor: Executor = SerialExecutor() if workers <= 1 else ProcessExecutor(workers)
    results: list[SimulationResultPublic] = []
    groups: list[tuple[FloatArray, FloatArray]] = []
    try:
        resolved, done = _resolved(spec, frames, for_rx, base_dir, executor, should_stop)
        for f in range(frames.n_frames):  # one run per frame: a loop over frames, each a vectorized run
            keep = _receivers_of(for_rx, f)
            run = done.pop(f, None) or _run(frame_spec(resolved, frames, f, keep), base_dir, executor, should_stop)
            groups.append(reliability.group_dc_gain(run.finished.accs.values(), run.finished.los.gain))
            results.append(run.result)
            if progress is not None:
                progress(f + 1, frames.n_frames)
            if should_stop is not None and should_stop():
                break
    finally:
        executor.close()
    n_groups = max(g.shape[1] for g, _ in groups)
    h0 = np.stack([np.pad(g, ((0, 0), (0, n_groups - g.shape[1]))) for g, _ in groups])
    paths = np.stack([np.pad(c, ((0, 0), (0, n_groups - c.shape[1]))) for _, c in groups])
    return FramesOutcome(results, h0, FrameMethod.INDEPENDENT, paths)


def _reweighted(
    spec: SceneSpec,
    frames: MediumFrames,
    frame_of_receiver: IntArray | None,
    base_dir: str | Path | None,
    workers: int,
    progress: Callable[[int, int], None] | None,
    should_stop: Callable[[], bool] | None,
) -> FramesOutcome:
    """REWEIGHTED: every frame from one set of paths (frames_reweighted.py); progress as the frames' share done."""
    n = frames.n_frames

    def report(p: Progress) -> None:
        if progress is not None:
            progress(min(n, int(p.fraction * n)), n)

    results, h0, paths = simulate_reweighted(
        spec,
        frames,
        frame_of_receiver=frame_of_receiver,
        base_dir=base_dir,
        workers=workers,
        progress=report,
        should_stop=should_stop,
    )
    if progress is not None:
        progress(len(results), n)
    return FramesOutcome(results, h0, FrameMethod.REWEIGHTED, paths)
