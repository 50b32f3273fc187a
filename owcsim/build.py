"""Small builders for the common scenes: a box room, furniture, lamps and arrays of them, transmitter
groups, spectra, photodiodes, grids on the work plane and on a wall.

Each returns the pydantic model of the scene document (owcsim.schemas), validated on the
spot, so a mistake is reported where it is made; `scene(...)` assembles them into a
`SceneSpec` that `owcsim.simulate` runs. Units are SI: metres, watts, square metres, degrees
for angles named `_deg`.

    import owcsim
    from owcsim import build

    room = build.box_room((5, 5, 3), walls=0.8, floor=0.3, ceiling=0.8)
    spec = build.scene(room, [build.lamp((2.5, 2.5, 3))], [build.photodiode((1, 1, 0))], paths=20_000)
    result = owcsim.simulate(spec)

Anything the builders do not cover is a keyword of the model itself (`lamp(..., luminous_output=...)`
passes it through to `TransmitterSpec`), and the models can be built directly.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any, Literal

from owcsim.schemas import SceneSpec
from owcsim.schemas.devices import PlaneArea, ReceiverGridSpec, ReceiverSpec, TransmitterSpec
from owcsim.schemas.geometry import BoxSpec, RoomReflectance, RoomSpec
from owcsim.schemas.scene import TransmitterGroupSpec
from owcsim.schemas.simulation import SimulationSpec
from owcsim.schemas.spectra import NamedCurveSpec, SpectralSpec, SpectralSurfaceSpec, TableCurveSpec

Vec = tuple[float, float, float] | Sequence[float]

#: Straight down and straight up: a ceiling lamp and a receiver on a desk or the floor.
DOWN, UP = (0.0, 0.0, -1.0), (0.0, 0.0, 1.0)


def box_room(
    size: Vec, *, walls: Any = 0.8, floor: Any = 0.3, ceiling: Any = 0.8, origin: Vec = (0.0, 0.0, 0.0)
) -> RoomSpec:
    """An axis-aligned room `size` = (L, W, H) [m] with its corner at `origin`; each face a reflectance
    in [0, 1] or a surface model (a dict of the scene document, e.g. {"type": "phong", ...})."""
    return RoomSpec(
        size=tuple(size),
        origin=tuple(origin),
        reflectance=RoomReflectance(walls=walls, floor=floor, ceiling=ceiling),
    )


def lamp(
    position: Vec,
    *,
    normal: Vec = DOWN,
    power: float = 1.0,
    lambertian_order: float | None = None,
    half_power_semi_angle_deg: float | None = None,
    id: str | None = None,
    **fields: Any,
) -> TransmitterSpec:
    """A generalized Lambertian source: optical power `power` [W], order m (or its half-power
    semi-angle, m = -ln 2 / ln cos(Phi_1/2)); m = 1 when neither is given."""
    if lambertian_order is None and half_power_semi_angle_deg is None and "photometry" not in fields:
        lambertian_order = 1.0
    return TransmitterSpec(
        id=id,
        position=tuple(position),
        normal=tuple(normal),
        power=power,
        lambertian_order=lambertian_order,
        half_power_semi_angle_deg=half_power_semi_angle_deg,
        **fields,
    )


def photodiode(
    position: Vec,
    *,
    normal: Vec = UP,
    area: float = 1e-4,
    fov_deg: float = 90.0,
    id: str | None = None,
    **fields: Any,
) -> ReceiverSpec:
    """A receiver of detector area `area` [m^2] and field of view `fov_deg` [deg] (half-angle)."""
    return ReceiverSpec(id=id, position=tuple(position), normal=tuple(normal), area=area, fov_deg=fov_deg, **fields)


def furniture(min: Vec, max: Vec, *, reflectance: Any = 0.5, name: str | None = None) -> BoxSpec:
    """A solid axis-aligned box from corner `min` to corner `max` [m] (a desk, a shelf, a cabinet); its
    surface a reflectance in [0, 1] or a surface model (`spectral_surface(...)`, a dict of the document)."""
    return BoxSpec(name=name, min=tuple(min), max=tuple(max), reflectance=reflectance)


def lamp_array(
    room: RoomSpec,
    shape: tuple[int, int] = (2, 2),
    *,
    height: float | None = None,
    id_prefix: str = "led",
    **lamp_fields: Any,
) -> list[TransmitterSpec]:
    """`shape` = (n_x, n_y) lamps facing down at the centres of an n_x x n_y division of the room's floor plan
    (a 5 x 5 m room's 2 x 2 array: x, y in {1.25, 3.75}), `height` [m] above the floor (default: the ceiling);
    ids `{id_prefix}1`, `{id_prefix}2`, ... row by row along y; other keywords go to each `lamp`."""
    nx, ny = shape
    if nx < 1 or ny < 1:
        raise ValueError(f"a lamp array needs at least one lamp along x and y, got shape {shape}")
    (x0, y0, z0), (length, width, tall) = room.origin, room.size
    z = z0 + (tall if height is None else height)
    return [
        lamp(
            (x0 + (i + 0.5) * length / nx, y0 + (j + 0.5) * width / ny, z),
            id=f"{id_prefix}{i * ny + j + 1}",
            **lamp_fields,
        )
        for i in range(nx)
        for j in range(ny)
    ]


def group(name: str, transmitters: Sequence[TransmitterSpec | str]) -> TransmitterGroupSpec:
    """Transmitters that carry one signal (a LiFi cell): their channels add up, per watt of the group's power.
    Members are given as transmitters (each with an `id`) or as ids."""
    ids = []
    for k, t in enumerate(transmitters):
        if isinstance(t, TransmitterSpec):
            if t.id is None:
                raise ValueError(f"member {k} of group {name!r} has no `id`: give its transmitter one (lamp(..., id=))")
            ids.append(t.id)
        else:
            ids.append(str(t))
    return TransmitterGroupSpec(name=name, transmitters=ids)


def spectrum(
    name: str | None = None, *, wavelengths: Sequence[float] | None = None, values: Sequence[float] | None = None
) -> NamedCurveSpec | TableCurveSpec:
    """A spectral curve (an SPD, a reflectance, a responsivity, a filter): a table shipped with owcsim by
    `name` ("white_led_cool", "white_paint", "silicon_pin", ...: schemas.spectra.NAMED_CURVES), or tabulated at
    `wavelengths` [m] (increasing) with `values`, linear between points."""
    if (name is None) == (wavelengths is None and values is None):
        raise ValueError("give a curve's `name`, or its `wavelengths` [m] and `values`")
    if name is not None:
        return NamedCurveSpec.model_validate({"name": name})
    return TableCurveSpec(wavelengths=list(wavelengths or []), values=list(values or []))


def spectral_surface(reflectance: Any) -> SpectralSurfaceSpec:
    """A surface whose reflectance varies with wavelength: a curve (`spectrum(...)`, a number or a list per
    band), for a room face or furniture in a scene with `spectral` bands."""
    return SpectralSurfaceSpec(reflectance=reflectance)


def bands(start: float, stop: float, count: int) -> SpectralSpec:
    """`count` equal wavelength bands from `start` to `stop` [m] (e.g. 380e-9 to 780e-9): the scene's
    `spectral` setting."""
    if count < 1:
        raise ValueError(f"give at least one band, got {count}")
    step = (stop - start) / count
    return SpectralSpec(band_edges=[start + k * step for k in range(count)] + [stop])


def _steps(spacing: float | tuple[float, float] | None, shape: tuple[int, int] | None) -> dict[str, Any]:
    if (spacing is None) == (shape is None):
        raise ValueError("give a grid's `spacing` (one step or (s_u, s_v), in m) or its `shape` (n_u, n_v)")
    return {"spacing": spacing} if shape is None else {"shape": tuple(shape)}


def work_plane(
    room: RoomSpec,
    *,
    height: float = 0.85,
    spacing: float | tuple[float, float] | None = None,
    shape: tuple[int, int] | None = None,
    margin: float = 0.0,
    area: float = 1e-4,
    fov_deg: float = 90.0,
    id_prefix: str = "grid",
    exclude: Sequence[PlaneArea | dict] = (),
    **fields: Any,
) -> ReceiverGridSpec:
    """Upward receivers on the horizontal plane `height` [m] above the room's floor, `margin` [m] in from the
    walls (0.85 m: the work plane of EN 12464-1): every `spacing` [m] (one step, or (s_x, s_y)), or `shape` =
    (n_x, n_y) points spread over the plane, both edges included; 0.1 m steps when neither is given.
    `exclude`: areas of the plane left out (plane coordinates [m] from the grid's corner, PlaneArea or dicts)."""
    x0, y0, z0 = room.origin
    length, width, _ = room.size
    return ReceiverGridSpec.model_validate(
        {
            "id_prefix": id_prefix,
            "origin": (x0 + margin, y0 + margin, z0 + height),
            "size": (length - 2 * margin, width - 2 * margin),
            **_steps(0.1 if spacing is None and shape is None else spacing, shape),
            "area": area,
            "fov_deg": fov_deg,
            "exclude": list(exclude),
            **fields,
        }
    )


#: The walls of a box room by name: (axis across the wall, at its low or high end).
WALLS: dict[str, tuple[int, bool]] = {"x_min": (0, False), "x_max": (0, True), "y_min": (1, False), "y_max": (1, True)}


def wall_grid(
    room: RoomSpec,
    wall: Literal["x_min", "x_max", "y_min", "y_max"],
    *,
    spacing: float | tuple[float, float] | None = None,
    shape: tuple[int, int] | None = None,
    margin: float = 0.0,
    heights: tuple[float, float] | None = None,
    offset: float = 0.0,
    area: float = 1e-4,
    fov_deg: float = 90.0,
    id_prefix: str | None = None,
    **fields: Any,
) -> ReceiverGridSpec:
    """Receivers on a wall of the room, facing into the room (vertical illuminance, a shelf's face):
    `offset` [m] in front of the wall, from `margin` [m] in from the neighbouring walls, between `heights` =
    (bottom, top) [m] above the floor (default: `margin` from floor and ceiling). u runs along the wall (+x or
    +y), v up (+z); every `spacing` [m] (one step, or (s_along, s_up)) or `shape` = (n_along, n_up) points."""
    if wall not in WALLS:
        raise ValueError(f"wall must be one of {sorted(WALLS)}, got {wall!r}")
    axis, high = WALLS[wall]
    along = 1 - axis
    lo, size = room.origin, room.size
    bottom, top = heights if heights is not None else (margin, size[2] - margin)
    origin = [0.0, 0.0, lo[2] + bottom]
    origin[axis] = lo[axis] + size[axis] - offset if high else lo[axis] + offset
    origin[along] = lo[along] + margin
    u = tuple(1.0 if k == along else 0.0 for k in range(3))
    normal = tuple((-1.0 if high else 1.0) if k == axis else 0.0 for k in range(3))
    return ReceiverGridSpec.model_validate(
        {
            "id_prefix": id_prefix or f"wall_{wall}",
            "origin": tuple(origin),
            "u": u,
            "v": (0.0, 0.0, 1.0),
            "size": (size[along] - 2 * margin, top - bottom),
            **_steps(spacing, shape),
            "normal": normal,
            "area": area,
            "fov_deg": fov_deg,
            **fields,
        }
    )


def scene(
    room: RoomSpec | None,
    transmitters: Sequence[TransmitterSpec],
    receivers: Sequence[ReceiverSpec] = (),
    grids: Sequence[ReceiverGridSpec] = (),
    *,
    furniture: Sequence[BoxSpec] = (),
    groups: Sequence[TransmitterGroupSpec] = (),
    medium: Any = None,
    spectral: SpectralSpec | None = None,
    link_budget: Any = None,
    name: str | None = None,
    **simulation: Any,
) -> SceneSpec:
    """The scene document: the room, furniture, devices, transmitter groups, an optional medium (a dict or
    MediumSpec), spectral bands and link budget, and the simulation settings as keywords (`paths=`,
    `algorithm=`, `max_reflections=`, `target_rel_error=`, ...)."""
    return SceneSpec(
        name=name,
        room=room,
        furniture=list(furniture),
        transmitters=list(transmitters),
        receivers=list(receivers),
        receiver_grids=list(grids),
        transmitter_groups=list(groups),
        medium=medium,
        spectral=spectral,
        link_budget=link_budget,
        simulation=SimulationSpec(**simulation),
    )
