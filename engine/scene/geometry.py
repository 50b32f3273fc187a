"""Scene geometry: triangles with per-face reflectance, and batched ray queries on Embree.

Surfaces are Lambertian (BRDF rho/pi) unless a face's material says otherwise
(bsdf.py: Phong lobe, mirror; `Geometry.material`). Vertices are re-centred on the scene's
bounding-box centre before the float32 Embree build, so a room 5 km from the origin
keeps millimetre precision; ray origins are re-centred the same way.
Note: embreex's `EmbreeScene.run` overwrites the `dists` array it is given, so
every call passes a fresh array.
"""

from __future__ import annotations

import io
import json
import struct
import warnings
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from embreex import rtcore_scene

from owcsim.engine.core.constants import DEGENERATE_AREA_FACTOR, MAX_SCENE_EXTENT, RAY_OFFSET_FACTOR
from owcsim.engine.core.errors import SceneError
from owcsim.engine.core.inputs import read_input
from owcsim.engine.core.lazy import trimesh  # imported on first use: it pulls in scipy (issue 10)
from owcsim.engine.spectral.spectra import grey_surfaces
from owcsim.engine.surfaces.bsdf import Materials
from owcsim.schemas import ROOM_FACES, SceneSpec
from owcsim.schemas.geometry import MAX_MESH_NODES, BoxSpec, MeshSpec, RoomSpec

# Unit-cube corners and the two triangles of each face, wound so normals point outward.
_CUBE = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0], [0, 0, 1], [1, 0, 1], [1, 1, 1], [0, 1, 1]], float)
_CUBE_FACES = {  # name -> two triangles, outward normal for a solid box
    "floor": [(0, 2, 1), (0, 3, 2)],
    "ceiling": [(4, 5, 6), (4, 6, 7)],
    "wall_x_min": [(0, 4, 7), (0, 7, 3)],
    "wall_x_max": [(1, 2, 6), (1, 6, 5)],
    "wall_y_min": [(0, 1, 5), (0, 5, 4)],
    "wall_y_max": [(3, 7, 6), (3, 6, 2)],
}


@dataclass
class Geometry:
    """Triangle soup: `vertices` (V,3) [m], `faces` (F,3), per-face `reflectance` and `group` name index.

    `reflectance` is each face's total reflectance rho = rho_d + rho_s + rho_m; `material`
    holds the split (bsdf.Materials, per face) when some face is not Lambertian, else None.
    """

    vertices: np.ndarray
    faces: np.ndarray
    reflectance: np.ndarray
    group: np.ndarray
    group_names: list[str]
    material: Materials | None = None
    #: per-face surface specs (numbers or materials) when some face is not a plain number, else None
    #: (spectral scenes read their per-band reflectances here: engine/spectral/spectra.py)
    surfaces: np.ndarray | None = None

    @property
    def normals(self) -> np.ndarray:
        v = self.vertices[self.faces]
        n = np.cross(v[:, 1] - v[:, 0], v[:, 2] - v[:, 0])
        return n / np.linalg.norm(n, axis=1, keepdims=True)


def _box_triangles(lo, hi, inward: bool) -> tuple[np.ndarray, np.ndarray, list[str]]:
    verts = np.asarray(lo) + _CUBE * (np.asarray(hi) - np.asarray(lo))
    faces, names = [], []
    for name in ROOM_FACES:
        for tri in _CUBE_FACES[name]:
            faces.append(tri[::-1] if inward else tri)
            names.append(name)
    return verts, np.asarray(faces), names


def _room(room: RoomSpec):
    verts, faces, names = _box_triangles(room.lo, room.hi, inward=True)
    rho = room.reflectance.by_face()
    return verts, faces, _surfaces([rho[n] for n in names]), [f"room.{n}" for n in names]


def _surfaces(values) -> np.ndarray:
    """Per-face reflectances as an array: float when all Lambertian numbers, else object (specs)."""
    if all(isinstance(v, (int, float)) for v in values):
        return np.array(values, float)
    out = np.empty(len(values), object)
    out[:] = list(values)
    return out


