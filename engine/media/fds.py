"""Frames from FDS (NIST Fire Dynamics Simulator) output, read with `fdsreader` (issue 26; docs/fds-input.md).

The mapping, step by step (printed in the result as `FramesReportPublic`):

1. Data. `quantity` "extinction": FDS's SOOT EXTINCTION COEFFICIENT K [1/m] (FDS's K_m times rho_soot)
   from a 3D slice; "soot_density": SOOT DENSITY rho_soot [kg/m^3] from a 3D slice or from SMOKE3D
   (fdsreader's `to_physical` decodes Smokeview's 8-bit codes), then K = K_m rho_soot with
   K_m = `mass_extinction_m2_per_kg` (FDS's default 8700 m^2/kg at 632.8 nm; Mulholland & Croarkin 2000).
2. Cells. A cell-centred slice holds FDS's cell values (used as they are). Node-based data (node slices,
   SMOKE3D) become cells by the mean of the cell's 8 corner nodes that lie outside obstructions (fdsreader's
   obstruction mask): node values inside obstructions are not gas values (soot density reads the gas
   density there). Cells inside obstructions get sigma = 0 (FDS itself writes extinction 0 there).
3. Meshes. All meshes of the slice are joined onto one grid (fdsreader's `to_global`); they must have
   the same uniform cell size and fill a box, else a SceneError says which mesh differs.
4. Wavelength. sigma_t = K (632.8 nm / lambda)^x, x = `wavelength_exponent`. Default 1: black carbon's
   absorption Angstrom exponent (Bond & Bergstrom 2006, Aerosol Sci. Technol. 40:27-67; the small-particle
   limit with a refractive index independent of wavelength), soot's extinction being mostly absorption;
   measured values for other soots and bands: docs/fds-input.md. Exactly 1 at 632.8 nm.
5. Albedo and phase: given, or Mie (frames.scattering_optics); sigma_s = albedo sigma_t, sigma_a = the rest.
6. Room. room = FDS coordinates + `origin` [m]; the grid box is the joined meshes' box moved by `origin`.

fdsreader writes a cache pickle next to the .smv by default; caching is switched off while reading, so
the case's folder is only read.
"""

from __future__ import annotations

import base64
import binascii
import io
import tempfile
import zipfile
from pathlib import Path

import numpy as np

from owcsim.engine.core.errors import SceneError
from owcsim.engine.core.lazy import LazyModule
from owcsim.engine.media.frames import MediumFrames, scattering_optics, select_frame_indices, split_extinction
from owcsim.schemas.frames import REFERENCE_WAVELENGTH_NM, FdsFramesSpec, FramesReportPublic
from owcsim.schemas.medium import MAX_COEFFICIENT, MAX_GRID_CELLS

fdsreader = LazyModule("fdsreader")

#: Relative tolerance on cell sizes (FDS writes node coordinates with 6-7 significant digits).
CELL_SIZE_RTOL = 1e-4
#: Most files and bytes an FDS case sent as a zip archive (`data_base64`) may unpack to.
MAX_ARCHIVE_MEMBERS = 10_000
MAX_ARCHIVE_BYTES = 512 * 2**20  # a legitimate case of 60 frames of 72,000 cells and a few quantities: ~100 MB
#: The FDS quantity names of the two inputs.
FDS_QUANTITIES = {"extinction": "SOOT EXTINCTION COEFFICIENT", "soot_density": "SOOT DENSITY"}


def open_simulation(path: str | Path):
    """fdsreader's Simulation of the case at `path` (its folder or .smv file), without writing a cache file."""
    try:
        settings = fdsreader.settings
    except ModuleNotFoundError as err:
        raise SceneError("frames: reading FDS output needs fdsreader (pip install 'owcsim[fire]')") from err
    p = Path(path)
    if not p.exists():
        raise SceneError(f"frames: FDS case {str(p)!r} not found (give the folder holding the .smv, or the .smv)")
    if p.is_dir() and not any(p.glob("*.smv")):
        raise SceneError(f"frames: no .smv file in {str(p)!r}")
    before = settings.ENABLE_CACHING
    settings.ENABLE_CACHING = False
    try:
        return fdsreader.Simulation(str(p))
    except (ValueError, OSError, AssertionError, IndexError) as err:
        raise SceneError(f"frames: fdsreader could not read the FDS case {str(p)!r}: {err}") from err
    finally:
        settings.ENABLE_CACHING = before


