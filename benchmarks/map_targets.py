"""Issue 24's map targets, each a whole `owcsim run` command, beside two deterministic references.

The room is examples/komine_map.json: 5 x 5 x 3 m (floor 0.3, walls and ceiling 0.8), 4 LED lamps
(Lambertian, semi-angle 70 deg) in one group, receivers facing up on a square grid at 0.85 m
(FOV 85 deg, 1 cm^2). Each owcsim case is the whole command `python -m owcsim run SCENE --out DIR`
(interpreter start-up, imports, the run, every file and plot written) in its own process; its wall
time, CPU time (user + sys: on a busy host the better guess of a quiet host's wall time) and peak
resident memory (that process's ru_maxrss, from os.wait4) are printed.

 (a) 50 x 50 points, every reflection order (automatic K), 1 % relative standard error per point: <= 20 s
 (b) the line-of-sight map (max_reflections 0), 50 x 50 points: <= 2 s
 (c) 100 x 100 points, every order, 1 % per point: <= 40 s and <= 1 GB
 (d) the exponent b of a least-squares fit log t = a + b log N over N = 10 x 10 ... 100 x 100 at 1 %: <= 0.8
 (e) two deterministic references of the same room, written here (no owcsim code): the textbook
     recursion (Barry et al. 1993: walls cut into patches, each patch a point element at its centre,
     reflection orders k <= 3) and a radiosity solve of every order (Goral et al. 1984; Cohen & Wallace
     1993, ch. 2: patches with n x n sub-points, M = rho (E + F M)), each with its time for the maps of
     (a) and (c) and its DC-gain deviation from owcsim's (median and worst over the points, in units of
     owcsim's standard error and in %).

DC gain of the group channel at a receiver (the lamps' powers are equal: the mean of the 4 links'):
    H = sum_i w_i [ H_los,i + A sum_j M_ij / pi  int_j cos th_j cos psi / d^2 rect(psi <= FOV) dA ],
    H_los,i = (m + 1) / (2 pi) cos^m phi  A cos psi / d^2 rect(psi <= FOV),  m = -ln 2 / ln cos(70 deg),
with M_ij the exitance of patch j [W/m^2 per W of lamp i]: E_j = (m + 1) / (2 pi) cos^m phi cos th_j / d^2,
and M = sum_{k=1..3} (rho F)^(k-1) rho E (recursion) or (I - rho F)^-1 rho E (radiosity), F[j, l] the form
factor from patch j to patch l. Both references are exact up to their discretisation (which the
deviations show); neither has occlusion to handle (an empty room).

`--baseline COMMIT` runs the same owcsim cases on that commit's tree, alternately with this tree's in the
same run: a `git worktree` at /tmp/owcsim-baseline-SHA with its own venv (scripts/bootstrap there; made
when missing, a few minutes). `--python PATH`: measure that interpreter's install instead of this one (the
row is named by its tree's folder). `--quick`: small grids and 5 % (a test that the script runs).
The commands run with bytecode cached (PYTHONDONTWRITEBYTECODE dropped for them), as an installed owcsim.
Run: .venv/bin/python benchmarks/map_targets.py [--quick] [--baseline a1746be] [--python PATH] [--cases a,b,c,d]
     [--no-references | --references-only]
"""

from __future__ import annotations

import argparse
import json
import math
import os
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
EXAMPLE = ROOT / "examples" / "komine_map.json"


# --- the scene ----------------------------------------------------------------------------------
def komine(side: int, **simulation) -> dict:
    """The example's document with a side x side grid over the same 4.9 m square, and `simulation`."""
    doc = json.loads(EXAMPLE.read_text())
    g = doc["receiver_grids"][0]
    g["spacing"] = g["size"][0] / (side - 1)
    doc["simulation"] = {"seed": 1, **simulation}
    return doc


