"""The engine's view of a scene: geometry on Embree, devices, medium. Built once per process."""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from schemas import SceneSpec

from .devices import Devices, receivers_from_specs, transmitters_from_specs
from .geometry import Geometry, Intersector, build_geometry
from .media import HomogeneousMedium, medium_from_spec


@dataclass
class Scene:
    spec: SceneSpec
    geometry: Geometry
    intersector: Intersector
    transmitters: Devices
    receivers: Devices
    medium: HomogeneousMedium | None

    #: True when every pair of points in the scene sees each other (an empty box room is
    #: convex), so shadow rays are skipped; benchmarks may turn it off to cast them anyway.
    all_visible: bool = False

    @property
    def n_links(self) -> int:
        return len(self.transmitters) * len(self.receivers)

    def link(self, tx, rx):
        """Flat link index of (transmitter, receiver): tx * n_rx + rx."""
        return tx * len(self.receivers) + rx


def build_scene(spec: SceneSpec, base_dir: str | Path | None = None) -> Scene:
    """Everything the kernel needs, from a validated scene document.

    `base_dir` resolves relative mesh file paths (the scene file's folder).
    """
    geometry = build_geometry(spec, Path(base_dir) if base_dir is not None else None)
    return Scene(
        spec=spec,
        geometry=geometry,
        intersector=Intersector(geometry),
        transmitters=transmitters_from_specs(spec.transmitters, spec.transmitter_ids()),
        receivers=receivers_from_specs(spec.all_receivers(), spec.receiver_ids()),
        medium=medium_from_spec(spec.medium),
        all_visible=spec.room is not None and not spec.furniture and not spec.meshes,
    )
