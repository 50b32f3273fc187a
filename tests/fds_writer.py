"""Write small FDS output cases in FDS's file formats, for tests (FDS itself does not install here; issue 26).

The files follow what FDS 6.9 writes (compare /work/shared/data/fds/office_fire, and fdsreader's parser,
fdsreader/simulation.py and fdsreader/slcf/slice.py):

- the .smv text file: CHID, a SURFACE entry (indexed by the obstructions), TOFFSET, and per mesh OFFSET, GRID
  (cells per axis), PDIM (the mesh box), TRNX / TRNY / TRNZ (node index and coordinate), OBST (box, id,
  surfaces, then node bounds, colour, block type), VENT (none) and CVENT (none); then one SLCF (node-based)
  or SLCC (cell-centred) entry per slice and mesh: `SLCC <mesh> # STRUCTURED %<ID> & i1 i2 j1 j2 k1 k2 !
  <slice number> <cell-centred flag>` followed by the .sf file name, quantity, short name and unit;
- the .sf slice file, Fortran unformatted sequential records (int32 byte count, payload, int32 byte
  count), little-endian: three 30-character records (quantity, short name, unit), one record of the six
  node bounds, then per frame a record with the time (float32) and a record with the values (float32) in
  Fortran (x fastest) order. A node slice holds (i2-i1+1)(j2-j1+1)(k2-k1+1) node values; a cell-centred
  slice holds as many values, the cells of the range plus one ghost layer at the low end of each axis (index
  0, skipped by readers): the ghost values are written as -999 here, so that reading them would show.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np


@dataclass
class FdsMesh:
    """A mesh: box lo..hi [m] (FDS coordinates) cut into shape = (nx, ny, nz) equal cells."""

    lo: tuple[float, float, float]
    hi: tuple[float, float, float]
    shape: tuple[int, int, int]

    def nodes(self, axis: int) -> np.ndarray:
        return np.linspace(self.lo[axis], self.hi[axis], self.shape[axis] + 1)


@dataclass
class FdsSlice:
    """A 3D slice over whole meshes: `data[m]` is mesh m's values, (F, nx, ny, nz) cells if `cell_centered`,
    else (F, nx+1, ny+1, nz+1) nodes, in FDS's unit of `quantity`."""

    slice_id: str
    quantity: str
    short_name: str
    unit: str
    cell_centered: bool
    data: list[np.ndarray]


@dataclass
class FdsObstruction:
    """An obstruction in mesh `mesh` (0-based) covering the cells i1..i2-1, j1..j2-1, k1..k2-1 (node bounds)."""

    mesh: int
    bounds: tuple[int, int, int, int, int, int]
    name: str = "Box"


@dataclass
class FdsCase:
    chid: str
    meshes: list[FdsMesh]
    times: np.ndarray
    slices: list[FdsSlice] = field(default_factory=list)
    obstructions: list[FdsObstruction] = field(default_factory=list)


def _record(payload: bytes) -> bytes:
    n = np.array([len(payload)], "<i4").tobytes()
    return n + payload + n


def _text30(s: str) -> bytes:
    return s.ljust(30)[:30].encode("ascii")


def write_sf(path: Path, sl: FdsSlice, mesh: FdsMesh, data: np.ndarray, times: np.ndarray) -> None:
    """One .sf file: the slice `sl` over the whole of `mesh`, frames `data` at `times` [s]."""
    nx, ny, nz = mesh.shape
    bounds = np.array([0, nx, 0, ny, 0, nz], "<i4")
    out = [_record(_text30(sl.quantity)), _record(_text30(sl.short_name)), _record(_text30(sl.unit))]
    out.append(_record(bounds.tobytes()))
    for t, values in zip(times, data):
        if sl.cell_centered:
            assert values.shape == (nx, ny, nz), values.shape
            full = np.full((nx + 1, ny + 1, nz + 1), -999.0)
            full[1:, 1:, 1:] = values
        else:
            assert values.shape == (nx + 1, ny + 1, nz + 1), values.shape
            full = values
        out.append(_record(np.array([t], "<f4").tobytes()))
        out.append(_record(np.asarray(full, "<f4").ravel(order="F").tobytes()))
    path.write_bytes(b"".join(out))


