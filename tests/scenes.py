"""Small scene factories for the tests (documents as plain dicts, validated by the caller)."""

from __future__ import annotations

import copy
import json
import math
from pathlib import Path

from owcsim.schemas import SceneSpec

EXAMPLES = Path(__file__).resolve().parent.parent / "examples"


def barry_doc(**simulation) -> dict:
    """Barry et al. 1993 configuration A, with simulation overrides."""
    doc = json.loads((EXAMPLES / "barry_config_a.json").read_text())
    doc["simulation"].update(simulation)
    return doc


#: Reflectances of room_doc's defaults (Barry et al. 1993 configuration A) per face, as tests/reference.py takes them.
BARRY_RHO = {"floor": 0.3, "ceiling": 0.8, "wall_x_min": 0.8, "wall_x_max": 0.8, "wall_y_min": 0.8, "wall_y_max": 0.8}


def barry_first_bounce(rx, fov_deg: float, rel_tol: float = 1e-4) -> float:
    """First-reflection DC gain H1 of room_doc's default room and transmitter (Barry configuration A) at an
    upward 1 cm^2 receiver `rx` with half-angle FOV `fov_deg`: the patch integral of tests/reference.py."""
    from tests.reference import first_bounce_box_dc_gain

    return first_bounce_box_dc_gain(
        (5.0, 5.0, 3.0),
        BARRY_RHO,
        (2.5, 2.5, 3.0),
        (0, 0, -1),
        1.0,
        rx,
        (0, 0, 1),
        1e-4,
        math.radians(fov_deg),
        rel_tol=rel_tol,
    )


def room_doc(
    rho_walls=0.8,
    rho_floor=0.3,
    rho_ceiling=0.8,
    *,
    tx=(2.5, 2.5, 3.0),
    tx_normal=(0, 0, -1),
    m=1.0,
    rx=(1.0, 1.0, 0.0),
    rx_normal=(0, 0, 1),
    area=1e-4,
    fov_deg=90.0,
    size=(5.0, 5.0, 3.0),
    origin=(0.0, 0.0, 0.0),
    medium=None,
    **simulation,
) -> dict:
    """A 5 x 5 x 3 m room with one transmitter and one receiver."""
    sim = {"algorithm": 1, "max_reflections": 3, "time_bin_s": 1e-9, "t_max_s": 2e-7, "paths": 20_000, "seed": 7}
    sim.update(simulation)
    doc = {
        "room": {
            "size": list(size),
            "origin": list(origin),
            "reflectance": {"floor": rho_floor, "ceiling": rho_ceiling, "walls": rho_walls},
        },
        "transmitters": [{"id": "tx", "position": list(tx), "normal": list(tx_normal), "lambertian_order": m}],
        "receivers": [{"id": "rx", "position": list(rx), "normal": list(rx_normal), "area": area, "fov_deg": fov_deg}],
        "simulation": sim,
    }
    if medium is not None:
        doc["medium"] = medium
    return doc


#: Homogeneous smoke of the scattering tests (albedo 0.8, HG g = 0.5).
SMOKE = {"type": "homogeneous", "sigma_a": 0.05, "sigma_s": 0.2, "phase": {"type": "hg", "g": 0.5}}


def open_doc(D=3.0, medium=SMOKE, **simulation) -> dict:
    """No surfaces: Tx at the origin facing +x, Rx at (D, 0, 0) facing it, FOV 90 deg."""
    sim = {"max_reflections": 0, "time_bin_s": 1e-9, "t_max_s": 1e-7, "paths": 40_000, "seed": 17}
    sim.update(simulation)
    return {
        "transmitters": [{"id": "tx", "position": [0, 0, 0], "normal": [1, 0, 0], "lambertian_order": 1}],
        "receivers": [{"id": "rx", "position": [D, 0, 0], "normal": [-1, 0, 0], "area": 1e-4, "fov_deg": 90}],
        "medium": medium,
        "simulation": sim,
    }


def spec(doc: dict) -> SceneSpec:
    return SceneSpec.model_validate(copy.deepcopy(doc))


def within(value, ref, stderr, n_sigma=4.0, bias=0.0) -> bool:
    """|value - ref| <= n_sigma * stderr + bias (bias: the reference's own error budget)."""
    return abs(value - ref) <= n_sigma * stderr + bias
