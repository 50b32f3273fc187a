"""The scene document: what `owcsim run` reads and `POST /v1/jobs` takes."""
from __future__ import annotations

from collections import Counter

from pydantic import Field, model_validator

from .base import SpecModel
from .devices import ReceiverGridSpec, ReceiverSpec, TransmitterSpec
from .geometry import BoxSpec, MeshSpec, RoomSpec
from .medium import MediumSpec
from .simulation import SimulationSpec

#: Most tally cells (links x reflection orders x time bins) a job may hold.
MAX_TALLY_CELLS = 50_000_000


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
    medium: MediumSpec | None = None
    simulation: SimulationSpec = Field(default_factory=SimulationSpec)

    @model_validator(mode="after")
    def _check(self) -> "SceneSpec":
        rx = self.all_receivers()
        if not rx:
            raise ValueError("the scene has no receiver: give `receivers` or `receiver_grids`")
        for kind, devs in (("transmitters", self.transmitters), ("receivers", rx)):
            ids = [d.id for d in devs if d.id is not None]
            dup = sorted(i for i, n in Counter(ids).items() if n > 1)  # linear: grids hold 1e5 receivers
            if dup:
                raise ValueError(f"{kind}: duplicate ids {dup}")
        for kind, devs in (("transmitters", self.transmitters), ("receivers", rx)):
            for i, d in enumerate(devs):
                _check_device_placement(self, f"{kind}[{i}]" + (f" ({d.id})" if d.id else ""), d)
        sim = self.simulation
        if not sim.is_resolved:  # the engine checks the budget once it has chosen K, S and the window
            return self
        orders = (sim.max_reflections + 1) * (sim.scattering_orders + 1)
        cells = len(self.transmitters) * len(rx) * orders * sim.n_bins
        if cells > MAX_TALLY_CELLS:
            raise ValueError(
                f"{len(self.transmitters)} x {len(rx)} links x {orders} (reflection, scattering) orders x "
                f"{sim.n_bins} bins = {cells} tally cells, more than the budget of {MAX_TALLY_CELLS}: "
                "widen `time_bin_s`, shorten the window or lower `max_reflections` / `max_scattering`")
        return self

    def all_receivers(self) -> list[ReceiverSpec]:
        """Receivers, then every grid expanded, in order."""
        out = list(self.receivers)
        for g in self.receiver_grids:
            out.extend(g.expand())
        return out

    def transmitter_ids(self) -> list[str]:
        return [t.id or f"tx{i}" for i, t in enumerate(self.transmitters)]

    def receiver_ids(self) -> list[str]:
        return [r.id or f"rx{i}" for i, r in enumerate(self.all_receivers())]


def _check_device_placement(scene: SceneSpec, where: str, dev) -> None:
    """A device must be inside the room (on a face is fine if it faces inward), not in furniture."""
    p, n = dev.position, dev.normal
    if scene.room is not None:
        lo, hi = scene.room.lo, scene.room.hi
        tol = 1e-9 * max(1.0, *map(abs, lo), *map(abs, hi))
        for ax in range(3):
            if p[ax] < lo[ax] - tol or p[ax] > hi[ax] + tol:
                raise ValueError(f"{where}: position {p} is outside the room {lo}..{hi}")
            if abs(p[ax] - lo[ax]) <= tol and n[ax] <= 0:
                raise ValueError(f"{where}: sits on a room face at {'xyz'[ax]} = {lo[ax]:g} and faces into it")
            if abs(p[ax] - hi[ax]) <= tol and n[ax] >= 0:
                raise ValueError(f"{where}: sits on a room face at {'xyz'[ax]} = {hi[ax]:g} and faces into it")
    for j, box in enumerate(scene.furniture):
        inside = all(a < c < b for a, b, c in zip(box.min, box.max, p))
        if inside:
            raise ValueError(f"{where}: position {p} is inside furniture[{j}]" + (f" ({box.name})" if box.name else ""))
