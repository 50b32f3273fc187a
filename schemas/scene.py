"""The scene document: what `owcsim run` reads and `POST /v1/jobs` takes."""

from __future__ import annotations

from collections import Counter
from typing import Any

from pydantic import Field, model_validator

from .base import Point, SpecModel
from .devices import ReceiverGridSpec, ReceiverSpec, TransmitterSpec
from .geometry import BoxSpec, MeshSpec, RoomSpec
from .lighting import LightingSpec, check_lighting
from .link_budget import LinkBudgetSpec
from .medium import MediumSpec
from .orientation import AngleDiversityReceiverSpec, check_hidden, hidden_count, hidden_ids, hidden_receiver_fields
from .outputs import OutputsSpec
from .simulation import SimulationSpec
from .spectra import SpectralSpec, check_scene
from .timeline import TimelineSpec, check_timeline

#: Most tally cells (links x reflection orders x time bins) a job may hold.
MAX_TALLY_CELLS = 50_000_000


class TransmitterGroupSpec(SpecModel):
    """Transmitters that send the same signal (e.g. the LEDs of one ceiling): their channels add up.

    The group's channel is h_g(t) = sum_i P_i h_i(t) / sum_i P_i (per watt of the group's total
    power, P_i the members' optical powers); its received power is sum_i P_i H0_i.
    """

    name: str = Field(min_length=1, max_length=200)
    transmitters: list[str] = Field(
        min_length=1,
        description="ids of the member transmitters (default ids tx0, tx1, ... when a transmitter has none)",
    )


