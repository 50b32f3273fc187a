"""Wire models (pydantic v2): the one source of truth for the JSON of scenes, jobs and results.

Depends on nothing else in owcsim; `engine`, `server` and `clients` import it.
"""
from .devices import ReceiverGridSpec, ReceiverSpec, TransmitterSpec
from .geometry import ROOM_FACES, BoxSpec, MeshSpec, RoomReflectance, RoomSpec
from .medium import (BoxRegionSpec, HenyeyGreensteinPhaseSpec, HomogeneousMediumSpec, IsotropicPhaseSpec,
                     MediumSpec, MixturePhaseSpec, PhaseSpec, RayleighPhaseSpec, SceneRegionSpec,
                     SchlickPhaseSpec)
from .scene import SceneSpec
from .simulation import SimulationSpec

__all__ = [
    "BoxRegionSpec", "BoxSpec", "HenyeyGreensteinPhaseSpec", "HomogeneousMediumSpec", "IsotropicPhaseSpec",
    "MediumSpec", "MeshSpec", "MixturePhaseSpec", "PhaseSpec", "RayleighPhaseSpec", "ReceiverGridSpec",
    "ReceiverSpec", "ROOM_FACES", "RoomReflectance", "RoomSpec", "SceneRegionSpec", "SceneSpec",
    "SchlickPhaseSpec", "SimulationSpec", "TransmitterSpec",
]