def _is_3d(slc) -> bool:
    return slc.orientation == 0 and all(
        s.extent.x_start < s.extent.x_end and s.extent.y_start < s.extent.y_end and s.extent.z_start < s.extent.z_end
        for s in slc.subslices
    )


def pick_slice(sim, quantity: str, slice_id: str | None):
    """The slice with `slice_id`, or the 3D slice of the FDS quantity (cell-centred first)."""
    name = FDS_QUANTITIES[quantity]
    slices = list(sim.slices)
    if slice_id is not None:
        found = [s for s in slices if s.id == slice_id]
        if not found:
            ids = ", ".join(sorted(s.id for s in slices if s.id)) or "none"
            raise SceneError(f"frames: no FDS slice with ID {slice_id!r} (slices: {ids})")
        slc = found[0]
        if not slc.quantity.name.upper().startswith(name):
            raise SceneError(f"frames: slice {slice_id!r} holds {slc.quantity.name}, not {name} (`quantity`)")
    else:
        found = sorted(
            (s for s in slices if s.quantity.name.upper().startswith(name) and _is_3d(s)),
            key=lambda s: not s.cell_centered,
        )
        if not found:
            raise SceneError(f"frames: the FDS case has no 3D slice of {name} (add SLCF with XB of the room)")
        slc = found[0]
    if not _is_3d(slc):
        raise SceneError(f"frames: slice {slc.id!r} is a plane; a 3D slice (SLCF XB with volume) is needed")
    return slc


def check_cell_sizes(meshes) -> np.ndarray:
    """The common cell size (dx, dy, dz) [m] of `meshes`; a SceneError for stretched or unequal meshes."""
    sizes: list[tuple[str, np.ndarray]] = []
    for mesh in meshes:
        d: list[float] = []
        for axis in "xyz":
            steps = np.diff(np.asarray(mesh.coordinates[axis], np.float64))
            if len(steps) == 0 or np.ptp(steps) > CELL_SIZE_RTOL * steps.mean():
                raise SceneError(f"frames: FDS mesh {mesh.id!r} has unequal cells along {axis} (stretched grid)")
            d.append(float(steps.mean()))
        sizes.append((mesh.id, np.array(d)))
    ref_id, ref = sizes[0]
    for mesh_id, size in sizes[1:]:
        if np.any(np.abs(size - ref) > CELL_SIZE_RTOL * ref):
            raise SceneError(
                f"frames: FDS meshes of different cell sizes cannot be joined onto one grid: {ref_id!r} has "
                f"{ref.round(6).tolist()} m, {mesh_id!r} has {size.round(6).tolist()} m (use equal cells)"
            )
    return ref


def _box(subslices) -> tuple[np.ndarray, np.ndarray]:
    """Low and high corners [m] (FDS coordinates) of the nodes the subslices cover."""
    nodes = [s.get_coordinates(ignore_cell_centered=True) for s in subslices]
    lo = np.array([min(float(n[a][0]) for n in nodes) for a in "xyz"])
    hi = np.array([max(float(n[a][-1]) for n in nodes) for a in "xyz"])
    return lo, hi