class SceneSpec(SpecModel):
    """Surfaces + transmitters + receivers + optional medium + simulation settings."""

    name: str | None = None
    description: str | None = None
    room: RoomSpec | None = None
    furniture: list[BoxSpec] = Field(default_factory=list)
    meshes: list[MeshSpec] = Field(default_factory=list)
    transmitters: list[TransmitterSpec] = Field(min_length=1)
    receivers: list[ReceiverSpec] = Field(default_factory=list)
    receiver_grids: list[ReceiverGridSpec] = Field(default_factory=list)
    angle_diversity_receivers: list[AngleDiversityReceiverSpec] = Field(
        default_factory=list, description="several photodiodes at one point, combined (docs/orientation.md)"
    )
    medium: MediumSpec | None = None
    transmitter_groups: list[TransmitterGroupSpec] = Field(
        default_factory=list,
        description="transmitters that carry one signal: each group's channel (their summed response, per "
        "watt of the group's total power: sum_i P_i h_i / sum_i P_i) is reported beside the links, and maps are "
        "drawn per group",
    )
    outputs: OutputsSpec = Field(
        default_factory=OutputsSpec,
        description="optional quantities to compute: the "
        "binned CIR and the order split (default: for explicit receivers, not grids)",
    )
    link_budget: LinkBudgetSpec | None = Field(
        None,
        description="photodiode and receiver electronics: adds SNR, BER of OOK and the bit rate the delay "
        "spread allows to links, channels and maps (Komine & Nakagawa 2004 noise model)",
    )
    lighting: LightingSpec | None = Field(
        None, description="EN 12464-1 task areas and cylindrical illuminance asked of the result (docs/lighting.md)"
    )
    spectral: SpectralSpec | None = Field(
        None,
        description="wavelength bands: per-band spectra of sources, surfaces, detectors and smoke "
        "(docs/spectra.md); without it the scene is grey",
    )
    simulation: SimulationSpec = Field(default_factory=SimulationSpec)
    timeline: TimelineSpec | None = Field(
        None, description="the channel over time: smoke frames and moving receivers (docs/fire-timeline.md)"
    )

    @model_validator(mode="after")
    def _check(self) -> "SceneSpec":
        check_scene(self)
        if not self.receivers and not self.receiver_grids and not self.angle_diversity_receivers:
            raise ValueError("the scene has no receiver: give `receivers` or `receiver_grids`")
        rx_ids = [r.id for r in self.receivers if r.id is not None] + [i for g in self.receiver_grids for i in g.ids()]
        rx_ids += [a.id for a in self.angle_diversity_receivers]
        check_hidden(self)
        tx_given = [d.id for d in self.transmitters if d.id is not None]
        for kind, ids in (("transmitters", tx_given), ("receivers", rx_ids)):
            dup = sorted(i for i, n in Counter(ids).items() if n > 1)  # linear: grids hold 1e5 receivers
            if dup:
                raise ValueError(f"{kind}: duplicate ids {dup[:20]}")
        # Explicit devices must be placed sensibly; grid points that are not are masked by the engine.
        devices: list[tuple[str, int, TransmitterSpec | ReceiverSpec | AngleDiversityReceiverSpec]] = [
            ("transmitters", i, d) for i, d in enumerate(self.transmitters)
        ]
        devices += [("receivers", i, d) for i, d in enumerate(self.receivers)]
        devices += [("angle_diversity_receivers", i, d) for i, d in enumerate(self.angle_diversity_receivers)]
        for kind, i, d in devices:
            problem = placement_problem(self, d.position, d.normal)
            if problem:
                raise ValueError(f"{kind}[{i}]" + (f" ({d.id})" if d.id else "") + f": {problem}")
        _check_oriented_points(self)
        check_timeline(self)
        tx_ids = self.transmitter_ids()
        known = set(tx_ids)
        names = [g.name for g in self.transmitter_groups]
        dup = sorted(n for n, c in Counter(names).items() if c > 1)
        if dup:
            raise ValueError(f"transmitter_groups: duplicate names {dup}")
        for gi, g in enumerate(self.transmitter_groups):
            missing = [t for t in g.transmitters if t not in known]
            if missing:
                raise ValueError(
                    f"transmitter_groups[{gi}] ({g.name}): no transmitter with id {missing}; "
                    f"the ids are {tx_ids[:10]}{' ...' if len(tx_ids) > 10 else ''}"
                )
            if len(set(g.transmitters)) != len(g.transmitters):
                raise ValueError(f"transmitter_groups[{gi}] ({g.name}): a transmitter is listed twice")
        check_lighting(self.lighting, [g.id_prefix for g in self.receiver_grids])
        lit = self.spectral is not None or any(t.luminous_output or t.photometry for t in self.transmitters)
        if self.lighting is not None and not lit:  # a grey scene's flux: luminous_output or a photometric file
            raise ValueError(
                "lighting: no transmitter gives a luminous flux, so there would be no figures: give the lamps "
                "`luminous_output` (luminous_flux [lm] or center_luminous_intensity [cd]) or a `photometry` file"
            )
        if self.simulation.is_resolved:  # the engine checks the budget once it has chosen K, S and the window
            self.check_tally_budget()
        return self

    def check_tally_budget(self) -> None:
        """ValueError when the outputs asked need more than MAX_TALLY_CELLS cells (resolved settings only)."""
        sim = self.simulation
        assert sim.max_reflections is not None, "the budget is checked once K is chosen"
        cells = self.tally_cells(sim.max_reflections, sim.scattering_orders, sim.n_bins)
        if cells > MAX_TALLY_CELLS:
            raise ValueError(
                f"the binned CIR and order split asked for need {cells} tally cells (links x orders x bins), more "
                f"than the budget of {MAX_TALLY_CELLS}: widen `time_bin_s`, shorten the window, lower "
                "`max_reflections` / `max_scattering`, or ask for them on fewer receivers (`outputs`)"
            )

    def tally_cells(self, max_reflections: int, max_scattering: int, n_bins: int) -> int:
        """Tally cells the asked outputs hold: CIR bins (per order when the split is asked) and order cells."""
        n_tx = len(self.transmitters)
        cir, orders = self.outputs.per_receiver(len(self.receivers), self.grid_receiver_count())
        n_cir = n_tx * sum(cir)
        n_ord = n_tx * sum(orders)
        n_both = n_tx * sum(c and o for c, o in zip(cir, orders)) if self.outputs.cir_by_order is not False else 0
        k, s = max_reflections + 1, max_scattering + 1
        return n_cir * n_bins + n_both * (k + s) * n_bins + n_ord * k * s

    def grid_receiver_count(self) -> int:
        """Receivers after the explicit ones: grid points, then the hidden receivers (orientation samples,
        angle-diversity photodiodes: schemas/orientation.py), which take the grid points' default outputs."""
        return sum(g.count for g in self.receiver_grids) + hidden_count(self)

    def all_receivers(self) -> list[ReceiverSpec]:
        """Receivers, then every grid expanded, in order."""
        out = list(self.receivers)
        for g in self.receiver_grids:
            out.extend(g.expand())
        return out

    def transmitter_ids(self) -> list[str]:
        return [t.id or f"tx{i}" for i, t in enumerate(self.transmitters)]

    def receiver_ids(self) -> list[str]:
        """Ids of the explicit receivers (rx<i> when not given), then of every grid point, then the hidden ones."""
        ids = [r.id or f"rx{i}" for i, r in enumerate(self.receivers)] + [
            i for g in self.receiver_grids for i in g.ids()
        ]
        return ids + list(hidden_ids(self, ids))

    def receiver_at(self, index: int) -> ReceiverSpec:
        """The receiver of global index `index` (explicit receivers first, then the grids' points, then the hidden
        receivers, in order)."""
        if index < len(self.receivers):
            return self.receivers[index]
        index -= len(self.receivers)
        for g in self.receiver_grids:
            if index < g.count:
                return g.point(*divmod(index, g.shape[1]))
            index -= g.count
        index += len(self.receivers) + sum(g.count for g in self.receiver_grids)  # back to the global index
        return ReceiverSpec(**hidden_receiver_fields(self, index))  # a hidden receiver (schemas/orientation.py)


