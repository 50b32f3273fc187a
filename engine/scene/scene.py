"""The engine's view of a scene: geometry on Embree, devices, medium. Built once per process."""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from owcsim.engine.core.errors import SceneError
from owcsim.engine.media.frame_ratios import FrameRatios
from owcsim.engine.media.media import HomogeneousMedium, region_from_spec
from owcsim.engine.media.medium import Medium
from owcsim.engine.media.model import MediumKind, MediumModel, medium_model
from owcsim.engine.media.phase import PhaseFunction
from owcsim.engine.media.registry import medium_from_spec
from owcsim.engine.scene.geometry import Geometry, Intersector, build_geometry, check_extent
from owcsim.engine.scene.orientation import with_hidden_receivers
from owcsim.engine.sources.devices import Devices, concentrator_gain, transmitters_from_specs
from owcsim.engine.spectral.spectra import SceneSpectra, carrier_bands, medium_bands, scene_tables, unsupported
from owcsim.engine.surfaces.bsdf import MirrorPlane, mirror_planes
from owcsim.schemas import SceneSpec
from owcsim.schemas.algorithms import ALGORITHMS
from owcsim.schemas.orientation import hidden_blocks


@dataclass
class Scene:
    spec: SceneSpec
    geometry: Geometry
    intersector: Intersector
    transmitters: Devices
    receivers: Devices
    medium: Medium | None

    #: True when every pair of points in the scene sees each other (an empty box room is
    #: convex), so shadow rays are skipped; benchmarks may turn it off to cast them anyway.
    all_visible: bool = False
    #: phase function of the medium (None without a medium)
    phase: PhaseFunction | None = None
    #: length given to segments that leave the scene: the medium beyond it absorbs everything [m]
    medium_far_distance: float = float("inf")
    #: per receiver: why it is not simulated ("" = simulated): grid points in furniture or outside the room
    masked: np.ndarray = field(default_factory=lambda: np.zeros(0, object))
    #: receiver index range of each grid: (first, shape (nu, nv)) in `spec.receiver_grids` order
    grid_slices: list[tuple[int, tuple[int, int]]] = field(default_factory=list)
    #: planar groups of perfect-mirror faces (bsdf.MirrorPlane): devices are reached through their images
    mirror_planes: list[MirrorPlane] = field(default_factory=list)
    #: per-band tables of a spectral scene (engine/spectral/spectra.py), None when grey
    spectra: SceneSpectra | None = None
    #: the document's medium as decided once when built: scatters, max_albedo, report (engine/media/model.py)
    medium_model: MediumModel | None = None
    #: per-frame ratio rows of a time-varying medium reweighted from one carrier (engine/media/frame_ratios.py)
    path_ratios: FrameRatios | None = None

    @property
    def n_links(self) -> int:
        return len(self.transmitters) * len(self.receivers)

    def link(self, tx, rx):
        """Flat link index of (transmitter, receiver): tx * n_rx + rx."""
        return tx * len(self.receivers) + rx

    @property
    def scatters(self) -> bool:
        """The medium scatters somewhere (sigma_s > 0), as decided when it was built (engine/media/model.py)."""
        return self.medium_model is not None and self.medium_model.scatters

    @property
    def max_albedo(self) -> float:
        """albedo_max: the medium's largest single-scattering albedo sigma_s / sigma_t [-] (a medium is needed)."""
        assert self.medium_model is not None
        return self.medium_model.max_albedo

    @property
    def max_reflectance(self) -> float:
        """rho_max: the largest reflectance of the scene's surfaces [-] (0 without surfaces)."""
        rho = self.geometry.reflectance
        return float(rho.max()) if len(rho) else 0.0