@dataclass(frozen=True)
class Room:
    """The empty box [0, size] with a reflectance per face, Lambertian lamps (positions, normals, order m,
    weights P_i / sum P), and the receivers' normal, FOV [rad] and area [m^2]."""

    size: tuple[float, float, float]
    rho: dict[str, float]  # floor, ceiling, walls
    lamps: np.ndarray  # (L, 3)
    lamp_normals: np.ndarray  # (L, 3)
    m: np.ndarray  # (L,)
    weights: np.ndarray  # (L,)
    rx_normal: np.ndarray  # (3,)
    fov: float
    area: float

    @classmethod
    def of(cls, doc: dict) -> Room:
        txs, g = doc["transmitters"], doc["receiver_grids"][0]
        m = [-math.log(2) / math.log(math.cos(math.radians(t["half_power_semi_angle_deg"]))) for t in txs]
        power = np.array([t["power"] for t in txs], float)
        n = np.array(g["normal"], float)
        return cls(
            tuple(doc["room"]["size"]),
            dict(doc["room"]["reflectance"]),
            np.array([t["position"] for t in txs], float),
            np.array([t["normal"] for t in txs], float),
            np.array(m),
            power / power.sum(),
            n / np.linalg.norm(n),
            math.radians(g["fov_deg"]),
            float(g["area"]),
        )


def grid_points(doc: dict) -> np.ndarray:
    """(N, 3) receiver positions of the document's grid, in the engine's order (i along u, then j)."""
    g = doc["receiver_grids"][0]
    n = [int(math.floor(s / g["spacing"] + 1e-9)) + 1 for s in g["size"]]
    i, j = np.meshgrid(np.arange(n[0]), np.arange(n[1]), indexing="ij")
    o = np.array(g["origin"], float)
    return o + g["spacing"] * np.stack([i.ravel(), j.ravel(), np.zeros(i.size)], axis=1)


# --- the references -----------------------------------------------------------------------------
def patches(room: Room, patch: float, n_sub: int):
    """Sub-points (P, n_sub^2, 3), inward normals (P, 3), reflectances (P,), sub-point areas dA (P,) and corners
    (P, 4, 3): each face cut into round(edge / patch) equal parts per edge, each part into n_sub x n_sub
    midpoints."""
    lx, ly, lz = room.size
    ex, ey, ez = np.eye(3)
    faces = [
        (np.zeros(3), lx * ex, ly * ey, ez, room.rho["floor"]),
        (lz * ez, lx * ex, ly * ey, -ez, room.rho["ceiling"]),
        (np.zeros(3), lx * ex, lz * ez, ey, room.rho["walls"]),
        (ly * ey, lx * ex, lz * ez, -ey, room.rho["walls"]),
        (np.zeros(3), ly * ey, lz * ez, ex, room.rho["walls"]),
        (lx * ex, ly * ey, lz * ez, -ex, room.rho["walls"]),
    ]
    pts, nrm, rho, d_a, corners = [], [], [], [], []
    s = (np.arange(n_sub) + 0.5) / n_sub
    square = np.array([[0, 0], [1, 0], [1, 1], [0, 1]])
    for o, u, v, n, r in faces:
        nu, nv = (max(1, round(np.linalg.norm(e) / patch)) for e in (u, v))
        i, j = np.meshgrid(np.arange(nu), np.arange(nv), indexing="ij")
        a = (i.reshape(-1, 1, 1) + s[None, :, None]) / nu  # (P_f, n_sub, 1)
        b = (j.reshape(-1, 1, 1) + s[None, None, :]) / nv  # (P_f, 1, n_sub)
        p = o + a[..., None] * u + b[..., None] * v  # (P_f, n_sub, n_sub, 3)
        pts.append(p.reshape(nu * nv, n_sub * n_sub, 3))
        nrm.append(np.tile(n, (nu * nv, 1)))
        rho.append(np.full(nu * nv, r))
        d_a.append(np.full(nu * nv, np.linalg.norm(u) * np.linalg.norm(v) / (nu * nv * n_sub**2)))
        ca = (i.reshape(-1, 1) + square[None, :, 0]) / nu  # (P_f, 4)
        cb = (j.reshape(-1, 1) + square[None, :, 1]) / nv
        corners.append(o + ca[..., None] * u + cb[..., None] * v)
    cat = np.concatenate
    return cat(pts), cat(nrm), cat(rho), cat(d_a), cat(corners)


