"""The combination matrix of issue 22: every combination either holds or is refused with one sentence.

A *cell* picks one value on each axis of `AXES` (furnishing, medium, spectral, surfaces, luminaire,
algorithm, output, receivers, extreme). `scene(cell)` builds the scene document a user would write
(from the shapes of examples/*.json and tests/scenes.py); `run(cell)` runs it through the public
Python API (`owcsim.simulate`) and checks it against an estimate that does not share its estimator:

- no scattering (no medium, or the `sigma -> 0` extreme, which is compared with the room *without*
  smoke: vacuum): algorithm 1 from the other side (forward <-> backward);
- algorithms 1 and 5 in smoke: the same algorithm from the other side;
- algorithms 2, 3, 4 in smoke with a swappable pair (Lambertian m = 1 transmitter, FOV 90 deg):
  the devices swapped, algorithm 2 <-> 3 (4 <-> 4): reciprocity maps algorithm 2's family
  Tx -> p -> (k) -> Rx onto algorithm 3's Rx' -> (k) -> p -> Tx' (physics.md section 6);
- algorithms 2, 3, 4 otherwise (photometric luminaire, FOV 1 deg): the cell runs with K = 0, where
  the families coincide with algorithm 5's s <= 1 (2, 3) or s <= 2 (4) (physics.md section 4);
- automatic settings (algorithm `auto`): the reference has K = S = 1000 (nothing truncated), so a
  pilot that stops too early is seen;
- and, in an empty room with a Lambertian transmitter and homogeneous (or no) smoke, every link's
  line-of-sight gain against the closed form (m+1) A cos^m(phi) cos(psi) / (2 pi d^2) exp(-sigma_t d)
  (tests/reference.py), to 1e-6.

The reference runs with another seed, so even a same-side comparison is two independent estimates.
Per link, z = |a - b| / sqrt(se_a^2 + se_b^2); a cell holds when every link has z <= Z_MAX. With
Gaussian errors P(|Z| > 4.5) = 6.8e-6 per link; the full matrix compares about 1 000 links, so the
expected number of false alarms is 0.007 (and the seeds are fixed, so a cell never flakes). Power:
every cell must also fail when the cell's gains are planted 10 % high (max z of 1.1 a against b above
Z_MAX), i.e. the combined relative error is below about 2 %; `Outcome.power` records it and the tests
require it. A cell whose z exceeds Z_MAX while its result warns that the error bar is unreliable is
"flagged" (the run said so), not silently wrong.

Refusals: an `InputError` (invalid document) or `EngineError` (a scene the engine refuses) whose message
is one line without a traceback. Anything else (another exception, a non-finite number, a z above
Z_MAX without a warning) is a failure.

`python -m tests.matrix --table` prints the "At the extremes" table of docs/extremes.md;
`--tier fast|full` runs a tier and prints one row per cell.
"""

from __future__ import annotations

import argparse
import base64
import copy
import itertools
import math
import random
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

EXAMPLES = Path(__file__).resolve().parent.parent / "examples"

#: Largest |a - b| / sqrt(se_a^2 + se_b^2) of a cell that holds (module docstring).
Z_MAX = 4.5
#: The planted error of the power check (a cell must fail with its gains 10 % high).
PLANTED = 0.10

AXES: dict[str, tuple[str, ...]] = {
    "furnishing": ("empty", "desks", "mesh"),
    "medium": ("none", "homogeneous", "grid", "mixture", "mie"),
    "spectral": ("off", "on"),
    "surfaces": ("lambert", "phong", "mirror"),
    "luminaire": ("lambertian", "ies"),
    "algorithm": ("auto", "1", "2", "3", "4", "5"),
    "output": ("links", "map"),
    "receivers": ("1", "9", "40"),
    "extreme": (
        "none",
        "reflectance 0.99",
        "g +0.999",
        "g -0.999",
        "sigma -> 0",
        "optical depth 30",
        "FOV 1 deg",
        "area 1e-8 m2",
        "Tx-Rx 1 mm",
    ),
}

#: Extremes that set the smoke's coefficients or phase function: only with a homogeneous or grid medium.
MEDIUM_EXTREMES = ("g +0.999", "g -0.999", "sigma -> 0", "optical depth 30")