def _check_oriented_points(scene: SceneSpec) -> None:
    """ValueError when an `orientation` would tilt a point on a room face into that face: the engine masks such
    samples, so the point's statistics would be null. A grid's points on a face include a corner (the grid is a
    rectangle), so its four corners are checked."""
    oriented: list[tuple[str, Any, list[Point], Any]] = [
        (f"receivers[{i}]" + (f" ({r.id})" if r.id else ""), r.orientation, [r.position], r.normal)
        for i, r in enumerate(scene.receivers)
        if r.orientation is not None
    ]
    for k, g in enumerate(scene.receiver_grids):
        if g.orientation is not None:
            nu, nv = g.shape
            corners = [g.point(i, j).position for i in {0, nu - 1} for j in {0, nv - 1}]
            oriented.append((f"receiver_grids[{k}] ({g.id_prefix})", g.orientation, corners, g.receiver_normal))
    for where, orientation, points, normal in oriented:
        normals = orientation.normals(normal)
        # per axis the sample normal leaning most toward -axis and +axis: the only ones a face can refuse
        extremes = [min(normals, key=lambda n: n[ax]) for ax in range(3)]
        extremes += [max(normals, key=lambda n: n[ax]) for ax in range(3)]
        for p in points:
            if placement_problem(scene, p, normal):  # a masked grid point (or a refused receiver): not ours
                continue
            for n in extremes:
                problem = placement_problem(scene, p, n)
                if problem:
                    at = tuple(round(c, 6) for c in p)
                    raise ValueError(
                        f"{where}: the point at {at} {problem.replace('faces', 'would face')} when tilted by "
                        "`orientation`, which gives it no statistics: move it off the face (e.g. 1 cm into the room)"
                    )


def placement_problem(scene: SceneSpec, p, n) -> str | None:
    """Why a device at `p` with normal `n` cannot see the room, or None.

    Outside the room, strictly inside a furniture box, or on a room face with its normal
    pointing into the face. A device on a face whose normal lies along the face (a grid
    point on the edge of the floor, facing up) is fine: half its field of view is open.
    """
    if scene.room is not None:
        lo, hi = scene.room.lo, scene.room.hi
        tol = 1e-9 * max(1.0, *map(abs, lo), *map(abs, hi))
        for ax in range(3):
            if p[ax] < lo[ax] - tol or p[ax] > hi[ax] + tol:
                return f"position {tuple(p)} is outside the room {lo}..{hi}"
            if abs(p[ax] - lo[ax]) <= tol and n[ax] < 0:
                return f"sits on a room face at {'xyz'[ax]} = {lo[ax]:g} and faces into it"
            if abs(p[ax] - hi[ax]) <= tol and n[ax] > 0:
                return f"sits on a room face at {'xyz'[ax]} = {hi[ax]:g} and faces into it"
    for j, box in enumerate(scene.furniture):
        if all(a < c < b for a, b, c in zip(box.min, box.max, p)):
            return f"position {tuple(p)} is inside furniture[{j}]" + (f" ({box.name})" if box.name else "")
    return None