def build_scene(spec: SceneSpec, base_dir: str | Path | None = None) -> Scene:
    """Everything the kernel needs, from a validated scene document.

    `base_dir` resolves relative mesh file paths (the scene file's folder).
    """
    geometry = build_geometry(spec, Path(base_dir) if base_dir is not None else None)
    transmitters = transmitters_from_specs(
        spec.transmitters, spec.transmitter_ids(), Path(base_dir) if base_dir is not None else None
    )
    receivers, grid_slices = receivers_from_scene(spec)
    if len(geometry.faces):  # rays are cast in float32 around the surfaces' centre: devices count too
        check_extent(
            np.concatenate([geometry.vertices, transmitters.positions, receivers.positions]), "the surfaces and devices"
        )
    medium = medium_from_spec(spec.medium)
    intersector = Intersector(geometry)
    planes = _mirror_planes(geometry, intersector)
    scene = Scene(
        spec=spec,
        geometry=geometry,
        intersector=intersector,
        transmitters=transmitters,
        receivers=receivers,
        medium=medium,
        all_visible=spec.room is not None and not spec.furniture and not spec.meshes,
        phase=medium.phase if medium is not None else None,
        medium_far_distance=_far_distance(spec, geometry, medium, receivers.positions),
        masked=mask_reasons(spec, receivers, len(spec.receivers)),
        grid_slices=grid_slices,
        mirror_planes=planes,
        medium_model=medium_model(spec.medium, medium),
    )
    if spec.spectral is not None:  # per-band tables; the scene becomes the carrier band's (engine/spectral/spectra.py)
        scene = spectral_scene(scene)
    return scene


def spectral_scene(scene: Scene) -> Scene:
    """The scene with its per-band tables (`spectra`), made the carrier: the largest reflectance (the geometry's,
    geometry.build_geometry via spectra.grey_surfaces) and the least attenuated band's medium (docs/spectra.md)."""
    spec = scene.spec
    assert spec.spectral is not None
    geo = scene.geometry
    tables = scene_tables(spec, geo.reflectance, getattr(geo, "surfaces", None), len(scene.receivers))
    carrier: dict = {}
    bands = medium_bands(spec, spec.spectral)
    if bands is not None:
        sigma_a, sigma_s, phases = bands
        c = carrier_bands(tables, sigma_a, sigma_s, phases)
        if c is None:  # no band attenuates
            carrier = {"medium": None, "phase": None, "medium_far_distance": float("inf")}
        else:
            assert spec.medium is not None and spec.medium.type != "grid"  # (per-band grids: refused by the schema)
            box, region = region_from_spec(spec.medium.region)
            medium = HomogeneousMedium(float(sigma_a[c]), float(sigma_s[c]), box, region=region, phase_spec=phases[c])
            far = _far_distance(spec, geo, medium, scene.receivers.positions)
            carrier = {"medium": medium, "phase": medium.phase, "medium_far_distance": far}
    if scene.medium_model is not None and scene.medium_model.kind is MediumKind.PARTICLES:
        assert spec.medium is not None and spec.medium.type == "particles"
        tables.warnings.append(
            f"medium.particles.wavelength ({spec.medium.particles.wavelength:.4g} m) is not used: a "
            "spectral scene computes the Mie optics at each band centre (spectral.medium_bands)"
        )
    out = replace(scene, spectra=tables, **carrier)
    algorithm = spec.simulation.algorithm
    check_spectral(out, algorithm != "auto" and ALGORITHMS[algorithm].counts_scattering)
    return out


def check_spectral(scene: Scene, samples_scattering: bool) -> None:
    """SceneError where a spectral scene's per-band ratios would be needed by a part of the kernel that does not
    carry them (spectra.unsupported). Checked when the scene is built (for the document's algorithm: does it
    sample scattering points, `counts_scattering` in schemas/algorithms.py) and again when a job starts its
    tallies (for the kernel settings the automatic settings chose, on a scene built before)."""
    if scene.spectra is None:
        return
    why = unsupported(scene.spectra, bool(scene.mirror_planes), scene.medium is not None, samples_scattering)
    if why is not None:
        raise SceneError(why)


def _unit_rows(v: np.ndarray) -> np.ndarray:
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


def grid_points(grid) -> tuple[np.ndarray, tuple[int, int]]:
    """Positions (nu * nv, 3) [m] of a ReceiverGridSpec's points, row-major in (i along u, j along v):
    origin + i s_u u + j s_v v (one step: origin + s (i u + j v), the square grid's bits)."""
    nu, nv = grid.shape
    su, sv = grid.steps
    u, v = _unit_rows(np.asarray(grid.u, float)), _unit_rows(np.asarray(grid.v, float))
    i, j = np.meshgrid(np.arange(nu), np.arange(nv), indexing="ij")
    if su == sv:
        pos = np.asarray(grid.origin, float) + su * (i.reshape(-1, 1) * u + j.reshape(-1, 1) * v)
    else:
        pos = np.asarray(grid.origin, float) + (su * i.reshape(-1, 1)) * u + (sv * j.reshape(-1, 1)) * v
    return pos, (nu, nv)