#: Extremes where a cell may hold without the power to see a 10 % error, when the comparison's combined relative
#: error is above 5 % (the result says how wide its error bar is): forward-only algorithms with a 1 deg FOV,
#: the scattered light at optical depth 30.
IMPRECISE_OK = ("FOV 1 deg", "optical depth 30")

#: Paths per source device of a cell's run and of its reference; a cell without power runs again with 4x.
PATHS = 4096
#: ... and with 40 receivers (runs from the receivers trace 40x as many paths; the best-measured link gives the power).
PATHS_40 = 1024
#: Extremes where paths from the transmitter cannot see what the receiver sees (FOV 1 deg: a 1 deg cone;
#: 1 mm below a ceiling light: the ceiling within a few mm of the receiver), so the reference of an algorithm
#: 1 or 5 cell is a second run from the receiver side (another seed) rather than a forward run
#: (`test_matrix.py::test_forward_misses_*` holds what forward runs report there).
BACKWARD_ONLY = ("FOV 1 deg", "Tx-Rx 1 mm")


def forbidden(a: tuple[str, str], b: tuple[str, str]) -> bool:
    """Whether the two (axis, value) choices cannot be in one cell (the extremes of the smoke need smoke)."""
    pair = dict([a, b])
    if len(pair) < 2:
        return False
    ext, med = pair.get("extreme"), pair.get("medium")
    if pair.get("spectral") == "on" and pair.get("surfaces") == "mirror":
        return True  # refused by design (REFUSED below): mirrors with spectral surfaces
    return ext in MEDIUM_EXTREMES and med is not None and med not in ("homogeneous", "grid")


def valid(cell: dict) -> bool:
    return not any(forbidden(a, b) for a, b in itertools.combinations(cell.items(), 2))


def cell_id(cell: dict) -> str:
    """A short stable name: furnishing/medium/spectral/surfaces/luminaire/algorithm/output/receivers/extreme."""
    c = cell
    spec = "spec" if c["spectral"] == "on" else "grey"
    return (
        f"{c['furnishing']}-{c['medium']}-{spec}-{c['surfaces']}-{c['luminaire']}-a{c['algorithm']}-"
        f"{c['output']}{c['receivers']}-{c['extreme'].replace(' ', '')}"
    )


#: Combinations too slow for the default run (tens of seconds: backward or two-sided runs from 40 receivers,
#: and algorithms 2-4 at optical depth 30); the slow tier has them.
SLOW_PAIRS = (
    (("receivers", "40"), ("algorithm", "2")),
    (("receivers", "40"), ("algorithm", "3")),
    (("receivers", "40"), ("algorithm", "4")),
    (("extreme", "optical depth 30"), ("algorithm", "2")),
    (("extreme", "optical depth 30"), ("algorithm", "3")),
    (("extreme", "optical depth 30"), ("algorithm", "4")),
)


def slow(cell: dict) -> bool:
    return any(all(cell.get(k) == v for k, v in pair) for pair in SLOW_PAIRS)


def covering(strength: int = 2, seed: int = 0, candidates: int = 40, axes=AXES, exclude=()) -> list[dict]:
    """A deterministic covering array: cells such that every valid combination of `strength` axis values
    appears in at least one cell (greedy, AETG-like: each new cell is the best of `candidates` random
    completions of a still uncovered combination)."""
    names = list(axes)
    rng = random.Random(seed)

    def bad(a, b):
        return forbidden(a, b) or (a, b) in exclude or (b, a) in exclude

    def combos(cell):
        return {
            tuple((n, cell[n]) for n in sub)
            for sub in itertools.combinations(names, strength)
            if all(n in cell for n in sub)
        }

    uncovered = set()
    for sub in itertools.combinations(names, strength):
        for values in itertools.product(*(axes[n] for n in sub)):
            choice = tuple(zip(sub, values))
            if not any(bad(a, b) for a, b in itertools.combinations(choice, 2)):
                uncovered.add(choice)
    cells: list[dict] = []
    while uncovered:
        start = sorted(uncovered)[rng.randrange(len(uncovered))] if len(uncovered) > 1 else next(iter(uncovered))
        best, best_gain = None, -1
        for _ in range(candidates):
            cell = dict(start)
            for n in rng.sample(names, len(names)):
                if n in cell:
                    continue
                options = []
                for v in axes[n]:
                    trial = {**cell, n: v}
                    if any(bad((n, v), (m, w)) for m, w in cell.items()):
                        continue
                    options.append((len(combos(trial) & uncovered), rng.random(), v))
                cell[n] = max(options)[2]
            gain = len(combos(cell) & uncovered)
            if gain > best_gain:
                best, best_gain = cell, gain
        assert best is not None
        cells.append({n: best[n] for n in names})
        uncovered -= combos(best)
    return cells


