"""Wire models (pydantic v2): the one source of truth for the JSON of scenes, jobs and results.

Depends on nothing else in owcsim; `engine`, `server` and `clients` import it.
"""

from .devices import ReceiverGridSpec, ReceiverSpec, TransmitterSpec
from .geometry import ROOM_FACES, BoxSpec, MeshSpec, RoomReflectance, RoomSpec
from .link_budget import LinkBudgetSpec, LuminousOutputSpec
from .medium import (
    BoxRegionSpec,
    ComplexIndexSpec,
    GridMediumSpec,
    HenyeyGreensteinPhaseSpec,
    HomogeneousMediumSpec,
    IsotropicPhaseSpec,
    MediumSpec,
    MeshRegionSpec,
    MiePhaseSpec,
    MixturePhaseSpec,
    ParticleMediumSpec,
    ParticlesSpec,
    PhaseSpec,
    RayleighPhaseSpec,
    SceneRegionSpec,
    SchlickPhaseSpec,
    TabulatedPhaseSpec,
)
from .outputs import OutputsSpec
from .photometry import PhotometrySpec
from .scene import SceneSpec, TransmitterGroupSpec
from .simulation import SimulationSpec

__all__ = [
    "BoxRegionSpec",
    "BoxSpec",
    "GridMediumSpec",
    "MeshRegionSpec",
    "HenyeyGreensteinPhaseSpec",
    "HomogeneousMediumSpec",
    "IsotropicPhaseSpec",
    "MediumSpec",
    "MeshSpec",
    "MixturePhaseSpec",
    "PhaseSpec",
    "RayleighPhaseSpec",
    "ReceiverGridSpec",
    "ReceiverSpec",
    "ROOM_FACES",
    "RoomReflectance",
    "RoomSpec",
    "SceneRegionSpec",
    "SceneSpec",
    "SchlickPhaseSpec",
    "SimulationSpec",
    "TransmitterSpec",
    "LinkBudgetSpec",
    "LuminousOutputSpec",
    "PhotometrySpec",
    "OutputsSpec",
    "TransmitterGroupSpec",
    "ComplexIndexSpec",
    "MiePhaseSpec",
    "ParticleMediumSpec",
    "ParticlesSpec",
    "TabulatedPhaseSpec",
]

# The HTTP service: jobs and problem details.
from .errors import Problem, ProblemField  # noqa: E402
from .jobs import HealthPublic, JobListPublic, JobProgress, JobPublic, JobStatus, JobUrls, VersionPublic  # noqa: E402

__all__ += [
    "HealthPublic",
    "JobListPublic",
    "JobProgress",
    "JobPublic",
    "JobStatus",
    "JobUrls",
    "Problem",
    "ProblemField",
    "VersionPublic",
]