def _in_area(ab: np.ndarray, outline: np.ndarray, tol: float = 1e-9) -> np.ndarray:
    """Per plane point (n, 2) [m]: inside the closed polygon `outline` (k, 2), or within `tol` of its edge.

    Crossing number (even-odd rule, Shimrat 1962), a loop over the k edges vectorized over the points.
    """
    a, b = ab[:, 0], ab[:, 1]
    inside = np.zeros(len(ab), bool)
    on_edge = np.zeros(len(ab), bool)
    for (a1, b1), (a2, b2) in zip(outline, np.roll(outline, -1, axis=0)):
        spans = (b1 > b) != (b2 > b)
        with np.errstate(divide="ignore", invalid="ignore"):
            cross = a1 + (b - b1) * (a2 - a1) / (b2 - b1)
        inside ^= spans & (a < cross)
        d = np.array([a2 - a1, b2 - b1])
        t = np.clip(((a - a1) * d[0] + (b - b1) * d[1]) / max(float(d @ d), 1e-300), 0.0, 1.0)
        on_edge |= np.hypot(a - a1 - t * d[0], b - b1 - t * d[1]) <= tol
    return inside | on_edge


def grid_area_reasons(grid) -> np.ndarray:
    """Per point of a grid (row-major): "" or why its `exclude` / `include` areas mask it."""
    nu, nv = grid.shape
    su, sv = grid.steps
    i, j = np.meshgrid(np.arange(nu), np.arange(nv), indexing="ij")
    ab = np.stack([su * i.ravel(), sv * j.ravel()], axis=1)
    reason = np.full(nu * nv, "", dtype=object)
    if grid.include:
        kept = np.any([_in_area(ab, np.asarray(area.vertices(), float)) for area in grid.include], axis=0)
        reason[~kept] = "outside the grid's include areas"
    for k, area in enumerate(grid.exclude):
        reason[_in_area(ab, np.asarray(area.vertices(), float))] = f"in the grid's exclude[{k}]"
    return reason


def receivers_from_scene(spec: SceneSpec) -> tuple[Devices, list]:
    """Explicit receivers then every grid, as arrays (grids are expanded without building per-point models), then
    the hidden receivers of orientation requests and angle-diversity receivers (engine/scene/orientation.py).

    Returns the Devices and, per grid, (first receiver index, (nu, nv)).
    """
    rows, slices, ids = [], [], list(spec.receiver_ids()[: len(spec.receivers)])
    for r in spec.receivers:
        rows.append((np.asarray([r.position]), r.normal, r.area, r.fov_deg, r.filter_gain, r.concentrator_index))
    first = len(spec.receivers)
    for g in spec.receiver_grids:
        pos, (nu, nv) = grid_points(g)
        rows.append((pos, g.receiver_normal, g.area, g.fov_deg, g.filter_gain, g.concentrator_index))
        slices.append((first, (nu, nv)))
        ids += [f"{g.id_prefix}[{i},{j}]" for i in range(nu) for j in range(nv)]
        first += nu * nv
    counts = [len(r[0]) for r in rows]
    n = sum(counts)

    def per_point(values) -> np.ndarray:
        return np.repeat(np.asarray(values, float), counts, axis=0).reshape(n, *np.shape(values)[1:])

    fov = np.radians(per_point([r[3] for r in rows]))
    gain = per_point([r[2] * r[4] * concentrator_gain(np.radians(r[3]), r[5]) for r in rows])
    # cos(90 deg) is 6e-17 in floating point, not 0: clamp so FOV = 90 deg is the full hemisphere.
    cos_fov = np.where(np.isclose(fov, np.pi / 2, rtol=0, atol=1e-12), 0.0, np.cos(fov))
    positions = np.concatenate([r[0] for r in rows]).reshape(n, 3) if rows else np.zeros((0, 3))
    normals = _unit_rows(per_point([r[1] for r in rows]).reshape(n, 3)) if rows else np.zeros((0, 3))
    devices = Devices(
        kind="receiver",
        ids=ids,
        positions=positions,
        normals=normals,
        order=np.zeros(n),
        cos_fov=cos_fov,
        gain=gain,
        power=np.ones(n),
        area=per_point([r[2] for r in rows]),
        patterns=[None] * n,
    )
    return with_hidden_receivers(spec, devices), slices  # orientation samples, photodiodes (scene/orientation.py)


