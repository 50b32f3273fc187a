"""Surfaces of a scene: the parametric box room, furniture boxes, triangle meshes.

Every surface is Lambertian with reflectance `rho` in [0, 1] (BRDF rho/pi,
physics.md section 2) unless its `reflectance` is a material (surfaces.py: Phong,
mirror). The room's faces have inward normals; furniture and meshes reflect on
whichever side a ray arrives from.
"""

from __future__ import annotations

import math
from typing import Annotated, Literal

from pydantic import Field, model_validator

from .base import Point, SpecModel
from .surfaces import Surface  # a Lambertian reflectance, or a material (Phong, mirror; see surfaces.py)

Reflectance = Annotated[float, Field(ge=0.0, le=1.0, description="Lambertian reflectance rho, in [0, 1]")]

#: Names of the six faces of the box room, in the order the engine builds them.
ROOM_FACES = ("floor", "ceiling", "wall_x_min", "wall_x_max", "wall_y_min", "wall_y_max")
#: Most nodes of a glTF / GLB mesh file (each node a transform the scene graph holds).
MAX_MESH_NODES = 100_000


class RoomReflectance(SpecModel):
    """One reflectance (or material) per face; `walls` applies to the four walls unless one is named."""

    floor: Surface
    ceiling: Surface
    walls: Surface | None = None
    wall_x_min: Surface | None = None
    wall_x_max: Surface | None = None
    wall_y_min: Surface | None = None
    wall_y_max: Surface | None = None

    @model_validator(mode="after")
    def _every_wall_known(self) -> "RoomReflectance":
        missing = [w for w in ROOM_FACES[2:] if getattr(self, w) is None and self.walls is None]
        if missing:
            raise ValueError(f"no reflectance for {', '.join(missing)}: give `walls` or each wall")
        return self

    def by_face(self) -> dict:
        """Reflectance (or material) of each face, keyed by the names of ROOM_FACES."""
        out: dict = {"floor": self.floor, "ceiling": self.ceiling}
        for w in ROOM_FACES[2:]:
            v = getattr(self, w)
            out[w] = self.walls if v is None else v
        return out


class RoomSpec(SpecModel):
    """Axis-aligned box room: corner `origin` [m], `size` (L, W, H) [m], z up."""

    size: tuple[float, float, float] = Field(
        description="length x, width y, height z [m] (a side over 100 m warns: centimetres meant?)"
    )
    origin: Point = (0.0, 0.0, 0.0)
    reflectance: RoomReflectance

    @model_validator(mode="after")
    def _positive_size(self) -> "RoomSpec":
        if not all(math.isfinite(s) and s > 0 for s in self.size):
            raise ValueError("room size must be three positive finite lengths [m]")
        return self

    @property
    def lo(self) -> tuple[float, float, float]:
        return self.origin

    @property
    def hi(self) -> tuple[float, float, float]:
        return tuple(o + s for o, s in zip(self.origin, self.size))  # type: ignore[return-value]


class BoxSpec(SpecModel):
    """A solid axis-aligned box inside the room (furniture): corners `min`, `max` [m] (a side over 100 m warns)."""

    name: str | None = None
    min: Point
    max: Point
    reflectance: Surface

    @model_validator(mode="after")
    def _ordered(self) -> "BoxSpec":
        if not all(b > a for a, b in zip(self.min, self.max)):
            raise ValueError("box `max` must exceed `min` on every axis")
        return self


class MeshSpec(SpecModel):
    """A triangle mesh, inline or from a file trimesh reads (OBJ, STL, PLY, GLB).

    Give exactly one of: `vertices` + `faces` (inline), `file` (a path, relative to
    the scene document), or `data_base64` + `format` (file content in the document).
    `reflectance` applies to every face; `group_reflectance` overrides it per named
    group (OBJ groups/objects, GLB nodes) where the file has groups.
    """

    type: Literal["mesh"] = "mesh"
    name: str | None = None
    vertices: list[Point] | None = None
    faces: list[tuple[int, int, int]] | None = None
    file: str | None = None
    data_base64: str | None = None
    format: Literal["obj", "stl", "ply", "glb", "gltf", "off"] | None = None
    reflectance: Surface
    group_reflectance: dict[str, Surface] = Field(default_factory=dict)

    @model_validator(mode="after")
    def _one_source(self) -> "MeshSpec":
        sources = [
            self.vertices is not None or self.faces is not None,
            self.file is not None,
            self.data_base64 is not None,
        ]
        if sum(sources) != 1:
            raise ValueError("give exactly one of `vertices`+`faces`, `file`, `data_base64`+`format`")
        if sources[0]:
            if not self.vertices or not self.faces:
                raise ValueError("an inline mesh needs non-empty `vertices` and `faces`")
            n = len(self.vertices)
            bad = [i for i, f in enumerate(self.faces) if min(f) < 0 or max(f) >= n]
            if bad:
                raise ValueError(f"faces {bad[:5]} index vertices outside 0..{n - 1}")
        if sources[2] and self.format is None:
            raise ValueError("`data_base64` needs `format`")
        if self.file is not None and self.format is None:
            suffix = self.file.rsplit(".", 1)[-1].lower()
            if suffix not in ("obj", "stl", "ply", "glb", "gltf", "off"):
                raise ValueError(f"cannot tell the format of {self.file!r}: give `format`")
        return self