def nodes_to_cells(nodes: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Cell values (F, nx, ny, nz) from node values (F, nx+1, ny+1, nz+1): the mean of each cell's 8 corners
    that are not NaN (masked, inside obstructions); 0 where all 8 are masked (also returned: that mask)."""
    total = np.zeros((nodes.shape[0], *(n - 1 for n in nodes.shape[1:])))
    count = np.zeros(total.shape)
    for dx in (0, 1):
        for dy in (0, 1):
            for dz in (0, 1):
                corner = nodes[:, dx : dx + total.shape[1], dy : dy + total.shape[2], dz : dz + total.shape[3]]
                ok = np.isfinite(corner)
                total += np.where(ok, corner, 0.0)
                count += ok
    return np.divide(total, count, out=np.zeros_like(total), where=count > 0), count == 0


def _global(obj, masked: bool, physical: bool) -> np.ndarray:
    if physical:
        values = obj.to_physical(masked=masked, fill=np.nan)
    else:
        values = obj.to_global(masked=masked, fill=np.nan)
    if isinstance(values, tuple):  # two grids: only for planes cut along a mesh border
        raise SceneError("frames: the FDS data gave two global grids (a plane on a mesh border); use a 3D slice")
    return np.asarray(values, np.float64)


def read_fds_cells(sim, spec: FdsFramesSpec) -> dict:
    """The chosen FDS data as cells: values (F, nx, ny, nz) in the file's unit, times, FDS box, description."""
    if spec.source == "smoke3d":
        try:
            obj = sim.smoke_3d.get_by_quantity("SOOT DENSITY")
        except (KeyError, IndexError, StopIteration) as err:
            raise SceneError("frames: the FDS case has no SMOKE3D of SOOT DENSITY") from err
        if obj is None:
            raise SceneError("frames: the FDS case has no SMOKE3D of SOOT DENSITY")
        subs, physical, cell_centered = obj.subsmokes, True, False
        label, quantity = "SMOKE3D", "SOOT DENSITY [kg/m3] (SMOKE3D, 8-bit codes decoded)"
        times = np.asarray(obj.times, np.float64)
    else:
        obj = pick_slice(sim, spec.quantity, spec.slice_id)
        subs, physical, cell_centered = obj.subslices, False, bool(obj.cell_centered)
        label, quantity = obj.id, f"{obj.quantity.name} [{obj.quantity.unit}]"
        times = np.asarray(obj.times, np.float64)
    meshes = [s.mesh for s in subs]
    cell = check_cell_sizes(meshes)
    lo, hi = _box(subs) if spec.source == "slice" else _mesh_box(meshes)
    covered = _global(obj, masked=False, physical=physical)
    if np.isnan(covered).any():
        raise SceneError(f"frames: the FDS meshes of {label!r} do not fill a box (gaps between meshes)")
    values = _global(obj, masked=True, physical=physical)
    if cell_centered:
        masked = int(np.isnan(values[0]).sum())
        cells, how = np.nan_to_num(values, nan=0.0), "cell-centred slice: FDS's cell values"
    else:
        cells, blocked = nodes_to_cells(values)
        masked = int(blocked[0].sum())
        how = "node-based: mean of each cell's 8 corner nodes outside obstructions"
    shape = np.rint((hi - lo) / cell).astype(int)
    if tuple(shape) != cells.shape[1:]:
        raise SceneError(f"frames: FDS grid {cells.shape[1:]} does not match its box {lo}..{hi} m ({cell} m cells)")
    return dict(
        values=cells,
        times=times,
        lo=lo,
        hi=hi,
        label=label,
        quantity=quantity,
        how=how,
        masked=masked,
        meshes=len(meshes),
        file=str(sim.smv_file_path),
    )


def _mesh_box(meshes) -> tuple[np.ndarray, np.ndarray]:
    lo = np.array([min(float(m.coordinates[a][0]) for m in meshes) for a in "xyz"])
    hi = np.array([max(float(m.coordinates[a][-1]) for m in meshes) for a in "xyz"])
    return lo, hi


def wavelength_factor(spec: FdsFramesSpec) -> float:
    """(632.8 nm / lambda)^x: the extinction at `wavelength_nm` relative to 632.8 nm (exactly 1 there)."""
    if spec.wavelength_nm == REFERENCE_WAVELENGTH_NM:
        return 1.0
    return float((REFERENCE_WAVELENGTH_NM / spec.wavelength_nm) ** spec.wavelength_exponent)


def unpack_case(data_base64: str, folder: Path) -> Path:
    """Unpack a base64 zip archive of an FDS case into `folder`; the path of its one .smv file."""
    try:
        archive = zipfile.ZipFile(io.BytesIO(base64.b64decode(data_base64, validate=True)))
    except (binascii.Error, zipfile.BadZipFile) as err:
        raise SceneError(f"frames: `data_base64` is not a base64 zip archive of an FDS case ({err})") from err
    with archive:
        members = archive.infolist()
        size = sum(m.file_size for m in members)
        if len(members) > MAX_ARCHIVE_MEMBERS or size > MAX_ARCHIVE_BYTES:
            raise SceneError(
                f"frames: the FDS archive unpacks to {len(members)} files, {size} bytes; at most "
                f"{MAX_ARCHIVE_MEMBERS} files and {MAX_ARCHIVE_BYTES} bytes"
            )
        archive.extractall(folder)  # zipfile drops absolute paths and '..' from member names
    smv = sorted(folder.rglob("*.smv"))
    if len(smv) != 1:
        raise SceneError(f"frames: the FDS archive must hold exactly one .smv file, it holds {len(smv)}")
    return smv[0]


def fds_frames(spec: FdsFramesSpec, base_dir: str | Path | None = None) -> MediumFrames:
    """The frames of an FDS case (see the module's docstring for the mapping): at `path`, or unpacked from
    `data_base64` into a temporary folder (deleted once the frames are read)."""
    if spec.data_base64 is not None:
        with tempfile.TemporaryDirectory(prefix="owcsim-fds-") as tmp:
            smv = unpack_case(spec.data_base64, Path(tmp))
            data = read_fds_cells(open_simulation(smv), spec)
            data["file"] = f"data_base64:{smv.relative_to(tmp)}"
    else:
        assert spec.path is not None  # the schema asks for one of the two
        path = Path(spec.path)
        if not path.is_absolute() and base_dir is not None:
            path = Path(base_dir) / path
        data = read_fds_cells(open_simulation(path), spec)
    idx = select_frame_indices(data["times"], spec.times_s, spec.t_min, spec.t_max, spec.every)
    values = np.maximum(data["values"][idx], 0.0)  # FDS may write round-off negatives (-1e-20)
    factor = wavelength_factor(spec)
    km = spec.mass_extinction_m2_per_kg if spec.quantity == "soot_density" else None
    sigma_t = values * (km if km is not None else 1.0)
    if factor != 1.0:
        sigma_t = sigma_t * factor
    if int(np.prod(sigma_t.shape[1:])) > MAX_GRID_CELLS:
        raise SceneError(f"frames: {sigma_t.shape[1:]} cells exceed the limit of {MAX_GRID_CELLS}")
    if sigma_t.max(initial=0.0) > MAX_COEFFICIENT:
        raise SceneError(f"frames: FDS extinction reaches {sigma_t.max():.4g} 1/m, above {MAX_COEFFICIENT:g} 1/m")
    albedo, phase, albedo_from = scattering_optics(spec.albedo, spec.phase, spec.particles)
    sigma_a, sigma_s = split_extinction(sigma_t, albedo)
    origin = np.asarray(spec.origin, np.float64)
    lo, hi = data["lo"] + origin, data["hi"] + origin
    times = data["times"][idx]
    report = FramesReportPublic(
        kind="fds",
        file=data["file"],
        quantity=data["quantity"],
        data_id=data["label"],
        cell_values=data["how"],
        mass_extinction_m2_per_kg=km,
        wavelength_nm=spec.wavelength_nm,
        wavelength_factor=factor,
        albedo=albedo,
        albedo_from=albedo_from,
        phase=str(getattr(phase, "type", "")),
        origin=tuple(float(v) for v in origin),
        grid_min=tuple(float(v) for v in lo),
        grid_max=tuple(float(v) for v in hi),
        grid_shape=tuple(int(n) for n in sigma_t.shape[1:]),
        meshes=data["meshes"],
        masked_cells=data["masked"],
        times_s=[float(t) for t in times],
        max_sigma_t=float(sigma_t.max(initial=0.0)),
    )
    return MediumFrames(times, lo, hi, sigma_a, sigma_s, phase, report.text(), report)