def mask_reasons(spec: SceneSpec, receivers: Devices, n_explicit: int) -> np.ndarray:
    """Per receiver, why a grid point is not simulated ("" when it is), vectorized over points.

    Outside the room, strictly inside a furniture box, or on a room face with its normal pointing
    into the face (the rule `schemas.scene.placement_problem` applies to explicit devices, which
    are refused instead); then, for the points those leave, the grid's `exclude` / `include` areas.
    """
    p, nrm = receivers.positions, receivers.normals
    reason = np.full(len(p), "", dtype=object)
    if spec.room is not None:
        lo, hi = np.asarray(spec.room.lo), np.asarray(spec.room.hi)
        tol = 1e-9 * max(1.0, float(np.abs(lo).max()), float(np.abs(hi).max()))
        outside = np.any((p < lo - tol) | (p > hi + tol), axis=1)
        into = np.any(((np.abs(p - lo) <= tol) & (nrm < 0)) | ((np.abs(p - hi) <= tol) & (nrm > 0)), axis=1)
        reason[into] = "on a room face, facing into it"
        reason[outside] = "outside the room"
    for j, box in enumerate(spec.furniture):  # a loop over boxes, each test vectorized over points
        inside = np.all((p > np.asarray(box.min)) & (p < np.asarray(box.max)), axis=1) & (reason == "")
        reason[inside] = f"inside furniture[{j}]" + (f" ({box.name})" if box.name else "")
    reason[:n_explicit] = ""  # explicit receivers were checked (and refused) by the schema
    first = n_explicit
    area = np.full(len(p), "", dtype=object)  # the grids' own masks: exclude / include areas of their planes
    for grid in spec.receiver_grids:
        own = grid_area_reasons(grid)
        area[first : first + len(own)] = own
        first += len(own)
    for block in hidden_blocks(spec):  # a point's orientation samples share its area mask (point-major)
        if block.kind == "orientation":
            area[block.first : block.first + block.count] = np.repeat(
                area[block.points.start : block.points.stop], block.per_point
            )
    take = (area != "") & (reason == "")
    reason[take] = area[take]
    return reason


#: most distinct mirror planes a scene may have (each costs one image connection per vertex and target)
MAX_MIRROR_PLANES = 32


def _mirror_planes(geometry: Geometry, intersector: Intersector) -> list:
    """The planes of the perfect-mirror faces; SceneError where the image method does not apply."""
    if geometry.material is None or not geometry.material.rho_m.any():
        return []
    planes = mirror_planes(geometry.vertices, geometry.faces, geometry.material.rho_m, tol=intersector.offset)
    if len(planes) > MAX_MIRROR_PLANES:
        raise SceneError(
            f"the mirror surfaces lie in {len(planes)} distinct planes, more than {MAX_MIRROR_PLANES}: "
            "perfect mirrors must be flat (use a Phong material for curved glossy surfaces)"
        )
    return planes


def _far_distance(spec: SceneSpec, geometry: Geometry, medium, rx_positions: np.ndarray) -> float:
    """A segment length past which a ray that left the scene meets no more medium [m].

    Bounded region: the diagonal of the box holding surfaces, devices and region.
    Whole-scene medium: where its optical depth reaches 50 (transmittance 2e-22).
    """
    if medium is None:
        return float("inf")
    pts = [geometry.vertices] if len(geometry.vertices) else []
    pts += [np.array([d.position for d in spec.transmitters]), rx_positions]
    bounds = getattr(medium, "bounds", None)
    if bounds is not None:
        pts.append(np.asarray(bounds, float).reshape(-1, 3))
    allp = np.concatenate(pts)
    diag = float(np.linalg.norm(allp.max(axis=0) - allp.min(axis=0))) + 1.0
    if bounds is not None:
        return diag
    return diag + 50.0 / max(getattr(medium, "sigma_t_min", medium.sigma_t), 1e-12)