def _materials(rho: np.ndarray) -> tuple[np.ndarray, Materials | None]:
    """(total reflectance per face, Materials or None if every face is Lambertian) from _surfaces' arrays."""
    if rho.dtype != object:
        return rho, None
    mat = Materials.of_surfaces(list(rho))
    if mat.is_lambertian:
        return mat.rho_d, None
    return mat.total, mat


def _furniture(i: int, box: BoxSpec):
    verts, faces, names = _box_triangles(box.min, box.max, inward=False)
    label = box.name or f"furniture[{i}]"
    return verts, faces, _surfaces([box.reflectance] * len(faces)), [label] * len(faces)


def _load_mesh(i: int, spec: MeshSpec, base_dir: Path | None, count_only: bool = False):
    """(vertices, faces, reflectance, labels) of a mesh, every node's instance flattened.

    `count_only`: return only the number of triangles the mesh flattens to, counted from the
    file's structure (triangles of each geometry x the nodes instancing it), without
    transforming or copying anything (a small file may instance a large mesh many times).
    """
    label = spec.name or f"meshes[{i}]"
    if spec.vertices is not None:
        assert spec.faces is not None  # (the schema gives faces with vertices)
        if count_only:
            return len(spec.faces)
        verts = np.asarray(spec.vertices, float)
        faces = np.asarray(spec.faces, np.int64)
        return verts, faces, np.full(len(faces), spec.reflectance), [label] * len(faces)
    fmt: str | None = spec.format
    try:
        data, path = read_input(spec.file, spec.data_base64, base_dir, f"{label}: mesh file")
        if path is not None:
            fmt = fmt or path.suffix[1:].lower()
        if count_only and fmt in ("glb", "gltf"):
            return _gltf_triangles(data, fmt, label)
        # OBJ objects and groups become separate geometries (trimesh merges them otherwise).
        kw = {"split_objects": True, "split_groups": True} if fmt == "obj" else {}
        loaded = trimesh.load_scene(io.BytesIO(data), file_type=fmt, process=False, **kw)
    except SceneError:
        raise
    except Exception as exc:  # trimesh raises many kinds; the user needs the file and the reason
        raise SceneError(f"{label}: cannot read mesh ({type(exc).__name__}: {exc})") from None
    if count_only:
        return sum(
            len(getattr(loaded.geometry.get(name), "faces", ())) * len(nodes)
            for name, nodes in loaded.graph.geometry_nodes.items()
        )
    unknown = set(spec.group_reflectance)
    vs, fs, rhos, names, offset = [], [], [], [], 0
    for node in loaded.graph.nodes_geometry:
        transform, geom_name = loaded.graph[node]
        part = loaded.geometry[geom_name]
        if not hasattr(part, "faces") or len(part.faces) == 0:
            continue
        key = next((k for k in (node, geom_name) if k in spec.group_reflectance), None)
        unknown.discard(key)
        vs.append(trimesh.transform_points(np.asarray(part.vertices, float), transform))
        fs.append(np.asarray(part.faces, np.int64) + offset)
        offset += len(part.vertices)
        rho = spec.group_reflectance.get(key, spec.reflectance) if key is not None else spec.reflectance
        rhos.append(np.full(len(part.faces), rho))
        names += [f"{label}.{key or geom_name}"] * len(part.faces)
    if unknown:
        raise SceneError(f"{label}: group_reflectance names groups the file does not have: {sorted(unknown)}")
    if not fs:
        raise SceneError(f"{label}: the mesh has no faces")
    return np.concatenate(vs), np.concatenate(fs), np.concatenate(rhos), names


