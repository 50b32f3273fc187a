"""The engine's view of a scene: geometry on Embree, devices, medium. Built once per process."""
from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from owcsim.schemas import SceneSpec

from .bsdf import mirror_planes
from .devices import Devices, receivers_from_specs, transmitters_from_specs
from .errors import SceneError
from .geometry import Geometry, Intersector, build_geometry, check_extent
from .media import HomogeneousMedium, medium_from_spec
from .phase import phase_from_spec


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
    #: phase function of the medium (None without a medium)
    phase: object = None
    #: length given to segments that leave the scene: the medium beyond it absorbs everything [m]
    medium_far_distance: float = float("inf")
    #: planar groups of perfect-mirror faces (bsdf.MirrorPlane): devices are reached through their images
    mirror_planes: list = field(default_factory=list)

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
    transmitters = transmitters_from_specs(spec.transmitters, spec.transmitter_ids(),
                                           Path(base_dir) if base_dir is not None else None)
    receivers = receivers_from_specs(spec.all_receivers(), spec.receiver_ids())
    if len(geometry.faces):  # rays are cast in float32 around the surfaces' centre: devices count too
        check_extent(np.concatenate([geometry.vertices, transmitters.positions, receivers.positions]),
                     "the surfaces and devices")
    medium = medium_from_spec(spec.medium)
    intersector = Intersector(geometry)
    planes = _mirror_planes(geometry, intersector, medium)
    return Scene(
        spec=spec,
        geometry=geometry,
        intersector=intersector,
        transmitters=transmitters,
        receivers=receivers,
        medium=medium,
        all_visible=spec.room is not None and not spec.furniture and not spec.meshes,
        phase=phase_from_spec(spec.medium.phase) if medium is not None else None,
        medium_far_distance=_far_distance(spec, geometry, medium),
        mirror_planes=planes,
    )


#: most distinct mirror planes a scene may have (each costs one image connection per vertex and target)
MAX_MIRROR_PLANES = 32


def _mirror_planes(geometry: Geometry, intersector: Intersector, medium) -> list:
    """The planes of the perfect-mirror faces; SceneError where the image method does not apply."""
    if geometry.material is None or not geometry.material.rho_m.any():
        return []
    if medium is not None:
        raise SceneError("perfect-mirror surfaces cannot be combined with a medium yet: use a Phong material "
                         "with a large exponent for the specular part")
    planes = mirror_planes(geometry.vertices, geometry.faces, geometry.material.rho_m, tol=intersector.offset)
    if len(planes) > MAX_MIRROR_PLANES:
        raise SceneError(f"the mirror surfaces lie in {len(planes)} distinct planes, more than {MAX_MIRROR_PLANES}: "
                         "perfect mirrors must be flat (use a Phong material for curved glossy surfaces)")
    return planes


def _far_distance(spec: SceneSpec, geometry: Geometry, medium) -> float:
    """A segment length past which a ray that left the scene meets no more medium [m].

    Bounded region: the diagonal of the box holding surfaces, devices and region.
    Whole-scene medium: where its optical depth reaches 50 (transmittance 2e-22).
    """
    if medium is None:
        return float("inf")
    pts = [geometry.vertices] if len(geometry.vertices) else []
    pts += [np.array([d.position for d in spec.transmitters]), np.array([r.position for r in spec.all_receivers()])]
    bounds = getattr(medium, "bounds", None)
    if bounds is not None:
        pts.append(np.asarray(bounds, float).reshape(-1, 3))
    allp = np.concatenate(pts)
    diag = float(np.linalg.norm(allp.max(axis=0) - allp.min(axis=0))) + 1.0
    if bounds is not None:
        return diag
    return diag + 50.0 / max(getattr(medium, "sigma_t_min", medium.sigma_t), 1e-12)