def _direct(room: Room, pts: np.ndarray, nrm: np.ndarray) -> np.ndarray:
    """(L, P) mean irradiance of each patch from each lamp per watt: (m + 1) / (2 pi) cos^m phi cos th / d^2."""
    d = pts[None] - room.lamps[:, None, None, :]  # (L, P, S, 3)
    r2 = (d * d).sum(-1)
    r2 = np.where(r2 > 0, r2, np.inf)  # a sub-point on a lamp (in the lamp's plane: no light) adds 0
    r = np.sqrt(r2)
    cos_phi = np.clip((d * room.lamp_normals[:, None, None, :]).sum(-1) / r, 0.0, None)
    cos_th = np.clip(-(d * nrm[None, :, None, :]).sum(-1) / r, 0.0, None)
    m = room.m[:, None, None]
    return ((m + 1) / (2 * math.pi) * cos_phi**m * cos_th / r2).mean(axis=2)


def _form_factors(pts: np.ndarray, nrm: np.ndarray, d_a: np.ndarray) -> np.ndarray:
    """F[j, l] = mean over j's sub-points of sum over l's of cos th_j cos th_l / (pi d^2) dA_l, in blocks of rows."""
    n_p, n_s = pts.shape[:2]
    rows = max(1, int(4e6 // (n_s * n_s * n_p)))  # about 100 MB of temporaries per block
    flat, normals = pts.reshape(-1, 3), np.repeat(nrm, n_s, axis=0)
    f = np.empty((n_p, n_p))
    for j0 in range(0, n_p, rows):  # a loop over blocks of patches; each block one array operation
        pj, nj = pts[j0 : j0 + rows], nrm[j0 : j0 + rows]
        d = [flat[None, None, :, c] - pj[:, :, None, c] for c in range(3)]  # 3 x (B, S, P S)
        r2 = d[0] * d[0] + d[1] * d[1] + d[2] * d[2]
        same = r2 < 1e-18
        r2[same] = 1.0
        cj = sum(d[c] * nj[:, None, None, c] for c in range(3))
        cl = -sum(d[c] * normals[None, None, :, c] for c in range(3))
        k = np.where(same | (cj <= 0) | (cl <= 0), 0.0, cj * cl / (math.pi * r2 * r2))
        f[j0 : j0 + rows] = k.mean(axis=1).reshape(len(pj), n_p, n_s).sum(axis=2) * d_a[None, :]
    return f


def _to_receivers(room: Room, rx: np.ndarray, pts: np.ndarray, nrm: np.ndarray, d_a: np.ndarray, chunk: int = 64):
    """(N, P) coupling A / pi sum over sub-points cos th_j cos psi / d^2 rect(psi <= FOV) dA of each patch."""
    out = np.empty((len(rx), len(pts)))
    cos_fov = math.cos(room.fov)
    for a in range(0, len(rx), chunk):
        d = rx[a : a + chunk, None, None, :] - pts[None]  # (B, P, S, 3)
        r2 = (d * d).sum(-1)
        r = np.sqrt(r2)
        cos_j = np.clip((d * nrm[None, :, None, :]).sum(-1) / r, 0.0, None)
        cos_psi = -(d @ room.rx_normal) / r
        k = np.where(cos_psi >= cos_fov, cos_j * cos_psi / r2, 0.0)
        out[a : a + chunk] = room.area / math.pi * k.sum(-1) * d_a[None, :]
    return out


def _to_receivers_exact(room: Room, rx: np.ndarray, pts, nrm, d_a, corners, chunk: int = 128) -> np.ndarray:
    """(N, P) coupling A F of each patch, F = int cos th_j cos psi / (pi d^2) dA over the part of the patch above
    the receiver's plane, in closed form (Lambert's contour integral, F = 1/(2 pi) sum_k g_k n . (u_k x u_k+1) /
    |u_k x u_k+1|, g_k the angle between the unit vectors u_k, u_k+1 to consecutive corners; Cohen & Wallace
    1993, sec. 4.9), less the band FOV < psi < 90 deg by the sub-points (cos psi < cos FOV there: a small term).
    Receivers facing up (+z) only: the patch is clipped at the receiver's height."""
    if not np.allclose(room.rx_normal, (0.0, 0.0, 1.0)):
        raise ValueError("the exact coupling clips patches at the receiver's height: receivers facing up only")
    out = np.empty((len(rx), len(pts)))
    cos_fov = math.cos(room.fov)
    top = corners[:, :, 2].max(axis=1)
    for a in range(0, len(rx), chunk):
        x = rx[a : a + chunk]
        c = np.broadcast_to(corners[None], (len(x), *corners.shape)).copy()  # (B, P, 4, 3)
        c[..., 2] = np.maximum(c[..., 2], x[:, None, None, 2])  # clipped at the receiver's plane
        r = c - x[:, None, None, :]
        u = r / np.maximum(np.linalg.norm(r, axis=-1, keepdims=True), 1e-300)
        w = np.roll(u, -1, axis=2)
        cross = np.cross(u, w)
        sin = np.linalg.norm(cross, axis=-1)
        angle = np.arctan2(sin, (u * w).sum(-1))
        term = np.where(sin > 1e-15, angle * cross[..., 2] / np.maximum(sin, 1e-300), 0.0)
        f = np.abs(term.sum(-1)) / (2 * math.pi) * (top[None, :] > x[:, None, 2])
        # the band outside the FOV, by the sub-points
        d = x[:, None, None, :] - pts[None]
        r2 = (d * d).sum(-1)
        rr = np.sqrt(r2)
        cos_j = np.clip((d * nrm[None, :, None, :]).sum(-1) / rr, 0.0, None)
        cos_psi = -(d @ room.rx_normal) / rr
        band = np.where((cos_psi > 0) & (cos_psi < cos_fov), cos_j * cos_psi / (math.pi * r2), 0.0).sum(-1) * d_a
        out[a : a + chunk] = room.area * (f - band)
    return out


def _los(room: Room, rx: np.ndarray) -> np.ndarray:
    """(N,) sum_i w_i (m + 1) / (2 pi) cos^m phi A cos psi / d^2 rect(psi <= FOV), closed form."""
    d = rx[None] - room.lamps[:, None, :]  # (L, N, 3)
    r2 = (d * d).sum(-1)
    r = np.sqrt(r2)
    cos_phi = np.clip((d * room.lamp_normals[:, None, :]).sum(-1) / r, 0.0, None)
    cos_psi = -(d @ room.rx_normal) / r
    m = room.m[:, None]
    h = (m + 1) / (2 * math.pi) * cos_phi**m * np.where(cos_psi >= math.cos(room.fov), cos_psi, 0.0) * room.area / r2
    return room.weights @ h


@dataclass(frozen=True)
class Reference:
    """A deterministic reference: patch size, sub-points, the orders it sums, whether F's rows are closed and
    whether the receivers gather in closed form (else by the sub-points)."""

    name: str
    patch: float  # [m]
    n_sub: int  # sub-points per patch edge
    orders: int | None  # reflection orders k <= orders; None: every order (a linear solve)
    closure: bool  # rows of F scaled to sum to 1 (a closed box)
    exact_gather: bool  # patch -> receiver in closed form (_to_receivers_exact)


RECURSION = Reference("recursion k <= 3 (Barry 1993)", 0.2, 1, 3, False, False)
RADIOSITY = Reference("radiosity, all orders", 0.25, 3, None, True, True)


def reference_dc_gain(ref: Reference, room: Room, rx: np.ndarray) -> np.ndarray:
    """(N,) H of the group channel at the receivers `rx` (module docstring)."""
    pts, nrm, rho, d_a, corners = patches(room, ref.patch, ref.n_sub)
    e = room.weights @ _direct(room, pts, nrm)  # (P,) the group's irradiance per watt
    f = _form_factors(pts, nrm, d_a)
    if ref.closure:
        f /= f.sum(axis=1, keepdims=True)
    if ref.orders is None:
        exitance = np.linalg.solve(np.eye(len(rho)) - rho[:, None] * f, rho * e)
    else:
        term = rho * e
        exitance = term.copy()
        for _ in range(ref.orders - 1):
            term = rho * (f @ term)
            exitance += term
    if ref.exact_gather:
        gather = _to_receivers_exact(room, rx, pts, nrm, d_a, corners)
    else:
        gather = _to_receivers(room, rx, pts, nrm, d_a)
    return _los(room, rx) + gather @ exitance


# --- owcsim runs --------------------------------------------------------------------------------
#: The commands' environment: bytecode cached (.pyc) as an installed owcsim runs, even where the caller set
#: PYTHONDONTWRITEBYTECODE (compiling owcsim's ~100 modules from source costs ~0.2-0.3 s a command).
ENV = {k: v for k, v in os.environ.items() if k != "PYTHONDONTWRITEBYTECODE"}


@dataclass
class Command:
    """One whole `owcsim run`: wall and CPU time [s], peak RSS [MB], and its group channels."""

    wall_s: float
    cpu_s: float
    peak_mb: float
    last_line: str
    dc_gain: np.ndarray  # (N,) NaN where missing
    stderr: np.ndarray
    positions: np.ndarray  # (N, 3) the receivers [m], as the result lists them


def run_owcsim(python: str, doc: dict) -> Command:
    """Run the document as a whole command in its own process (in a folder outside every source tree, so the
    interpreter runs its own install) and read its result.json."""
    with tempfile.TemporaryDirectory(prefix="owcsim-maptargets-") as tmp:
        scene, out = Path(tmp) / "scene.json", Path(tmp) / "out"
        scene.write_text(json.dumps(doc))
        with open(Path(tmp) / "stdout", "w+b") as so, open(Path(tmp) / "stderr", "w+b") as se:
            t = time.perf_counter()
            proc = subprocess.Popen(
                [python, "-m", "owcsim", "run", str(scene), "--out", str(out)], stdout=so, stderr=se, cwd=tmp, env=ENV
            )
            _, status, usage = os.wait4(proc.pid, 0)  # this child's own CPU time and peak RSS
            wall = time.perf_counter() - t
            proc.returncode = os.waitstatus_to_exitcode(status)
            so.seek(0), se.seek(0)
            stdout, stderr = so.read().decode(), se.read().decode()
        if proc.returncode:
            raise RuntimeError(f"owcsim run failed ({proc.returncode}): {stderr[-2000:]}")
        res = json.loads((out / "result.json").read_text())
    n = len(res["receivers"])
    h, err = np.full(n, np.nan), np.full(n, np.nan)
    for ch in res["channels"]:
        h[ch["receiver_index"]] = np.nan if ch["dc_gain"] is None else ch["dc_gain"]
        err[ch["receiver_index"]] = np.nan if ch["dc_gain_stderr"] is None else ch["dc_gain_stderr"]
    last = stdout.strip().splitlines()[-1].split(";")[0]
    pos = np.array([r["position"] for r in res["receivers"]], float)
    return Command(wall, usage.ru_utime + usage.ru_stime, usage.ru_maxrss / 1024, last, h, err, pos)


def baseline_python(rev: str) -> str:
    """The interpreter of a venv with commit `rev` installed (a git worktree under /tmp, made when missing)."""
    sha = subprocess.run(
        ["git", "-C", str(ROOT), "rev-parse", "--short", rev], check=True, capture_output=True, text=True
    ).stdout.strip()
    tree = Path(tempfile.gettempdir()) / f"owcsim-baseline-{sha}"
    if not tree.exists():
        subprocess.run(["git", "-C", str(ROOT), "worktree", "add", "--detach", str(tree), sha], check=True)
    python = tree / ".venv" / "bin" / "python"
    if not python.exists():
        print(f"making the baseline's venv in {tree} (scripts/bootstrap, a few minutes)", flush=True)
        subprocess.run([str(tree / "scripts" / "bootstrap")], check=True, cwd=tree, capture_output=True)
    return str(python)


# --- the report ---------------------------------------------------------------------------------
def fit_exponent(n: list[int], t: list[float]) -> float:
    """b of the least-squares fit log t = a + b log n."""
    return float(np.polyfit(np.log(n), np.log(t), 1)[0])


def deviation(ref: np.ndarray, run: Command) -> tuple[float, float, float, float]:
    """(median, worst) of (ref - H) / stderr and of 100 (ref - H) / H over the points with a value (worst: the
    largest in magnitude, with its sign)."""
    ok = np.isfinite(run.dc_gain) & np.isfinite(run.stderr) & (run.stderr > 0)
    z = (ref[ok] - run.dc_gain[ok]) / run.stderr[ok]
    pct = 100 * (ref[ok] - run.dc_gain[ok]) / run.dc_gain[ok]
    return float(np.median(z)), float(z[np.argmax(abs(z))]), float(np.median(pct)), float(pct[np.argmax(abs(pct))])


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="small grids at 5 %%: a test that the script runs")
    ap.add_argument("--baseline", default="", metavar="COMMIT", help="also run the owcsim cases on this commit")
    ap.add_argument("--python", help="interpreter of the install to measure (default: this one)")
    ap.add_argument("--no-references", action="store_true", help="skip (e)")
    ap.add_argument("--references-only", action="store_true", help="only (e), against no owcsim run")
    ap.add_argument("--cases", default="a,b,c,d", help="the owcsim cases to run, of a,b,c,d (default all)")
    args = ap.parse_args()
    quick = args.quick
    target = 0.05 if quick else 0.01
    side_a, side_b, side_c = (8, 8, 12) if quick else (50, 50, 100)
    sides_d = (4, 6, 8, 12) if quick else (10, 20, 50, 100)
    trees = (
        [("this tree", sys.executable)]
        if args.python is None
        else [(Path(args.python).parent.parent.parent.name, args.python)]
    )
    if args.baseline:
        sha = subprocess.run(
            ["git", "-C", str(ROOT), "rev-parse", "--short", args.baseline], check=True, capture_output=True, text=True
        ).stdout.strip()
        trees.append((f"baseline {sha}", baseline_python(sha)))
    docs = {
        "a": komine(side_a, target_rel_error=target),
        "b": komine(side_b, max_reflections=0),
        "c": komine(side_c, target_rel_error=target),
    }
    for side in sides_d:
        key = "a" if side == side_a else "c" if side == side_c else f"d{side}"
        docs.setdefault(key, komine(side, target_rel_error=target))
    cases = set(args.cases.split(","))
    wanted = {k for k in docs if k[0] in cases or ("d" in cases and k in ("a", "c"))}
    print(
        f"Komine room (examples/komine_map.json), 4 lamps in one group; whole `owcsim run` commands, "
        f"{target:.0%} per point; {time.strftime('%Y-%m-%d %H:%M')} UTC, {os.cpu_count()} cores, "
        f"load {os.getloadavg()[0]:.1f}",
        flush=True,
    )
    runs: dict[tuple[str, str], Command] = {}
    if not args.references_only:
        for key, doc in docs.items():
            if key not in wanted:
                continue
            for tree, python in trees:  # alternately: a change of load hits both trees alike
                r = runs[key, tree] = run_owcsim(python, doc)
                print(
                    f"  ran {key:>4} on {tree}: {r.wall_s:.1f} s, CPU {r.cpu_s:.1f} s, {r.peak_mb:.0f} MB "
                    f"({r.last_line})",
                    flush=True,
                )
        table(runs, trees, target, side_a, side_b, side_c, sides_d, docs)
    if not args.no_references:
        references(runs, trees, docs, quick, args.references_only)


def table(runs, trees, target, side_a, side_b, side_c, sides_d, docs) -> None:
    pct = f"{target:.0%}"
    rows = [
        ("a", f"(a) {side_a} x {side_a}, all orders, {pct}", 20.0, None),
        ("b", f"(b) {side_b} x {side_b}, line of sight", 2.0, None),
        ("c", f"(c) {side_c} x {side_c}, all orders, {pct}", 40.0, 1024.0),
    ]
    print(
        f"{'case':38s} {'tree':24s} {'time [s]':>9s} {'CPU [s]':>8s} {'target':>16s} {'met (time/CPU)':>15s} "
        f"{'peak [MB]':>10s}"
    )

    def yes(ok: bool) -> str:
        return "yes" if ok else "no"

    for key, label, t_max, mb_max in rows:
        for tree, _ in trees:
            if (key, tree) not in runs:
                continue
            r = runs[key, tree]
            mem = mb_max is None or r.peak_mb <= mb_max
            met = f"{yes(r.wall_s <= t_max and mem)}/{yes(r.cpu_s <= t_max and mem)}"
            goal = f"<= {t_max:g} s" + (f", {mb_max:g} MB" if mb_max else "")
            print(f"{label:38s} {tree:24s} {r.wall_s:9.2f} {r.cpu_s:8.2f} {goal:>16s} {met:>15s} {r.peak_mb:10.0f}")
    n = [s * s for s in sides_d]
    keys = ["a" if s == side_a else "c" if s == side_c else f"d{s}" for s in sides_d]
    label = f"(d) exponent, N = {n[0]:,d} ... {n[-1]:,d}"
    for tree, _ in trees:
        if any((k, tree) not in runs for k in keys):
            continue
        b_wall = fit_exponent(n, [runs[k, tree].wall_s for k in keys])
        b_cpu = fit_exponent(n, [runs[k, tree].cpu_s for k in keys])
        print(
            f"{label:38s} {tree:24s} {b_wall:9.2f} {b_cpu:8.2f} {'<= 0.8':>16s} "
            f"{yes(b_wall <= 0.8) + '/' + yes(b_cpu <= 0.8):>15s} {max(runs[k, tree].peak_mb for k in keys):10.0f}"
        )
        print(
            f"    {tree}: N -> time [s]: " + ", ".join(f"{x:,d}: {runs[k, tree].wall_s:.1f}" for x, k in zip(n, keys))
        )
    print(
        "  (time: wall time of the whole command; CPU: its user + sys time, the better estimate of a quiet host's"
        " wall time on a busy one; (d) prints the exponents fitted to each)"
    )


def references(runs, trees, docs, quick, references_only=False) -> None:
    room = Room.of(docs["a"])
    refs = (
        (Reference(RECURSION.name, 0.5, 1, 3, False, False), Reference(RADIOSITY.name, 0.5, 2, None, True, True))
        if quick
        else (RECURSION, RADIOSITY)
    )
    print("(e) deterministic references of the same room (this script, numpy): time, and (ref - owcsim) at the points")
    print(
        f"    {'reference':50s} {'points':>7s} {'time [s]':>9s} {'CPU [s]':>8s}   {'owcsim':24s} {'median z':>9s} "
        f"{'worst z':>9s} "
        f"{'median %':>9s} {'worst %':>9s}"
    )
    for ref in refs:
        for key in ("a", "c"):
            found = [(tree, runs[key, tree]) for tree, _ in trees if (key, tree) in runs]
            if not found and not references_only:
                continue
            rx = grid_points(docs[key])  # the points the runs report, when there are runs
            for _, r in found:
                if r.positions.shape != rx.shape:
                    raise RuntimeError(f"case {key}: the result has {len(r.positions)} receivers, not {len(rx)}")
                rx = r.positions
            t, c = time.perf_counter(), time.process_time()
            h = reference_dc_gain(ref, room, rx)
            el, el_cpu = time.perf_counter() - t, time.process_time() - c
            label = f"{ref.name} (patch {ref.patch:g} m, {ref.n_sub}x{ref.n_sub})"
            if not found:
                print(f"    {label:50s} {len(rx):7,d} {el:9.2f} {el_cpu:8.2f}")
            for tree, r in found:
                if not np.allclose(r.positions, rx):
                    raise RuntimeError(f"case {key}: {tree}'s receivers are not the others'")
                z_med, z_max, p_med, p_max = deviation(h, r)
                print(
                    f"    {label:50s} {len(rx):7,d} {el:9.2f} {el_cpu:8.2f}   {tree:24s} {z_med:9.2f} {z_max:9.2f} "
                    f"{p_med:9.2f} {p_max:9.2f}"
                )


if __name__ == "__main__":
    main()