# --- scenes -----------------------------------------------------------------------------------------

ROOM = (5.0, 5.0, 3.0)
TX = (2.5, 2.5, 3.0)
DESKS = [
    {"name": "desk_a", "min": [0.4, 0.3, 0.7], "max": [2.0, 1.0, 0.74], "reflectance": 0.5},
    {"name": "desk_b", "min": [3.0, 3.8, 0.7], "max": [4.6, 4.5, 0.74], "reflectance": 0.5},
]


def _box_mesh(lo, hi) -> tuple[list, list]:
    """Vertices and outward triangles of an axis-aligned box (a mesh a user would export from CAD)."""
    x0, y0, z0 = lo
    x1, y1, z1 = hi
    v = [[x, y, z] for x in (x0, x1) for y in (y0, y1) for z in (z0, z1)]
    quads = [(0, 1, 3, 2), (4, 6, 7, 5), (0, 4, 5, 1), (2, 3, 7, 6), (0, 2, 6, 4), (1, 5, 7, 3)]
    faces = [t for a, b, c, d in quads for t in ((a, b, c), (a, c, d))]
    return v, faces


def _mesh() -> dict:
    """A cabinet as a closed box mesh plus a tilted reflecting panel (two triangles) hanging in the room."""
    v, f = _box_mesh((3.6, 0.2, 0.0), (4.6, 1.0, 1.6))
    panel = [[0.5, 3.5, 2.2], [1.7, 3.5, 2.6], [1.7, 4.5, 2.6], [0.5, 4.5, 2.2]]
    n = len(v)
    f += [(n, n + 1, n + 2), (n, n + 2, n + 3)]
    return {"vertices": v + panel, "faces": [list(t) for t in f], "reflectance": 0.6}


def _ies_base64() -> str:
    return base64.b64encode((EXAMPLES / "downlight_batwing.ies").read_bytes()).decode()


def _medium(kind: str, extreme: str) -> dict | None:
    g = {"g +0.999": 0.999, "g -0.999": -0.999}.get(extreme, 0.7)
    sigma_a, sigma_s = 0.05, 0.2
    if extreme == "sigma -> 0":
        sigma_a, sigma_s = 1e-9, 1e-9
    elif extreme == "optical depth 30":
        sigma_a, sigma_s = 2.0, 8.0
    if kind == "none":
        return None
    if kind == "homogeneous":
        return {"type": "homogeneous", "sigma_a": sigma_a, "sigma_s": sigma_s, "phase": {"type": "hg", "g": g}}
    if kind == "grid":
        # denser under the ceiling (the fire case of examples/smoke_grid.json), 1 x 1 x 3 cells
        scale = [0.5, 1.0, 1.5]
        return {
            "type": "grid",
            "min": [0, 0, 0],
            "max": list(ROOM),
            "shape": [1, 1, 3],
            "sigma_a": [sigma_a * s for s in scale],
            "sigma_s": [sigma_s * s for s in scale],
            "phase": {"type": "hg", "g": g},
        }
    if kind == "mixture":
        return {
            "type": "homogeneous",
            "sigma_a": sigma_a,
            "sigma_s": sigma_s,
            "phase": {
                "type": "mixture",
                "components": [
                    {"weight": 0.7, "phase": {"type": "hg", "g": 0.9}},
                    {"weight": 0.3, "phase": {"type": "rayleigh"}},
                ],
            },
        }
    if kind == "mie":  # the soot of examples/soot_room_light.json
        return {
            "type": "particles",
            "mass_concentration": 5e-5,
            "particle_density": 1800.0,
            "particles": {
                "distribution": "lognormal",
                "geometric_mean_diameter": 1.5e-7,
                "geometric_std": 1.8,
                "refractive_index": {"real": 1.57, "imag": 0.56},
                "wavelength": 8.5e-7,
            },
        }
    raise ValueError(kind)


