"""A timeline job (schemas/timeline.py): the channel at every evaluation time, as one job.

The medium at time t is the frames interpolated linearly in time, cell by cell (`frames_at`: exactly
frame i at its own time). A moving receiver becomes one receiver per time, at its trajectory's position and
normal then (engine/scene/trajectory.py), traced only in that time's run. With frames, every time is a run
of engine/run/frames.py (the same seed for all: common random numbers); without (a static medium, or
none), one run traces every time's receivers together. The result is the first time's run with the
`timeline` section (engine/results/timeline.py) that holds every time.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from functools import partial
from pathlib import Path

import numpy as np

from owcsim.engine.core.arrays import FloatArray, IntArray
from owcsim.engine.core.errors import SceneError
from owcsim.engine.media.frame_sources import frames_from_spec
from owcsim.engine.media.frames import MediumFrames
from owcsim.engine.results.job import FinishedJob
from owcsim.engine.results.link_budget import link_budget_from_spec
from owcsim.engine.results.timeline import Series, build_timeline
from owcsim.engine.run.frames import FrameMethod, FramesOutcome, simulate_frames
from owcsim.engine.run.job import Progress, ProgressFn
from owcsim.engine.run.simulate import simulate
from owcsim.engine.scene.trajectory import normals_at, positions_at
from owcsim.engine.tally import reliability
from owcsim.schemas import SceneSpec
from owcsim.schemas.results import ChannelPublic, LinkPublic, SimulationResultPublic
from owcsim.schemas.scene import placement_problem
from owcsim.schemas.timeline import TimelineMethod

MEDIUM_IN_TIME = (
    "the frames interpolated linearly in time, cell by cell: sigma(t) = (1 - w) sigma_i + w sigma_(i+1), "
    "w = (t - t_i) / (t_(i+1) - t_i); exactly frame i at its own time"
)


def frames_at(frames: MediumFrames, times: FloatArray) -> MediumFrames:
    """The medium at `times` [s] (within the frames' times): linear interpolation in time, cell by cell."""
    t = np.asarray(times, np.float64)
    if t.min() < frames.times[0] or t.max() > frames.times[-1]:
        out = t[(t < frames.times[0]) | (t > frames.times[-1])]
        raise SceneError(
            f"timeline.times_s {out[:5].tolist()} lie outside the frames' times {frames.times[0]:g}.."
            f"{frames.times[-1]:g} s: the medium is known only between the first and the last frame"
        )
    if frames.n_frames == 1:
        i, w = np.zeros(len(t), np.int64), np.zeros(len(t))
    else:
        i = np.clip(np.searchsorted(frames.times, t, side="right") - 1, 0, frames.n_frames - 2)
        w = (t - frames.times[i]) / (frames.times[i + 1] - frames.times[i])
    j = np.minimum(i + 1, frames.n_frames - 1)
    wb = w[:, None, None, None]

    def mix(x: FloatArray) -> FloatArray:
        return (1.0 - wb) * x[i] + wb * x[j]

    return MediumFrames(
        t, frames.lo, frames.hi, mix(frames.sigma_a), mix(frames.sigma_s), frames.phase, frames.source, frames.report
    )


def expand_receivers(spec: SceneSpec, times: FloatArray) -> tuple[SceneSpec, IntArray, list[tuple[str, str | None]]]:
    """The document with every moving receiver copied once per time: (spec, frame_of_receiver, base ids).

    In document order: a static receiver stays (frame -1, every time); a moving receiver `id` becomes its
    copies `id@t<i>` at its position and normal at time i (frame i), so each time's run sees the receivers
    in document order. `base[r]` = (timeline id, None for a static receiver or its copy's id)."""
    assert spec.timeline is not None
    moving = {t.device: t for t in spec.timeline.trajectories}
    receivers, frame = [], []
    base: list[tuple[str, str | None]] = []
    for k, r in enumerate(spec.receivers):  # the document's explicit receivers, not a loop over paths
        rid = r.id or f"rx{k}"
        if rid not in moving:
            receivers.append(r.model_copy(update={"id": rid}))
            frame.append(-1)
            base.append((rid, None))
            continue
        p, n = positions_at(moving[rid], times), normals_at(moving[rid], r.normal, times)
        for i in range(len(times)):
            cid = f"{rid}@t{i}"
            at, facing = tuple(float(v) for v in p[i]), tuple(float(v) for v in n[i])
            problem = placement_problem(spec, at, facing)
            if problem is not None:  # (the copies skip the schema's check of explicit receivers)
                raise SceneError(f"timeline.trajectories ({rid}): at t = {times[i]:g} s the receiver {problem}")
            receivers.append(r.model_copy(update={"id": cid, "position": at, "normal": facing}))
            frame.append(i)
            base.append((rid, cid))
    return spec.model_copy(update={"receivers": receivers}), np.asarray(frame, np.int64), base


def _lookup(result: SimulationResultPublic) -> dict[tuple[str, str], LinkPublic | ChannelPublic]:
    table: dict[tuple[str, str], LinkPublic | ChannelPublic] = {(e.transmitter, e.receiver): e for e in result.links}
    table.update({(c.group, c.receiver): c for c in result.channels})
    return table


def _series(
    spec: SceneSpec,
    times: FloatArray,
    results: list[SimulationResultPublic],
    groups: list[tuple[FloatArray, FloatArray]],
    base: list[tuple[str, str | None]],
) -> list[Series]:
    """Every (transmitter or group, receiver) of the timeline over time; results[i] / groups[i] at time i."""
    tx_ids = spec.transmitter_ids()
    power = np.array([t.power for t in spec.transmitters])
    senders = [(t, "link", np.eye(len(tx_ids))[k]) for k, t in enumerate(tx_ids)]
    for g in spec.transmitter_groups:
        w = np.array([power[k] if t in g.transmitters else 0.0 for k, t in enumerate(tx_ids)])
        senders.append((g.name, "channel", w / w.sum()))
    tables = [_lookup(r) for r in results]
    rx_index = [{r.id: j for j, r in enumerate(res.receivers)} for res in results]
    area = {(r.id or f"rx{k}"): r.area for k, r in enumerate(spec.receivers)}
    rx_ids = list(dict.fromkeys(b for b, _ in base))
    copy_at = {b: [c for bb, c in base if bb == b] for b in rx_ids}
    out = []
    for rx in rx_ids:  # the timeline's few explicit receivers and transmitters (not paths, not map points)
        ids = [c if c is not None else rx for c in copy_at[rx]]
        ids = ids * len(times) if len(ids) == 1 else ids
        for name, kind, w in senders:
            entries = [tables[i][(name, ids[i])] for i in range(len(times))]
            x, n = [], []
            for i in range(len(results)):
                gh0, gp = groups[i]
                n_rx = gh0.shape[0] // len(tx_ids)
                flat = np.arange(len(tx_ids)) * n_rx + rx_index[i][ids[i]]
                x.append(w @ gh0[flat])
                n.append(gp[flat[int(np.argmax(w))]])
            pos = np.array([res.receivers[rx_index[i][ids[i]]].position for i, res in enumerate(results)])
            out.append(Series(name, rx, kind, entries, pos, np.array(x), np.array(n), area[rx]))
    return out


#: Fewest times for which `auto` reweights one set of paths rather than running every time on its own.
AUTO_REWEIGHT_MIN_TIMES = 3


def frames_method(spec: SceneSpec, n_times: int) -> FrameMethod:
    """The timeline's `method`; `auto` reweights (frames_reweighted.py: ~1/6 of the independent runs' cost at 60
    frames, benchmarks/timeline_cost.py) from AUTO_REWEIGHT_MIN_TIMES times on, except with receiver grids
    (per-frame tallies of every grid point) or moving devices (a receiver at another place at every time shares
    no paths between times: reweighting costs more than the runs), else runs every time on its own. (Scenes
    reweighting does not support, spectral or with perfect mirrors, fall back to independent runs in
    `run_timeline`, with a note.)"""
    tl = spec.timeline
    assert tl is not None
    if tl.method is not TimelineMethod.AUTO:
        return FrameMethod(tl.method.value)
    if spec.receiver_grids or tl.trajectories or n_times < AUTO_REWEIGHT_MIN_TIMES:
        return FrameMethod.INDEPENDENT
    return FrameMethod.REWEIGHTED


def _frames_outcome(
    run: Callable[..., FramesOutcome], method: FrameMethod, auto: bool, notes: list[str]
) -> FramesOutcome:
    """`run(method=...)`; an `auto` choice of reweighting that the scene does not support (a "frames:" refusal of
    frames_reweighted.py: spectral bands, perfect mirrors) runs every time on its own instead, with a note."""
    if not (auto and method is FrameMethod.REWEIGHTED):
        return run(method=method)
    try:
        return run(method=method)
    except SceneError as err:
        if not str(err).startswith("frames:"):
            raise
        notes.append(f"method auto: every time runs on its own, since reweighting cannot ({err})")
        return run(method=FrameMethod.INDEPENDENT)


def run_timeline(
    spec: SceneSpec,
    *,
    base_dir: str | Path | None = None,
    workers: int = 1,
    progress: ProgressFn | None = None,
    should_stop: Callable[[], bool] | None = None,
) -> SimulationResultPublic:
    """Run the document's timeline; the result is the first time's run with the `timeline` of every time."""
    tl = spec.timeline
    assert tl is not None, "run_timeline needs a document with a `timeline`"
    t0 = time.perf_counter()
    read = frames_from_spec(tl.frames, base_dir) if tl.frames is not None else None
    given = tl.times_s if tl.times_s is not None else (read.times if read is not None else None)
    assert given is not None, "the schema asks for times_s without frames"
    times = np.asarray(given, np.float64)
    expanded, frame_of_rx, base = expand_receivers(spec, times)
    notes = ["links, receivers and maps of this result are those of the first time; `timeline` holds every time"]
    if read is not None:
        frames = frames_at(read, times)

        def per_frame(done: int, total: int) -> None:
            if progress is not None:
                progress(Progress(done / total, 0, done, None, time.perf_counter() - t0))

        run = partial(
            simulate_frames,
            expanded.model_copy(update={"timeline": None}),
            frames,
            frame_of_receiver=frame_of_rx,
            base_dir=base_dir,
            workers=workers,
            progress=per_frame,
            should_stop=should_stop,
        )
        outcome = _frames_outcome(run, frames_method(spec, len(times)), tl.method is TimelineMethod.AUTO, notes)
        results = outcome.results
        done = len(results)
        assert outcome.dc_gain_groups is not None and outcome.group_paths is not None
        groups = [(outcome.dc_gain_groups[i], outcome.group_paths[i]) for i in range(done)]
        method_name, report = outcome.method.value, read.frames_report()
        source = report.text()
    else:
        seen: list[FinishedJob] = []
        one = simulate(
            expanded.model_copy(update={"timeline": None}),
            base_dir=base_dir,
            workers=workers,
            progress=progress,
            should_stop=should_stop,
            on_finished=seen.append,
        )
        done = len(times)
        results, groups = [one] * done, [reliability.group_dc_gain(seen[0].accs.values(), seen[0].los.gain)] * done
        method_name, source, report = "one_run", None, None
        notes.append("the medium does not change: one run traced every time's receivers together")
    if done < len(times):
        notes.append(f"stopped after {done} of {len(times)} times: the timeline holds those")
        times = times[:done]
    budget = link_budget_from_spec(spec.link_budget) if spec.link_budget is not None else None
    timeline = build_timeline(
        times,
        _series(spec, times, results, groups, base),
        outage=tl.outage,
        budget=budget,
        method=method_name,
        frames_source=source,
        frames_report=report,
        medium_in_time=MEDIUM_IN_TIME if tl.frames is not None else "the document's static medium (no frames)",
        cir=tl.cir,
        notes=notes,
    )
    return results[0].model_copy(update={"timeline": timeline, "scene": spec})