def _mesh_block(case: FdsCase, m: int, mesh: FdsMesh) -> list[str]:
    lines = ["OFFSET", "      0.00000      0.00000      0.00000", ""]
    lines += [f"GRID   MESH_{m + 1:07d}", "   {}   {}   {}    0".format(*mesh.shape), "", "PDIM"]
    lo, hi = mesh.lo, mesh.hi
    lines += ["  " + "  ".join(f"{v:12.5f}" for v in (lo[0], hi[0], lo[1], hi[1], lo[2], hi[2], 0, 0, 0)), ""]
    for axis, name in enumerate(("TRNX", "TRNY", "TRNZ")):
        lines += [name, "    0"] + [f"{i:5d}  {x:12.5f}" for i, x in enumerate(mesh.nodes(axis))] + [""]
    obst = [o for o in case.obstructions if o.mesh == m]
    lines += ["OBST", f"{len(obst):12d}"]
    for n, o in enumerate(obst, 1):
        i1, i2, j1, j2, k1, k2 = o.bounds
        xb = (mesh.nodes(0)[i1], mesh.nodes(0)[i2], mesh.nodes(1)[j1], mesh.nodes(1)[j2])
        xb += (mesh.nodes(2)[k1], mesh.nodes(2)[k2])
        lines.append("  ".join(f"{v:12.5f}" for v in xb) + f"  {n:5d}   0   0   0   0   0   0  ! {o.name}")
    for o in obst:
        lines.append(" ".join(f"{b:4d}" for b in o.bounds) + "   -1   -1")
    lines += ["", "VENT", "    0    0", "", "CVENT", "    0", ""]
    return lines


def write_case(folder: str | Path, case: FdsCase) -> Path:
    """Write `case` into `folder` (created): CHID.smv and one .sf file per slice and mesh; returns the .smv."""
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    lines = ["TITLE", " owcsim test case", "", "FDSVERSION", "FDS-6.9.1-0-g889da6a-master", ""]
    lines += ["CHID", f" {case.chid}", "", "NMESHES", f"  {len(case.meshes)}", ""]
    lines += ["SURFACE", " INERT", " 5000.00    1.00", " 0  1.0 1.0 1.0 0.8 0.4 1.0", " null", ""]
    lines += ["TOFFSET", "      0.00000      0.00000      0.00000", ""]
    for m, mesh in enumerate(case.meshes):
        lines += _mesh_block(case, m, mesh)
    n_file = 0
    for number, sl in enumerate(case.slices, 1):
        for m, mesh in enumerate(case.meshes):
            n_file += 1
            name = f"{case.chid}_{m + 1}_{number}.sf"
            write_sf(folder / name, sl, mesh, sl.data[m], case.times)
            kind = "SLCC" if sl.cell_centered else "SLCF"
            nx, ny, nz = mesh.shape
            lines.append(
                f"{kind}     {m + 1} # STRUCTURED %{sl.slice_id} &     0 {nx:5d}     0 {ny:5d}     0 {nz:5d} "
                f"!  {number:5d}  {int(sl.cell_centered):5d}"
            )
            lines += [f" {name}", f" {sl.quantity}", f" {sl.short_name}", f" {sl.unit}"]
    smv = folder / f"{case.chid}.smv"
    smv.write_text("\n".join(lines) + "\n")
    return smv


def read_back(folder: str | Path):
    """fdsreader's Simulation of a written case (no cache file)."""
    import fdsreader

    before = fdsreader.settings.ENABLE_CACHING
    fdsreader.settings.ENABLE_CACHING = False
    try:
        return fdsreader.Simulation(str(folder))
    finally:
        fdsreader.settings.ENABLE_CACHING = before
