"""Point devices: transmitters and receivers share one description (physics.md section 2).

A device is a point `position` with unit `normal` and an angular response
`response(cos)` [per sr]: for a transmitter the radiant intensity per watt,
R(phi) = (m+1)/(2 pi) cos^m(phi); for a receiver the collecting area per unit
radiance, A cos(psi) T_s g rect(psi <= FOV). The channel gain of a path
src -> x1 ... xk -> dst is then symmetric in the two devices, which is what lets
one kernel trace from either side: rays leave a device with a pdf proportional to
its response, carrying the weight `total_response` = integral of the response over
the sphere (1 for a transmitter per watt; A T_s g pi sin^2(FOV) for a receiver).

A transmitter may instead carry a tabulated pattern (a luminaire's photometric file,
photometry.py): response I(gamma, C) / Phi [1/sr], with gamma from its aiming axis
(`normal`) and C from its C = 0 half-plane (`frames`); its response needs the
direction, not only the cosine, and it may emit behind its normal (gamma > 90 deg).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from owcsim.engine.core.errors import SceneError
from owcsim.engine.core.inputs import read_input
from owcsim.engine.core.sampling import _cone_polar, _lambertian_polar, polar_about_soa
from owcsim.engine.sources.photometry import Photometry, PhotometryError, luminaire_frame
from owcsim.engine.sources.photometry_files import parse_photometry
from owcsim.schemas import ReceiverSpec, TransmitterSpec


@dataclass
class Devices:
    """A set of point devices of one kind; arrays have a leading device axis.

    `kind` is "transmitter" (response (m+1)/(2 pi) cos^m) or "receiver"
    (response gain * cos for cos >= cos_fov, with gain = A T_s g).
    """

    kind: str
    ids: list[str]
    positions: np.ndarray  # (n, 3) [m]
    normals: np.ndarray  # (n, 3)
    order: np.ndarray  # (n,) Lambertian order m (transmitters)
    cos_fov: np.ndarray  # (n,) cos(FOV) (receivers; 0 for transmitters)
    gain: np.ndarray  # (n,) A T_s g [m^2] (receivers; 1 for transmitters)
    power: np.ndarray  # (n,) P_t [W] (transmitters; 1 for receivers)
    area: np.ndarray  # (n,) collecting area A [m^2] (receivers; 0 for transmitters)
    #: tabulated patterns (transmitters from photometric files), None for a Lambertian device
    patterns: list[Photometry | None] = field(default_factory=list)
    #: (n, 3, 3) rows (e_C0, e_C90, aim) of each tabulated device (unused for the others)
    frames: np.ndarray | None = None

    def __len__(self) -> int:
        return len(self.ids)

    @property
    def tabulated(self) -> list[int]:
        """Indices of the devices with a tabulated pattern."""
        return [i for i, p in enumerate(self.patterns) if p is not None]

    def pattern(self, i: int) -> tuple[Photometry, np.ndarray]:
        """(tabulated pattern, frame (3, 3): rows e_C0, e_C90, aim) of device i, which has one."""
        p = self.patterns[i]
        assert p is not None and self.frames is not None, f"device {i} has no tabulated pattern"
        return p, self.frames[i]

    @property
    def front_only(self) -> bool:
        """True when no device responds behind its normal (cos <= 0 gives 0 for all)."""
        return all(self.pattern(i)[0].max_gamma <= np.pi / 2 + 1e-12 for i in self.tabulated)

    def response(self, idx: np.ndarray, cos: np.ndarray, directions: np.ndarray | None = None) -> np.ndarray:
        """Angular response of devices `idx` at cosine `cos` to their normal [1/sr or m^2].

        `directions` (n, 3): unit directions from the device (needed by tabulated devices).
        """
        cos = np.asarray(cos, float)
        idx = np.asarray(idx)
        if self.kind == "transmitter":
            tabulated = self.tabulated
            if len(tabulated) == len(self.ids) == 1:  # one luminaire (the usual backward target): no masks
                if directions is None:
                    raise ValueError("a tabulated transmitter's response needs the directions")
                pattern, frame = self.pattern(0)
                local = frame @ np.asarray(directions, float).T  # (3, n) rows (callers pass (3, n).T)
                return pattern.eval_rows(local[0], local[1], local[2])
            m = self.order.take(idx)
            safe = np.where(cos > 0, cos, 1.0)
            out = np.where(cos > 0, (m + 1) / (2 * np.pi) * np.exp(m * np.log(safe)), 0.0)
            for j in tabulated:  # a loop over devices
                sel = np.flatnonzero(idx == j)
                if len(sel):
                    if directions is None:
                        raise ValueError("a tabulated transmitter's response needs the directions")
                    pattern, frame = self.pattern(j)
                    local = frame @ np.asarray(directions, float)[sel].T
                    out[sel] = pattern.eval_rows(local[0], local[1], local[2])
            return out
        return np.where((cos > 0) & (cos >= self.cos_fov.take(idx)), self.gain.take(idx) * cos, 0.0)

    def response_one(self, i: int, cos: np.ndarray, directions: np.ndarray | None = None) -> np.ndarray:
        """`response` of device i alone at cosines `cos` [1/sr or m^2]: its parameters as scalars, no per-estimate
        index arrays (the kernel's connections to one target); m = 1 is cos / pi without a power."""
        if self.kind == "transmitter":
            if self.patterns and self.patterns[i] is not None:
                return self.response(np.full(len(cos), i), cos, directions)
            m = float(self.order[i])
            if m == 1.0:
                return np.maximum(cos, 0.0) * (1.0 / np.pi)
            safe = np.where(cos > 0, cos, 1.0)
            return np.where(cos > 0, (m + 1) / (2 * np.pi) * np.exp(m * np.log(safe)), 0.0)
        lowest, gain = float(self.cos_fov[i]), float(self.gain[i])
        if lowest <= 0.0:  # FOV = 90 deg: the front hemisphere
            return np.maximum(cos, 0.0) * gain
        return np.where(cos >= lowest, gain * cos, 0.0)

    @property
    def directional(self) -> bool:
        """True when a response needs the direction, not only the cosine (tabulated transmitters)."""
        return self.kind == "transmitter" and any(p is not None for p in self.patterns)

    def total_response(self, i: int) -> float:
        """Integral of device i's response over the sphere (the weight of a sampled ray)."""
        if self.kind == "transmitter":
            return 1.0
        return float(self.gain[i] * np.pi * (1.0 - self.cos_fov[i] ** 2))

    def sample_directions(self, i: int, u1: np.ndarray, u2: np.ndarray) -> np.ndarray:
        """Directions leaving device i with pdf response / total_response (exact inversion)."""
        if self.kind == "transmitter":
            if self.patterns and self.patterns[i] is not None:
                pattern, frame = self.pattern(i)
                return (frame.T @ pattern.sample_rows(u1, u2)).T  # a view of (3, n) rows
            polar = _lambertian_polar(self.order[i], u1)
        else:
            polar = _cone_polar(self.cos_fov[i], u1)
        return polar_about_soa(*polar, u2, self.normals[i]).T  # (n, 3) view of (3, n) rows


def unit_normals(specs) -> np.ndarray:
    """(n, 3) unit normals of device specs: the one normalisation of a document's directions
    (schemas keep them as given, so a stored document replays to the same bits)."""
    n = np.array([s.normal for s in specs], float).reshape(len(specs), 3)
    return n / np.linalg.norm(n, axis=1, keepdims=True)


def load_photometry(spec, where: str, base_dir: Path | None) -> Photometry:
    """Read and parse a transmitter's photometric file (inline base64, or a path relative to base_dir)."""
    pspec = spec.photometry
    data, path = read_input(pspec.file, pspec.data_base64, base_dir, f"{where}: photometric file")
    if path is not None:
        where = f"{where} ({path.name})"
    return parse_photometry(data, pspec.resolved_format, where)


def transmitters_from_specs(specs: list[TransmitterSpec], ids: list[str], base_dir: Path | None = None) -> Devices:
    n = len(specs)
    patterns: list[Photometry | None] = []
    frames = np.zeros((n, 3, 3))
    for i, s in enumerate(specs):
        if s.photometry is None:
            patterns.append(None)
            continue
        where = f"transmitters[{i}].photometry"
        try:
            patterns.append(load_photometry(s, where, base_dir))
        except PhotometryError as exc:  # located at the document's field: the service's problem names it
            exc.loc = f"transmitters.{i}.photometry.{'file' if s.photometry.file is not None else 'data_base64'}"
            raise
        try:
            frames[i] = luminaire_frame(s.normal, s.photometry.c0_direction, s.photometry.rotation_deg)
        except SceneError as exc:
            raise PhotometryError(f"transmitters[{i}]: {exc}") from None
    return Devices(
        kind="transmitter",
        ids=ids,
        positions=np.array([s.position for s in specs], float).reshape(n, 3),
        normals=unit_normals(specs),
        order=np.array([s.m for s in specs], float),
        cos_fov=np.zeros(n),
        gain=np.ones(n),
        power=np.array([s.power for s in specs], float),
        area=np.zeros(n),
        patterns=patterns,
        frames=frames,
    )


def concentrator_gain(fov: float, index: float | None) -> float:
    """Ideal non-imaging concentrator g = n_c^2 / sin^2(FOV); 1 without one."""
    return 1.0 if index is None else index**2 / np.sin(fov) ** 2


def receivers_from_specs(specs: list[ReceiverSpec], ids: list[str]) -> Devices:
    n = len(specs)
    fov = np.radians([s.fov_deg for s in specs]).reshape(n)
    gain = np.array(
        [s.area * s.filter_gain * concentrator_gain(f, s.concentrator_index) for s, f in zip(specs, fov)], float
    ).reshape(n)
    # cos(90 deg) is 6e-17 in floating point, not 0: clamp so FOV = 90 deg is the full hemisphere.
    cos_fov = np.where(np.isclose(fov, np.pi / 2, rtol=0, atol=1e-12), 0.0, np.cos(fov))
    return Devices(
        kind="receiver",
        ids=ids,
        positions=np.array([s.position for s in specs], float).reshape(n, 3),
        normals=unit_normals(specs),
        order=np.zeros(n),
        cos_fov=cos_fov,
        gain=gain,
        power=np.ones(n),
        area=np.array([s.area for s in specs], float).reshape(n),
        patterns=[None] * n,
    )