def _surfaces(kind: str, extreme: str, spectral: bool) -> dict:
    rho = 0.99 if extreme == "reflectance 0.99" else None
    walls: float | dict = rho or 0.8
    if spectral and rho is None:
        walls = {"type": "spectral", "reflectance": {"type": "named", "name": "white_paint"}}
    refl: dict = {"floor": rho or 0.3, "ceiling": rho or 0.8, "walls": walls}
    if kind == "phong":
        refl["floor"] = {"type": "phong", "reflectance": rho or 0.3, "diffuse_fraction": 0.6, "exponent": 30}
    elif kind == "mirror":
        refl["wall_x_max"] = {"type": "mirror", "reflectance": rho or 0.85, "diffuse_fraction": 0.1}
    return refl


def _receiver_points(n: int, extreme: str) -> list[tuple[float, float, float]]:
    """n receivers at desk height (0.85 m), on a regular grid; with `Tx-Rx 1 mm` the first hangs 1 mm below Tx."""
    nx, ny = {1: (1, 1), 9: (3, 3), 40: (8, 5)}[n]
    xs = [1.2] if nx == 1 else list(np.linspace(0.75, 4.25, nx))
    ys = [1.6] if ny == 1 else list(np.linspace(1.25, 3.75, ny))
    pts = [(float(x), float(y), 0.85) for x in xs for y in ys]
    if extreme == "Tx-Rx 1 mm":
        pts[0] = (TX[0], TX[1], TX[2] - 1e-3)
    return pts


def scene(cell: dict, seed: int = 1, paths: int = PATHS) -> dict:
    """The scene document of a cell (a plain dict, as a user would write it)."""
    ext = cell["extreme"]
    spectral = cell["spectral"] == "on"
    n = int(cell["receivers"])
    fov = 1.0 if ext == "FOV 1 deg" else 90.0
    area = 1e-8 if ext == "area 1e-8 m2" else 1e-4
    device = {"area": area, "fov_deg": fov}
    if spectral:
        device["responsivity"] = {"type": "named", "name": "silicon_pin"}
    tx: dict = {"id": "tx", "position": list(TX), "normal": [0, 0, -1], "power": 1.0}
    if cell["luminaire"] == "ies":
        tx["photometry"] = {"data_base64": _ies_base64(), "format": "ies"}
    else:
        tx["lambertian_order"] = 1
    if spectral:
        tx["spectrum"] = {"type": "named", "name": "white_led_cool"}
    doc: dict = {
        "name": f"matrix cell {cell_id(cell)}",
        "room": {"size": list(ROOM), "reflectance": _surfaces(cell["surfaces"], ext, spectral)},
        "transmitters": [tx],
    }
    if cell["furnishing"] == "desks":
        doc["furniture"] = copy.deepcopy(DESKS)
    elif cell["furnishing"] == "mesh":
        doc["meshes"] = [_mesh()]
    pts = _receiver_points(n, ext)
    if cell["output"] == "links" or ext == "Tx-Rx 1 mm":
        doc["receivers"] = [
            {"id": f"rx{i}", "position": list(p), "normal": [0, 0, 1], **device} for i, p in enumerate(pts)
        ]
    if cell["output"] == "map":
        nx, ny = {1: (1, 1), 9: (3, 3), 40: (8, 5)}[n]
        grid = {"id_prefix": "plane", "origin": [0.75, 1.25, 0.85], "spacing": 0.5, "normal": [0, 0, 1], **device}
        grid["size"] = [0.5 * (nx - 1), 0.5 * (ny - 1)]
        if ext == "Tx-Rx 1 mm":  # one explicit receiver 1 mm from Tx beside the grid
            doc["receivers"] = doc["receivers"][:1]
        doc["receiver_grids"] = [grid]
        doc["outputs"] = {"cir": True}
    medium = _medium(cell["medium"], ext)
    if medium is not None:
        doc["medium"] = medium
    if spectral:
        doc["spectral"] = {"band_edges": [400e-9, 500e-9, 600e-9, 700e-9]}
    sim: dict = {"paths": paths, "seed": seed}
    if cell["algorithm"] != "auto":
        sim.update(algorithm=int(cell["algorithm"]), max_reflections=3, time_bin_s=1e-9, t_max_s=1e-7)
        if cell["algorithm"] == "5":
            sim["max_scattering"] = 3
        if cell["algorithm"] in ("2", "3", "4") and scatters(cell) and not swappable(cell):
            sim["max_reflections"] = 0  # where the families coincide with algorithm 5's (reference_doc)
    doc["simulation"] = sim
    return doc