#: Triangles of a glTF primitive of `count` indices (or vertices) by its mode: triangles, strip, fan.
_GLTF_MODES = {4: lambda n: n // 3, 5: lambda n: max(n - 2, 0), 6: lambda n: max(n - 2, 0)}


def _gltf_triangles(data: bytes, fmt: str, label: str) -> int:
    """Triangles a glTF / GLB file flattens to, from its JSON only (no buffer decoded, no graph built):
    the triangles each node's mesh declares (accessor counts), over the nodes of the default scene and
    their children. SceneError past MAX_MESH_NODES nodes or for a JSON that is not glTF."""
    try:
        if fmt == "glb":
            magic, _, _ = struct.unpack_from("<4sII", data, 0)
            length, kind = struct.unpack_from("<I4s", data, 12)
            if magic != b"glTF" or kind != b"JSON":
                raise ValueError("not a GLB file (no glTF header and JSON chunk)")
            data = data[20 : 20 + length]
        doc = json.loads(data)
        nodes, meshes, accessors = (doc.get(k, []) for k in ("nodes", "meshes", "accessors"))
        if len(nodes) > MAX_MESH_NODES:
            raise SceneError(
                f"{label}: the mesh file has {len(nodes):,d} nodes; at most {MAX_MESH_NODES:,d} are accepted"
            )
        per_mesh = [
            sum(
                _GLTF_MODES.get(p.get("mode", 4), lambda n: 0)(
                    accessors[p["indices"] if "indices" in p else p["attributes"]["POSITION"]]["count"]
                )
                for p in m.get("primitives", [])
            )
            for m in meshes
        ]
        scenes = doc.get("scenes") or [{"nodes": list(range(len(nodes)))}]
        stack, seen, total = list(scenes[doc.get("scene", 0)].get("nodes", [])), set(), 0
        while stack:
            n = stack.pop()
            if n in seen:  # glTF nodes form a forest; a cycle would never end
                continue
            seen.add(n)
            total += per_mesh[nodes[n]["mesh"]] if "mesh" in nodes[n] else 0
            stack.extend(nodes[n].get("children", []))
        return total
    except SceneError:
        raise
    except Exception as exc:  # a malformed file: the user needs the file and the reason
        raise SceneError(f"{label}: cannot read mesh ({type(exc).__name__}: {exc})") from None


def check_extent(points: np.ndarray, what: str) -> float:
    """Largest side [m] of the box around `points` (n, 3); SceneError above MAX_SCENE_EXTENT."""
    with np.errstate(over="ignore", invalid="ignore"):
        extent = float(np.ptp(points, axis=0).max()) if len(points) else 0.0
    if not extent <= MAX_SCENE_EXTENT:
        raise SceneError(
            f"{what} span {extent:.4g} m, more than the {MAX_SCENE_EXTENT:g} m owcsim traces "
            "accurately (float32 ray casting around the scene centre); coordinates are in metres "
            "(a mesh in millimetres?)"
        )
    return extent


def build_geometry(spec: SceneSpec, base_dir: Path | None = None) -> Geometry:
    """All surfaces of the scene as one triangle soup; degenerate triangles dropped with a warning."""
    pieces = []
    if spec.room is not None:
        pieces.append(_room(spec.room))
    pieces += [_furniture(i, b) for i, b in enumerate(spec.furniture)]
    pieces += [_load_mesh(i, m, base_dir) for i, m in enumerate(spec.meshes)]
    if not pieces:
        return Geometry(np.zeros((0, 3)), np.zeros((0, 3), np.int64), np.zeros(0), np.zeros(0, np.int64), [])
    verts: list[np.ndarray] = []
    face_parts: list[np.ndarray] = []
    rho_parts: list[np.ndarray] = []
    labels: list[str] = []
    offset = 0
    for v, f, r, names in pieces:
        if not np.all(np.isfinite(v)):
            raise SceneError(f"{names[0].split('.')[0]}: vertices contain NaN or infinite values")
        verts.append(v)
        face_parts.append(f + offset)
        offset += len(v)
        rho_parts.append(r)
        labels += names
    vertices, faces, surfaces_all = np.concatenate(verts), np.concatenate(face_parts), np.concatenate(rho_parts)
    group_names, group = np.unique(np.asarray(labels), return_inverse=True)
    extent = check_extent(vertices, "the surfaces") or 1.0
    tri = vertices[faces]
    area2 = np.linalg.norm(np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]), axis=1)
    ok = area2 > 2 * DEGENERATE_AREA_FACTOR * extent**2
    if not ok.all():
        bad = sorted({str(group_names[g]) for g in group[~ok]})
        warnings.warn(f"dropped {int((~ok).sum())} degenerate (zero-area) triangles from {bad}", stacklevel=2)
    if not ok.any():
        raise SceneError("every triangle of the scene is degenerate")
    surfaces = surfaces_all[ok]
    rho, material = _materials(grey_surfaces(surfaces, spec))  # spectral surfaces: the carrier's (max over bands)
    return Geometry(
        vertices, faces[ok], rho, group[ok], list(group_names), material, surfaces if surfaces.dtype == object else None
    )


