"""Small builders for the common scenes: a box room, lamps, photodiodes, a work-plane grid.

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
from typing import Any

from owcsim.schemas import SceneSpec
from owcsim.schemas.devices import ReceiverGridSpec, ReceiverSpec, TransmitterSpec
from owcsim.schemas.geometry import RoomReflectance, RoomSpec
from owcsim.schemas.simulation import SimulationSpec

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


def work_plane(
    room: RoomSpec,
    *,
    height: float = 0.85,
    spacing: float = 0.1,
    margin: float = 0.0,
    area: float = 1e-4,
    fov_deg: float = 90.0,
    id_prefix: str = "grid",
    **fields: Any,
) -> ReceiverGridSpec:
    """Upward receivers every `spacing` [m] on the horizontal plane `height` [m] above the room's floor,
    `margin` [m] in from the walls (0.85 m: the work plane of EN 12464-1)."""
    x0, y0, z0 = room.origin
    length, width, _ = room.size
    return ReceiverGridSpec(
        id_prefix=id_prefix,
        origin=(x0 + margin, y0 + margin, z0 + height),
        size=(length - 2 * margin, width - 2 * margin),
        spacing=spacing,
        area=area,
        fov_deg=fov_deg,
        **fields,
    )


def scene(
    room: RoomSpec | None,
    transmitters: Sequence[TransmitterSpec],
    receivers: Sequence[ReceiverSpec] = (),
    grids: Sequence[ReceiverGridSpec] = (),
    *,
    medium: Any = None,
    name: str | None = None,
    **simulation: Any,
) -> SceneSpec:
    """The scene document: the room, devices, an optional medium (a dict or MediumSpec) and the
    simulation settings as keywords (`paths=`, `algorithm=`, `max_reflections=`, ...)."""
    return SceneSpec(
        name=name,
        room=room,
        transmitters=list(transmitters),
        receivers=list(receivers),
        receiver_grids=list(grids),
        medium=medium,
        simulation=SimulationSpec(**simulation),
    )