def scatters(cell: dict) -> bool:
    """Whether the cell's smoke scatters (sigma -> 0 counts as vacuum)."""
    return cell["medium"] != "none" and cell["extreme"] != "sigma -> 0"


def swappable(cell: dict) -> bool:
    """Reciprocity holds for swapped devices: Lambertian m = 1 transmitter and FOV 90 deg."""
    return cell["luminaire"] == "lambertian" and cell["extreme"] != "FOV 1 deg"


# --- running and checking ---------------------------------------------------------------------------


@dataclass
class Outcome:
    cell: dict
    status: str  # pass | refused | flagged | fail
    message: str = ""
    reference: str = ""
    z_max: float = float("nan")
    power: bool = False
    links: int = 0
    h0: float = float("nan")  # link 0's (or the first non-zero link's) H0
    h0_rel_stderr: float = float("nan")
    ref_h0: float = float("nan")
    algorithm: int | None = None  # the algorithm that ran (auto resolved)
    combined_rel_stderr: float = float("nan")  # sqrt(se_a^2 + se_b^2) / max(a, b) of that link
    warnings: list[str] = field(default_factory=list)
    seconds: float = 0.0

    @property
    def id(self) -> str:
        return cell_id(self.cell)


def one_sentence(message: str) -> bool:
    """A refusal a user can read: one sentence (an engine refusal), or the validator's "the scene has N
    problem(s):" followed by one located sentence per problem; no traceback, no line over 400 characters."""
    lines = message.strip().splitlines()
    if not lines or "Traceback" in message or 'File "' in message or any(len(ln) > 400 for ln in lines):
        return False
    if len(lines) == 1:
        return True
    head = lines[0]
    return head.startswith("the scene has ") and head.endswith(":") and len(lines) == 1 + int(head.split()[3])


def _gains(result) -> tuple[np.ndarray, np.ndarray]:
    h = np.array([np.nan if lk.dc_gain is None else lk.dc_gain for lk in result.links], float)
    se = np.array([np.nan if lk.dc_gain_stderr is None else lk.dc_gain_stderr for lk in result.links], float)
    return h, se


def _z(a, sa, b, sb) -> np.ndarray:
    """Per-link z; equal values (both zero, or deterministic LOS-only runs) give 0."""
    sigma = np.hypot(sa, sb)
    diff = np.abs(a - b)
    tiny = diff <= 1e-9 * np.maximum(np.abs(a), np.abs(b))
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(tiny, 0.0, diff / sigma)


def reference_doc(cell: dict, doc: dict, result) -> tuple[dict, str, list[int] | None]:
    """(reference scene, what it is, which of the cell's links it estimates: None = all, in order)."""
    ref = copy.deepcopy(doc)
    sim = ref["simulation"]
    sim["seed"] = doc["simulation"]["seed"] + 1000
    alg = int(result.algorithm)
    if cell["algorithm"] == "auto":
        sim.update(max_reflections=1000, max_scattering=1000 if scatters(cell) else None)
        sim.update(time_bin_s=1e-9, t_max_s=2e-7)
        if sim["max_scattering"] is None:
            del sim["max_scattering"]
        # H0 is compared, not the CIR: no CIR split by order at K = S = 1000 (links x 10^6 orders x bins
        # is past the memory budget); the automatic K does the same past the pilot's 40 orders
        ref.setdefault("outputs", {})["cir_by_order"] = False
    first = result.links[0].direction
    other = "backward" if first in ("forward", "both") else "forward"
    if cell["extreme"] in BACKWARD_ONLY:
        other = "backward"  # a replicate from the receiver side (another seed): see BACKWARD_ONLY
    if not scatters(cell):
        ref.pop("medium", None)
        sim.update(algorithm=1, direction=other)
        sim.pop("max_scattering", None)
        what = f"algorithm 1 {other}" + (" in vacuum" if cell["medium"] != "none" else "")
        return ref, what, None
    if alg in (1, 5):
        sim.update(algorithm=alg, direction=other)
        return ref, f"algorithm {alg} {other}", None
    if swappable(cell):
        swap = {2: 3, 3: 2, 4: 4}[alg]
        rx = result.receivers[0] if result.receivers else None
        pos = list(rx.position) if rx is not None else doc["receivers"][0]["position"]
        normal = list(rx.normal) if rx is not None else [0, 0, 1]
        dev = doc["receivers"][0] if doc.get("receivers") else doc["receiver_grids"][0]
        tx = doc["transmitters"][0]
        new_tx = {"id": "tx", "position": pos, "normal": normal, "power": 1.0, "lambertian_order": 1}
        if "spectrum" in tx:
            new_tx["spectrum"] = tx["spectrum"]
        new_rx = {"id": "rx", "position": tx["position"], "normal": tx["normal"], "area": dev["area"], "fov_deg": 90}
        if "responsivity" in dev:
            new_rx["responsivity"] = dev["responsivity"]
        ref["transmitters"], ref["receivers"] = [new_tx], [new_rx]
        ref.pop("receiver_grids", None)
        ref.pop("outputs", None)
        sim["algorithm"] = swap
        return ref, f"algorithm {swap}, devices swapped", [0]
    sim.update(algorithm=5, max_scattering=2 if alg == 4 else 1, max_reflections=0)
    return ref, f"algorithm 5 K = 0, S <= {sim['max_scattering']}", None