def _f32(a: np.ndarray, minus: np.ndarray | None = None) -> np.ndarray:
    """C-contiguous float32 (n, 3), as Embree wants it (from any layout, e.g. a transposed view), of `a` - `minus`
    (float64 arithmetic, one pass)."""
    a = np.asarray(a)
    out = np.empty(a.shape, np.float32)
    for k in range(a.shape[1]):  # column by column: 3-4x faster than one cast of a strided (transposed) view
        if minus is None:
            out[:, k] = a[:, k]
        else:
            np.subtract(a[:, k], minus[k], out=out[:, k], casting="same_kind")
    return out


class Intersector:
    """Batched closest-hit and occlusion queries against one Embree scene (float32, re-centred)."""

    def __init__(self, geometry: Geometry):
        self.geometry = geometry
        self.empty = len(geometry.faces) == 0
        v = geometry.vertices
        self.center = 0.5 * (v.min(axis=0) + v.max(axis=0)) if not self.empty else np.zeros(3)
        self.extent = float(np.ptp(v, axis=0).max()) if not self.empty else 1.0
        #: offset of re-spawned ray origins off surfaces [m]
        self.offset = RAY_OFFSET_FACTOR * max(self.extent, 1e-3)
        self.normals = geometry.normals if not self.empty else np.zeros((0, 3))
        #: face normals as (3, F) component rows, for gathers in the kernel
        self.normals_soa = np.ascontiguousarray(self.normals.T)
        self.n_intersect = 0
        self.n_occluded = 0
        if not self.empty:
            self._scene = rtcore_scene.EmbreeScene()
            from embreex.mesh_construction import TriangleMesh

            TriangleMesh(self._scene, (v - self.center).astype(np.float32)[geometry.faces])

    def intersect(self, origins: np.ndarray, directions: np.ndarray, t_max: np.ndarray | None = None):
        """Closest hit along each ray: (face index or -1, distance [m], inf on a miss)."""
        n = len(origins)
        self.n_intersect += n
        if self.empty or n == 0:
            return np.full(n, -1, np.int64), np.full(n, np.inf)
        dists = np.full(n, 1e30, np.float32) if t_max is None else np.array(t_max, np.float32)  # Embree writes it
        out = self._scene.run(_f32(origins, self.center), _f32(directions), dists=dists, output=1)
        prim = out["primID"].astype(np.int64)
        t = out["tfar"].astype(np.float64)
        missed = prim < 0
        if missed.any():
            t[missed] = np.inf
        return prim, t

    def occluded(self, origins: np.ndarray, directions: np.ndarray, t_max: np.ndarray) -> np.ndarray:
        """True where a surface lies on the ray within distance `t_max` [m]."""
        n = len(origins)
        self.n_occluded += n
        if self.empty or n == 0:
            return np.zeros(n, bool)
        res = self._scene.run(
            _f32(origins, self.center), _f32(directions), dists=np.array(t_max, np.float32), query="OCCLUDED"
        )
        return np.asarray(res) == 0