def _los_closed_form(cell: dict, doc: dict, result) -> float:
    """Largest relative difference of the links' LOS gains from the closed form (nan: not applicable)."""
    from tests.reference import los_gain

    if (
        cell["furnishing"] != "empty"
        or cell["luminaire"] != "lambertian"
        or cell["medium"] not in ("none", "homogeneous", "mixture")
    ):
        return float("nan")
    sigma_t = 0.0
    if "medium" in doc:
        sigma_t = doc["medium"]["sigma_a"] + doc["medium"]["sigma_s"]
    tx = doc["transmitters"][0]
    worst = 0.0
    for link, rx in zip(result.links, result.receivers):
        if link.los_gain is None:
            continue
        fov = (doc.get("receivers") or doc["receiver_grids"])[0]["fov_deg"]
        area = (doc.get("receivers") or doc["receiver_grids"])[0]["area"]
        h, _ = los_gain(
            tx["position"], tx["normal"], 1.0, rx.position, rx.normal, area, math.radians(fov), sigma_t=sigma_t
        )
        if h == 0 and link.los_gain == 0:
            continue
        worst = max(worst, abs(link.los_gain - h) / max(h, 1e-300))
    return worst


def _refusal(err: Exception) -> str | None:
    from owcsim.docs import InputError
    from owcsim.engine.core.errors import EngineError

    if isinstance(err, (InputError, EngineError)) and one_sentence(str(err)):
        return str(err).strip()
    return None


def run(cell: dict, seed: int = 1, paths: int = PATHS) -> Outcome:
    """Run a cell and its reference through owcsim.simulate and judge it (module docstring); a cell that
    passes without the power to see a 10 % error runs once more with 4x the paths."""
    t0 = time.perf_counter()
    if cell["receivers"] == "40" and paths == PATHS:
        paths = PATHS_40
    out = _attempt(cell, seed, paths)
    if out.status in ("pass", "flagged") and not out.power and out.z_max <= Z_MAX:
        out = _attempt(cell, seed, 4 * paths)
    out.seconds = time.perf_counter() - t0
    return out


def _attempt(cell: dict, seed: int, paths: int) -> Outcome:
    import owcsim

    t0 = time.perf_counter()
    doc = scene(cell, seed=seed, paths=paths)
    out = Outcome(cell=cell, status="fail")
    try:
        result = owcsim.simulate(doc)
    except Exception as err:  # noqa: BLE001 - every exception is judged: a refusal or a failure
        why = _refusal(err)
        out.status = "refused" if why else "fail"
        out.message = why or f"{type(err).__name__}: {err}"
        out.seconds = time.perf_counter() - t0
        return out
    out.warnings = list(result.warnings)
    out.algorithm = int(result.algorithm)
    out.links = len(result.links)
    h, se = _gains(result)
    if not (np.all(np.isfinite(h[~np.isnan(h)])) and np.all(np.isfinite(se[~np.isnan(h)]))):
        out.message = "non-finite H0 or standard error"
        return out
    if np.any(h[~np.isnan(h)] < 0) or np.any(se[~np.isnan(h)] < 0):
        out.message = "negative H0 or standard error"
        return out
    los = _los_closed_form(cell, doc, result)
    if los > 1e-6:
        out.message = f"LOS gain off the closed form by {los:.2e} (relative)"
        return out
    ref_doc, out.reference, subset = reference_doc(cell, doc, result)
    if subset is not None:  # one swapped link: cheap, so 4x the paths (the cell's error dominates the comparison)
        ref_doc["simulation"]["paths"] = 4 * paths
    try:
        ref = owcsim.simulate(ref_doc)
    except Exception as err:  # noqa: BLE001
        out.message = f"reference ({out.reference}) raised {type(err).__name__}: {err}"
        out.seconds = time.perf_counter() - t0
        return out
    b, sb = _gains(ref)
    if subset is not None:
        h, se = h[subset], se[subset]
    keep = ~(np.isnan(h) | np.isnan(b))
    h, se, b, sb = h[keep], se[keep], b[keep], sb[keep]
    z = _z(h, se, b, sb)
    planted = _z(h * (1 + PLANTED), se * (1 + PLANTED), b, sb)
    out.z_max = float(np.max(z)) if len(z) else 0.0
    out.power = bool(len(z) and np.max(planted) > Z_MAX)
    main = int(np.argmax(h > 0)) if np.any(h > 0) else 0
    if len(h):
        out.h0, out.ref_h0 = float(h[main]), float(b[main])
        out.h0_rel_stderr = float(se[main] / h[main]) if h[main] > 0 else float("nan")
        out.combined_rel_stderr = float(np.hypot(se[main], sb[main]) / max(h[main], b[main], 1e-300))
    out.seconds = time.perf_counter() - t0
    warned = any("unreliable error bar" in w for w in out.warnings)
    if out.z_max <= Z_MAX and not out.power and warned:  # it could not see a 10 % error, and the run said so
        out.status = "flagged"
        out.message = (
            f"z = {out.z_max:.1f} against {out.reference}, no power to see a 10 % error, and the result warns "
            "the error bar is unreliable"
        )
    elif out.z_max <= Z_MAX:
        out.status = "pass"
    elif warned:
        out.status = "flagged"
        out.message = f"z = {out.z_max:.1f} against {out.reference}, and the result warns the error bar is unreliable"
    else:
        out.message = f"z = {out.z_max:.1f} against {out.reference} (H0 {out.h0:.4e} vs {out.ref_h0:.4e})"
    return out


# --- the tiers --------------------------------------------------------------------------------------


#: Cells of the default-run tier.
FAST_CELLS = 14


def anchor_cells() -> list[dict]:
    """The plain cases every tier holds: the empty room, no extreme, one receiver; algorithm 1 without smoke
    and algorithms 2, 4, 5 in smoke (the covering cells are mostly at an extreme, where error bars are wide;
    these see a 10 % error of one estimator side in the diffuse part)."""
    base = dict(furnishing="empty", spectral="off", surfaces="lambert", luminaire="lambertian", output="links")
    return [
        dict(base, medium=medium, algorithm=alg, receivers="1", extreme="none")
        for medium, alg in (("none", "1"), ("homogeneous", "2"), ("homogeneous", "4"), ("homogeneous", "5"))
    ]


def fast_cells() -> list[dict]:
    """The default-run tier: the first FAST_CELLS cells of a pairwise covering array without SLOW_PAIRS (the
    greedy array puts the cells that cover the most pairs first); every value of every axis is in it."""
    cells = covering(strength=2, seed=0, exclude=SLOW_PAIRS)
    fast = cells[:FAST_CELLS] + anchor_cells()
    for axis, value in ((a, v) for a in AXES for v in AXES[a]):
        if not any(c[axis] == value for c in fast):
            fast.append(next(c for c in cells if c[axis] == value))
    return fast


def full_cells() -> list[dict]:
    """The slow tier: a pairwise covering array of all axes (every valid pair of values in some cell), and
    every extreme with every algorithm in the base scene (empty room, smoke where the extreme needs it)."""
    cells = covering(strength=2, seed=1)
    base = dict(furnishing="empty", spectral="off", surfaces="lambert", luminaire="lambertian", output="links")
    for ext, alg in itertools.product(AXES["extreme"], AXES["algorithm"]):
        medium = "homogeneous" if ext in MEDIUM_EXTREMES or alg in ("2", "3", "4") else "none"
        cells.append(dict(base, medium=medium, algorithm=alg, receivers="1", extreme=ext))
    return [{n: c[n] for n in AXES} for c in cells]


def extreme_cells() -> list[dict]:
    """One cell per extreme, as a new user would first try it: the empty room, a Lambertian lamp, one receiver,
    automatic settings; homogeneous smoke (HG g = 0.7 unless the extreme sets g) for the smoke's extremes."""
    base = dict(furnishing="empty", spectral="off", surfaces="lambert", luminaire="lambertian", output="links")
    return [
        dict(base, medium="homogeneous" if e in MEDIUM_EXTREMES else "none", algorithm="auto", receivers="1", extreme=e)
        for e in AXES["extreme"]
    ]


def table(outcomes: list[Outcome]) -> str:
    """The markdown table of docs/extremes.md: what each extreme gave, against what, and what it said."""
    lines = [
        "| extreme | smoke | ran | result | H0 | rel. SE | reference | H0 reference | z | warnings |",
        "|---|---|---|---|---|---|---|---|---|---|",
    ]
    for o in outcomes:
        c = o.cell
        ran = o.reference and o.algorithm or "-"
        h0 = f"{o.h0:.4g}" if np.isfinite(o.h0) else "-"
        ref = f"{o.ref_h0:.4g}" if np.isfinite(o.ref_h0) else "-"
        rel = f"{o.h0_rel_stderr:.2%}" if np.isfinite(o.h0_rel_stderr) else "-"
        z = f"{o.z_max:.2f}" if np.isfinite(o.z_max) else "-"
        status = o.status if o.status != "fail" or np.isfinite(o.z_max) else f"fail: {o.message[:60]}"
        lines.append(
            f"| {c['extreme']} | {c['medium']} | {ran} | {status} | {h0} | {rel} | {o.reference or '-'} | {ref} "
            f"| {z} | {len(o.warnings)} |"
        )
    return "\n".join(lines)


def summary(outcomes: list[Outcome]) -> str:
    """Cells per status, and the largest z and the median relative standard error of the cells that held."""
    counts = {s: sum(o.status == s for o in outcomes) for s in ("pass", "refused", "flagged", "fail")}
    held = [o for o in outcomes if o.status == "pass"]
    zs = [o.z_max for o in held]
    rels = [o.h0_rel_stderr for o in held if np.isfinite(o.h0_rel_stderr)]
    return (
        f"{len(outcomes)} cells: {counts['pass']} hold, {counts['refused']} refused, {counts['flagged']} flagged, "
        f"{counts['fail']} fail; largest z of those that hold {max(zs, default=float('nan')):.2f}, "
        f"median relative standard error {float(np.median(rels)) if rels else float('nan'):.2%}, "
        f"{sum(o.power for o in held)} of {len(held)} would see a 10 % error"
    )


def _row(o: Outcome) -> str:
    return (
        f"{o.id:<60} {o.status:<8} z={o.z_max:5.2f} power={'y' if o.power else 'n'} comb={o.combined_rel_stderr:.2%} "
        f"H0={o.h0:.3e} rel={o.h0_rel_stderr:.2%} ref={o.ref_h0:.3e} {o.seconds:5.1f} s {o.message[:120]}"
    )


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--tier", choices=("fast", "full"), default="fast")
    p.add_argument("--count", action="store_true", help="print the number of cells and stop")
    p.add_argument("--table", action="store_true", help="run one cell per extreme and print docs/extremes.md's table")
    p.add_argument("--summary", action="store_true", help="print only the tier's summary line")
    p.add_argument("--only", help="run cells whose id contains this text")
    args = p.parse_args(argv)
    if args.table:
        print(table([run(c) for c in extreme_cells()]))
        return 0
    cells = fast_cells() if args.tier == "fast" else full_cells()
    if args.only:
        cells = [c for c in cells if args.only in cell_id(c)]
    if args.count:
        print(f"{len(cells)} cells")
        return 0
    outcomes = []
    for c in cells:
        outcomes.append(run(c))
        if not args.summary:
            print(_row(outcomes[-1]), flush=True)
    print(summary(outcomes))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
