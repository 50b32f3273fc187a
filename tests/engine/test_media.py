"""Participating media (engine/media/media.py, regions.py, grid.py): depth, transmittance, free flight, schemas.

References are written here by hand (Beer-Lambert, slab lengths, sphere chords, cell sums)
or are exact distributions (exponential free flight); statistical checks use fixed seeds.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
import trimesh
from pydantic import ValidationError
from scipy import stats

from conftest import SEED, seeded_rng  # noqa: F401
from owcsim.engine.core.errors import SceneError
from owcsim.engine.media.grid import GridMedium
from owcsim.engine.media.media import HomogeneousMedium
from owcsim.engine.media.regions import MeshRegion
from owcsim.engine.media.registry import medium_from_spec
from owcsim.schemas import SceneSpec
from tests.scenes import room_doc

LO, HI = np.array([1.0, 0.0, -1.0]), np.array([2.0, 3.0, 1.0])  # a box region, not a unit cube


def _segments(n, rng, lo=-1.0, hi=4.0, max_len=6.0):
    o = rng.uniform(lo, hi, (n, 3))
    d = rng.normal(size=(n, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    return o, d, rng.uniform(0.0, max_len, n)


def _unit(*v):
    v = np.asarray(v, float)
    return v / np.linalg.norm(v)


def _box_mesh(lo, hi):
    return trimesh.creation.box(bounds=[lo, hi])


# --- Beer-Lambert and the box region ----------------------------------------------------------


def test_beer_lambert_on_known_segments():
    med = HomogeneousMedium(0.3, 0.2)
    o = np.zeros((4, 3))
    d = np.tile([0.0, 0.6, 0.8], (4, 1))
    L = np.array([0.0, 1.0, 2.5, 10.0])
    assert np.allclose(med.optical_depth(o, d, L), [0.0, 0.5, 1.25, 5.0], rtol=1e-15, atol=0)
    assert np.allclose(
        med.transmittance(o, d, L), [1.0, math.exp(-0.5), math.exp(-1.25), math.exp(-5.0)], rtol=1e-15, atol=0
    )
    assert med.bounds is None and med.albedo == pytest.approx(0.4)


# (origin, direction, length, expected length inside LO..HI = [1,2] x [0,3] x [-1,1])
BOX_CASES = [
    ((1.5, 1.0, 0.0), (1, 0, 0), 0.25, 0.25),  # fully inside
    ((0.0, 1.0, 0.0), (1, 0, 0), 5.0, 1.0),  # crosses the whole box along x
    ((0.0, 1.0, 0.0), (1, 0, 0), 1.5, 0.5),  # enters, ends inside
    ((1.5, 1.0, 0.0), (-1, 0, 0), 5.0, 0.5),  # starts inside, leaves
    ((0.0, 1.0, 0.0), (1, 0, 0), 0.9, 0.0),  # stops short of the box
    ((0.0, 5.0, 0.0), (1, 0, 0), 5.0, 0.0),  # misses (y outside the slab)
    ((3.0, 1.0, 0.0), (1, 0, 0), 5.0, 0.0),  # points away
    ((1.5, -1.0, 0.5), (0, 1, 0), 10.0, 3.0),  # parallel to the x and z faces, inside those slabs
    ((2.5, -1.0, 0.5), (0, 1, 0), 10.0, 0.0),  # parallel to the x faces, outside the x slab
    ((2.0, -1.0, 0.5), (0, 1, 0), 10.0, 3.0),  # in the plane of the face x = 2 (closed box: inside)
    ((1.0, 1.0, 0.0), (1, 0, 0), 5.0, 1.0),  # starts on the face x = 1, going in
    ((1.0, 1.0, 0.0), (-1, 0, 0), 5.0, 0.0),  # starts on the face x = 1, going out
    ((0.0, 0.0, -1.5), tuple(_unit(1, 1, 1)), 10.0, math.sqrt(3) * 1.0),  # diagonal: x from 1 to 2 (z -0.5..0.5)
]


@pytest.mark.parametrize("o,d,L,expected", BOX_CASES)
def test_box_region_length_inside_by_hand(o, d, L, expected):
    med = HomogeneousMedium(0.5, 0.0, (LO, HI))
    got = med.length_inside(np.array([o]), np.array([d], float), np.array([L]))
    assert got[0] == pytest.approx(expected, abs=1e-12)
    assert med.transmittance(np.array([o]), np.array([d], float), np.array([L]))[0] == pytest.approx(
        math.exp(-0.5 * expected), rel=1e-12
    )


def test_box_containing_every_segment_equals_whole_scene_exactly():
    rng = seeded_rng()
    o, d, L = _segments(5000, rng, 0.0, 1.0, 0.3)  # all inside [-1, 2]^3
    whole, box = HomogeneousMedium(0.1, 0.3), HomogeneousMedium(0.1, 0.3, (np.full(3, -1.0), np.full(3, 2.0)))
    assert np.array_equal(whole.optical_depth(o, d, L), box.optical_depth(o, d, L))
    assert np.array_equal(whole.transmittance(o, d, L), box.transmittance(o, d, L))
    u = rng.random(len(L))
    assert all(np.array_equal(a, b) for a, b in zip(whole.sample_distance(o, d, L, u), box.sample_distance(o, d, L, u)))


def test_any_array_layout():
    """Transposes of (3, n) arrays (the kernel's layout) give the same answers as (n, 3) arrays."""
    o, d, L = _segments(300, seeded_rng())
    o3, d3 = np.ascontiguousarray(o.T), np.ascontiguousarray(d.T)
    for med in (HomogeneousMedium(0.2, 0.1, (LO, HI)), GridMedium(LO, HI, (2, 3, 4), 0.2, np.arange(24) / 10)):
        assert np.array_equal(med.optical_depth(o, d, L), med.optical_depth(o3.T, d3.T, L))


# --- closed-mesh regions ------------------------------------------------------------------------


def _box_probe_segments(rng):
    """Random segments plus axis-aligned ones through face centres (they hit the diagonal edge of each face)."""
    o, d, L = _segments(20_000, rng)
    c = 0.5 * (LO + HI)
    axes = np.vstack([np.eye(3), -np.eye(3)])
    o2 = c - 2.0 * axes * (HI - LO)  # from outside, through the centre of opposite faces
    o3 = np.array([[LO[0], c[1], c[2]], [c[0], HI[1], c[2]], [c[0], c[1], LO[2]]])  # starting on faces
    d3 = np.array([[1.0, 0, 0], [0, -1.0, 0], [0.0, 0.6, 0.8]])
    return (
        np.vstack([o, o2, o3, o3]),
        np.vstack([d, axes, d3, -d3]),
        np.concatenate([L, np.full(6, 10.0), np.full(6, 0.7)]),
    )


@pytest.mark.parametrize("shift", [0.0, 5000.0])
def test_mesh_region_shaped_as_a_box_equals_the_box_region(shift):
    """Also 5 km from the origin: Embree's float32 is re-centred and crossings are recomputed in float64."""
    rng = seeded_rng()
    o, d, L = _box_probe_segments(rng)
    o = o + shift
    lo, hi = LO + shift, HI + shift
    ref = HomogeneousMedium(0.4, 0.1, (lo, hi))
    mesh = _box_mesh(lo, hi)
    # Unshared vertices and half the faces flipped: the region merges and orients them itself.
    tri = mesh.triangles.copy()
    tri[::2] = tri[::2, ::-1]
    med = HomogeneousMedium(0.4, 0.1, region=MeshRegion(tri.reshape(-1, 3), np.arange(len(tri) * 3).reshape(-1, 3)))
    want = ref.length_inside(o, d, L)
    assert (want > 0).mean() > 0.05
    assert np.abs(med.length_inside(o, d, L) - want).max() < 1e-9
    assert np.abs(med.optical_depth(o, d, L) - ref.optical_depth(o, d, L)).max() < 1e-9
    u = rng.random(len(L))
    (t1, s1), (t2, s2) = med.sample_distance(o, d, L, u), ref.sample_distance(o, d, L, u)
    assert np.array_equal(s1, s2) and np.abs(t1 - t2).max() < 1e-9
    pts = rng.uniform(0.0, 3.0, (5000, 3)) + shift
    assert np.array_equal(med.sigma_t_at(pts) > 0, np.all((pts >= lo) & (pts <= hi), axis=1))
    assert np.array_equal(med.bounds[0], lo) and np.array_equal(med.bounds[1], hi)


def test_mesh_region_rays_through_edges_and_corners():
    """Rays through the box's vertices, edge midpoints and face centres, many grazing an edge or a corner from
    outside (inside length 0): Embree reports one of the two faces there, the region must not flip inside/outside."""
    ref = HomogeneousMedium(1.0, 0.0, (LO, HI))
    med = HomogeneousMedium(1.0, 0.0, region=MeshRegion(_box_mesh(LO, HI).vertices, _box_mesh(LO, HI).faces))
    pts = np.stack(np.meshgrid(*[[a, 0.5 * (a + b), b] for a, b in zip(LO, HI)], indexing="ij"), -1).reshape(-1, 3)
    dirs = np.array(
        [_unit(*v) for v in [(1, 1, 0), (1, 0, 1), (0, 1, 1), (1, 1, 1), (1, -1, 0), (1, 0, 0), (0, 0, 1), (1, -1, 1)]]
    )
    dirs = np.vstack([dirs, -dirs])
    o = (pts[:, None] - 3.0 * dirs[None]).reshape(-1, 3)
    d = np.broadcast_to(dirs, (len(pts), len(dirs), 3)).reshape(-1, 3)
    L = np.full(len(o), 6.0)
    want = ref.length_inside(o, d, L)
    assert (want == 0).sum() > 50 and (want > 0).sum() > 50
    assert np.abs(med.length_inside(o, d, L) - want).max() < 1e-9


def test_mesh_region_sphere_against_analytic_chords():
    """Icosphere (5 subdivisions, 20480 faces) of radius R: the convex polyhedron lies between the sphere of its
    inradius r_in (closest face plane, R - r_in = 2.8e-4 R) and the sphere R, so every chord lies between the
    two analytic chords (faceting error); the mean error is also small."""
    R, c = 0.8, np.array([0.3, -0.2, 0.5])
    s = trimesh.creation.icosphere(subdivisions=5, radius=R)
    s.apply_translation(c)
    region = MeshRegion(s.vertices, s.faces)
    r_in = np.abs(np.einsum("ij,ij->i", s.triangles[:, 0] - c, s.face_normals)).min()
    assert 0.999 * R < r_in < R

    o, d, L = _segments(20_000, seeded_rng(), -1.0, 1.5, 3.0)

    def chord(r):
        oc = o - c
        b = np.einsum("ij,ij->i", oc, d)
        disc = b * b - (np.einsum("ij,ij->i", oc, oc) - r * r)
        sq = np.sqrt(np.maximum(disc, 0.0))
        return np.where(disc > 0, np.clip(-b + sq, 0, L) - np.clip(-b - sq, 0, L), 0.0)

    got = np.zeros(len(L))
    for ray, a, b in region.intervals(o, d, L):
        got[ray] += b - a
    outer, inner = chord(R), chord(r_in)
    assert (outer > 0).mean() > 0.2
    assert np.all(got <= outer + 1e-9) and np.all(got >= inner - 1e-9)
    assert np.abs(got - outer).mean() < 1e-3 * R  # measured: 6.8e-5 m mean, 9.4e-3 m max (near-tangent chords)


def test_nested_shells_make_a_hollow():
    """Outer box 0..4, inner box 1..3: inside is the shell between them (parity rule)."""
    outer, inner = _box_mesh([0, 0, 0], [4, 4, 4]), _box_mesh([1, 1, 1], [3, 3, 3])
    both = trimesh.util.concatenate([outer, inner])
    region = MeshRegion(both.vertices, both.faces)
    med = HomogeneousMedium(1.0, 0.0, region=region)
    o = np.array([[-1.0, 2.0, 2.0], [2.0, 2.0, 2.0], [-1.0, 0.5, 2.0]])
    d = np.array([[1.0, 0, 0], [1.0, 0, 0], [1.0, 0, 0]])
    assert np.allclose(med.length_inside(o, d, np.full(3, 10.0)), [2.0, 1.0, 4.0], atol=1e-12)
    assert np.array_equal(region.contains(np.array([[0.5, 2, 2], [2.0, 2, 2], [5.0, 2, 2]])), [True, False, False])


def test_open_mesh_region_is_refused_at_build():
    box = _box_mesh([0, 0, 0], [1, 1, 1])
    with pytest.raises(SceneError, match=r"medium\.region: .*not closed"):
        MeshRegion(box.vertices, box.faces[:-1])


# --- the 3-D grid ---------------------------------------------------------------------------------


def test_uniform_grid_equals_homogeneous_box():
    rng = seeded_rng()
    o, d, L = _segments(20_000, rng)
    grid, box = GridMedium(LO, HI, (7, 5, 3), 0.9, 0.6), HomogeneousMedium(0.9, 0.6, (LO, HI))
    tau_g, tau_b = grid.optical_depth(o, d, L), box.optical_depth(o, d, L)
    assert (tau_b > 0).mean() > 0.05
    assert np.abs(tau_g - tau_b).max() <= 1e-12 * max(1.0, tau_b.max())
    # Same uniforms: the same collisions (up to rounding); independent uniforms: the same distribution.
    u = rng.random(len(L))
    (tg, sg), (tb, sb) = grid.sample_distance(o, d, L, u), box.sample_distance(o, d, L, u)
    assert np.array_equal(sg, sb) and np.abs(tg - tb).max() < 1e-12
    sel = np.flatnonzero(tau_b > 0)[:1]  # one crossing segment, many flights
    n = 20_000
    args = (np.repeat(o[sel], n, 0), np.repeat(d[sel], n, 0), np.repeat(L[sel], n))
    tg, _ = grid.sample_distance(*args, rng.random(n))
    tb, _ = box.sample_distance(*args, rng.random(n))
    assert stats.ks_2samp(tg, tb).pvalue > 0.001


def test_grid_with_two_halves_by_hand():
    """x in [0, 1]: sigma_t = 0.5 + 0.25; x in [1, 2]: sigma_t = 2 + 1 (grid 0..2 x 0..1 x 0..1, shape 2x1x1)."""
    grid = GridMedium([0, 0, 0], [2, 1, 1], (2, 1, 1), [0.5, 2.0], [0.25, 1.0])
    d = _unit(4, 1, 0)  # from (0, 0.25, 0.5): x = 1 at s = sqrt(17)/4, leaves the top face y = 1 at x = 3
    o = np.array([[0.0, 0.25, 0.5], [-1.0, 0.5, 0.5], [1.5, 0.5, 0.5], [-1, 0.5, 0.5]])
    dirs = np.array([d, [1.0, 0, 0], [-1.0, 0, 0], [0.0, 0, 1]])
    L = np.array([10.0, 10.0, 10.0, 10.0])
    s1 = math.sqrt(17) / 4  # length in the first half
    expected = [0.75 * s1 + 3.0 * s1, 0.75 + 3.0, 3.0 * 0.5 + 0.75 * 1.0, 0.0]
    assert np.allclose(grid.optical_depth(o, dirs, L), expected, rtol=1e-13, atol=0)
    # Regular tracking by hand: depth 2 along the x axis from x = -1 is reached 1.25/3 into the second half.
    t, hit = grid.sample_distance(o[1:2], dirs[1:2], L[1:2], np.array([1 - math.exp(-2.0)]))
    assert hit[0] and t[0] == pytest.approx(2.0 + 1.25 / 3.0, rel=1e-12)
    assert np.allclose(
        grid.albedo_at(np.array([[0.5, 0.5, 0.5], [1.5, 0.5, 0.5], [3.0, 0.5, 0.5]])), [1 / 3, 1 / 3, 0.0]
    )


def test_grid_flat_index_is_c_order_x_slowest():
    nx, ny, nz = 2, 3, 4
    values = np.arange(nx * ny * nz, dtype=float)
    grid = GridMedium([0, 0, 0], [nx, ny, nz], (nx, ny, nz), values, 0.0)  # unit cells
    i, j, k = np.meshgrid(np.arange(nx), np.arange(ny), np.arange(nz), indexing="ij")
    centres = np.stack([i, j, k], axis=-1).reshape(-1, 3) + 0.5
    assert np.array_equal(grid.sigma_t_at(centres), ((i * ny + j) * nz + k).reshape(-1).astype(float))


# --- free-flight sampling ---------------------------------------------------------------------------


def test_mean_free_path_in_unbounded_medium():
    sigma_t, n = 0.7, 200_000
    med = HomogeneousMedium(0.2, 0.5)
    t, hit = med.sample_distance(np.zeros((n, 3)), np.tile([0.0, 0, 1], (n, 1)), np.full(n, np.inf), rng=seeded_rng())
    assert hit.all()
    se = (1 / sigma_t) / math.sqrt(n)  # the exponential's standard deviation is its mean
    assert abs(t.mean() - 1 / sigma_t) < 5 * se, (t.mean(), 1 / sigma_t, se)


@pytest.mark.parametrize("method", ["regular", "delta"])
def test_probability_of_no_collision(method):
    sigma_t, L, n = 1.3, 0.9, 100_000
    med = HomogeneousMedium(1.0, 0.3, (np.array([-1.0, -1, -1]), np.array([1.0, 1, 5])))
    o, d = np.zeros((n, 3)), np.tile(_unit(0, 0.6, 0.8), (n, 1))  # inside the box for all of L
    rng = seeded_rng()
    t, hit = med.sample_distance(
        o, d, np.full(n, L), rng.random(n) if method == "regular" else None, method=method, rng=rng
    )
    p = math.exp(-sigma_t * L)
    assert abs((~hit).mean() - p) < 5 * math.sqrt(p * (1 - p) / n)
    assert np.all(t[~hit] == L) and np.all((t[hit] >= 0) & (t[hit] < L))


def test_regular_and_delta_tracking_agree_on_a_random_grid():
    rng = seeded_rng()
    shape = (6, 5, 4)
    sa, ss = rng.uniform(0, 0.8, int(np.prod(shape))), rng.uniform(0, 0.5, int(np.prod(shape)))
    sa[rng.random(sa.size) < 0.2] = 0.0  # some cells nearly empty
    ss[sa == 0] = 0.0
    grid = GridMedium(LO, HI, shape, sa, ss)
    n = 20_000
    segs = [
        (np.array([0.5, 0.3, -0.9]), _unit(1, 1.2, 0.3), 4.0),
        (np.array([1.5, -0.5, 0.0]), _unit(0, 1, 0.05), 3.0),
        (np.array([1.1, 0.2, -1.0]), _unit(0.1, 0.3, 1), 2.5),
    ]
    for o0, d0, L0 in segs:
        o, d, L = np.tile(o0, (n, 1)), np.tile(d0, (n, 1)), np.full(n, L0)
        tr, hr = grid.sample_distance(o, d, L, rng.random(n))
        td, hd = grid.sample_distance(o, d, L, method="delta", rng=rng)
        assert 0.05 < hr.mean() < 0.95  # both outcomes are well represented
        assert stats.ks_2samp(tr, td).pvalue > 0.001
        # and both against the exact P(no collision) = exp(-tau)
        p = math.exp(-grid.optical_depth(o[:1], d[:1], L[:1])[0])
        for h in (hr, hd):
            assert abs((~h).mean() - p) < 5 * math.sqrt(p * (1 - p) / n)


def test_delta_tracking_in_a_mesh_region():
    """Delta tracking tests the inside of a sphere point by point; regular tracking walks its intervals."""
    s = trimesh.creation.icosphere(subdivisions=3, radius=1.0)
    med = HomogeneousMedium(0.8, 0.4, region=MeshRegion(s.vertices, s.faces))
    n, rng = 20_000, seeded_rng()
    o, d, L = np.tile([-2.0, 0.3, 0.1], (n, 1)), np.tile([1.0, 0, 0], (n, 1)), np.full(n, 4.0)
    tr, _ = med.sample_distance(o, d, L, rng.random(n))
    td, _ = med.sample_distance(o, d, L, method="delta", rng=rng)
    assert stats.ks_2samp(tr, td).pvalue > 0.001


# --- cost and numerical hygiene -------------------------------------------------------------------


@pytest.mark.parametrize("kind", ["box", "mesh", "grid"])
def test_segments_outside_a_region_cost_nothing(kind):
    if kind == "grid":
        med = GridMedium(LO, HI, (3, 3, 3), 0.5, 0.5)
    elif kind == "mesh":
        med = HomogeneousMedium(0.5, 0.5, region=MeshRegion(_box_mesh(LO, HI).vertices, _box_mesh(LO, HI).faces))
    else:
        med = HomogeneousMedium(0.5, 0.5, (LO, HI))
    rng = seeded_rng()
    o, d, L = _segments(1000, rng, 5.0, 9.0, 3.0)  # far from the region, never reaching it
    assert np.all(med.transmittance(o, d, L) == 1.0)
    assert np.all(med.optical_depth(o, d, L) == 0.0)
    t, hit = med.sample_distance(o, d, L, rng.random(len(L)))
    assert np.array_equal(t, L) and not hit.any()
    assert med.evaluations == 0
    # Two segments through the region, one outside: each method counts 2.
    o2 = np.array([[0.0, 1.0, 0.0], [1.5, -1.0, 0.0], [0.0, 9.0, 0.0]])
    d2, L2 = np.array([[1.0, 0, 0], [0, 1.0, 0], [1.0, 0, 0]]), np.full(3, 10.0)
    med.transmittance(o2, d2, L2)
    med.sample_distance(o2, d2, L2, np.full(3, 0.5))
    med.sample_distance(o2, d2, L2, method="delta", rng=rng)
    assert med.evaluations == 6


@pytest.mark.parametrize("sigma_t", [0.0, 1e-9])
def test_tiny_extinction(sigma_t):
    o, d = np.zeros((3, 3)), np.tile([1.0, 0, 0], (3, 1))
    L = np.array([0.0, 1.0, 1e3])
    for med in (
        HomogeneousMedium(sigma_t, 0.0),
        HomogeneousMedium(0.0, sigma_t, (np.full(3, -1e4), np.full(3, 1e4))),
        GridMedium([-1, -1, -1], [1e3, 1, 1], (4, 1, 1), sigma_t, 0.0),
    ):
        T = med.transmittance(o, d, L)
        assert np.all(np.isfinite(T))
        x = sigma_t * L
        assert np.all(np.abs(T - (1.0 - x + x * x / 2)) <= 2.3e-16)  # exp to second order: no lost digits
        assert np.all(np.abs(T - (1.0 - x)) <= x * x / 2 + 2.3e-16)
        if sigma_t == 0.0:
            assert np.all(T == 1.0)
        t, hit = med.sample_distance(o, d, L, np.array([0.0, 0.5, 0.999999]))
        assert np.all(np.isfinite(t)) and (sigma_t > 0 or (not hit.any() and np.array_equal(t, L)))
        assert np.all(np.isfinite(med.albedo_at(np.array([[0.0, 0, 0], [50.0, 0, 0]]))))
    empty = HomogeneousMedium(0.0, 0.0)
    assert empty.albedo_at(np.zeros((1, 3)))[0] == 0.0
    assert empty.transmittance(o[:1], d[:1], np.array([np.inf]))[0] == 1.0  # 0 * inf is not NaN here


def test_large_optical_depth_is_tiny_not_zero_or_nan():
    o, d, L = np.zeros((1, 3)), np.array([[0.0, 0, 1]]), np.array([10.0])
    for med in (HomogeneousMedium(4.0, 1.0), GridMedium([-1, -1, -1], [1, 1, 20], (1, 1, 7), 4.0, 1.0)):
        T = med.transmittance(o, d, L)[0]
        assert T > 0 and T == pytest.approx(math.exp(-50.0), rel=1e-12)
    assert not np.isnan(HomogeneousMedium(1e4, 0.0).transmittance(o, d, np.array([1e3]))).any()


# --- specs: parsing, medium_from_spec, located errors ---------------------------------------------


def _errors(medium) -> str:
    with pytest.raises(ValidationError) as exc:
        SceneSpec.model_validate(room_doc(medium=medium))
    return "\n".join(f"{'.'.join(map(str, e['loc']))}: {e['msg']}" for e in exc.value.errors())


GRID = {"type": "grid", "min": [0, 0, 2], "max": [5, 5, 3], "shape": [2, 3, 1], "sigma_a": [0.1] * 6, "sigma_s": 0.2}


def test_specs_build_the_right_media():
    grid = medium_from_spec(SceneSpec.model_validate(room_doc(medium=GRID)).medium)
    assert isinstance(grid, GridMedium) and grid.sigma_t_max == pytest.approx(0.3) and grid.bounds[0][2] == 2
    assert (
        medium_from_spec(SceneSpec.model_validate(room_doc(medium=dict(GRID, sigma_a=0, sigma_s=[0] * 6))).medium)
        is None
    )
    box = _box_mesh([1, 1, 1], [2, 2, 2])
    region = {"type": "mesh", "vertices": box.vertices.tolist(), "faces": box.faces.tolist()}
    spec = SceneSpec.model_validate(
        room_doc(
            medium={
                "type": "homogeneous",
                "sigma_a": 0.1,
                "sigma_s": 0.1,
                "phase": {"type": "hg", "g": 0.7},
                "region": region,
            }
        )
    )
    med = medium_from_spec(spec.medium)
    assert med.phase_spec.g == 0.7 and med.box is None
    assert med.length_inside(np.array([[0.0, 1.5, 1.5]]), np.array([[1.0, 0, 0]]), np.array([5.0]))[0] == pytest.approx(
        1.0, abs=1e-12
    )
    old = {
        "type": "homogeneous",
        "visibility_m": 10.0,
        "albedo": 0.5,
        "region": {"type": "box", "min": [0, 0, 2], "max": [5, 5, 3]},
    }
    med = medium_from_spec(SceneSpec.model_validate(room_doc(medium=old)).medium)
    assert med.sigma_t == pytest.approx(0.3912) and med.box[0][2] == 2.0


@pytest.mark.parametrize(
    "change,where,what",
    [
        ({"sigma_a": [0.1, 0.1, -0.1, 0.1, 0.1, 0.1]}, "medium.grid.sigma_a", "flat index 2 (cell 0, 2, 0)"),
        ({"sigma_s": -1.0}, "medium.grid.sigma_s", ">= 0"),
        ({"sigma_s": [0.1] * 5}, "medium.grid.sigma_s", "nx*ny*nz = 6 values"),
        ({"sigma_a": [0.1, float("nan")] * 3}, "medium.grid.sigma_a", "finite"),
        ({"shape": [2, 0, 1]}, "medium.grid.shape", ">= 1"),
        ({"shape": [1000, 1000, 21], "sigma_a": 0.1}, "medium.grid.shape", "limit"),
        ({"shape": [1, 1, 1001], "sigma_a": 0.1}, "medium.grid.shape", "1001 cells along one axis"),
        ({"max": [5, 5, 1]}, "medium.grid", "must exceed"),
    ],
)
def test_grid_spec_errors_are_located(change, where, what):
    msg = _errors(dict(GRID, **change))
    assert where in msg and what in msg, msg


def test_mesh_region_spec_errors_are_located():
    box = _box_mesh([1, 1, 1], [2, 2, 2])
    base = {"type": "homogeneous", "sigma_a": 0.1, "sigma_s": 0.1}
    open_region = {"type": "mesh", "vertices": box.vertices.tolist(), "faces": box.faces[:-1].tolist()}
    msg = _errors(dict(base, region=open_region))
    assert "medium.homogeneous.region.mesh" in msg and "not closed" in msg
    bad = box.vertices.tolist()
    bad[3][1] = float("inf")
    assert "medium.homogeneous.region.mesh.vertices.3" in _errors(dict(base, region=dict(open_region, vertices=bad)))
    assert "medium.homogeneous.region.mesh.faces" in _errors(dict(base, region=dict(open_region, faces=[])))
    assert "outside 0..7" in _errors(dict(base, region=dict(open_region, faces=[[0, 1, 8]] * 4)))
    assert "medium.homogeneous.sigma_a" in _errors(dict(base, sigma_a=-0.5))


def _random_grid_rays(rng, n=300):
    """A random grid, and rays from inside and outside it, some along axes, some from cell planes."""
    shape = (7, 3, 11)
    grid = GridMedium(LO, HI, shape, rng.uniform(0, 2, int(np.prod(shape))), rng.uniform(0, 1, int(np.prod(shape))))
    o = rng.uniform(LO - 0.5, HI + 0.5, (n, 3))
    o[:20, 0] = LO[0] + 3 * grid.h[0]  # start on an interior plane
    d = rng.uniform(LO, HI, (n, 3)) - o  # toward a point of the grid
    d[20:40, 1:] = 0.0  # along x
    d[40:60, :2] = 0.0  # along z
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    L = rng.uniform(0.1, 4.0, n)  # many end inside the grid
    return grid, o, d, L


def test_grid_optical_depth_against_fine_quadrature():
    # Independent of the traversal: midpoint sums of sigma_t(o + t d) with 200 000 points per ray.
    rng = seeded_rng()
    grid, o, d, L = _random_grid_rays(rng)
    tau = grid.optical_depth(o, d, L)
    m = 200_000
    for r in range(len(L)):  # a loop over test rays (reference), each vectorized over its points
        t = (np.arange(m) + 0.5) * (L[r] / m)
        sigma, _ = grid._coefficients_at(o[r] + t[:, None] * d[r])
        ref = sigma.sum() * (L[r] / m)
        # each cell plane crossed puts at most one step of the sum in the wrong cell
        planes = np.abs(np.diff(grid.cells(o[r] + t[[0, -1]][:, None] * d[r])[0], axis=0)).sum() + 2
        assert abs(tau[r] - ref) <= (planes + 1) * grid.sigma_t_max * (L[r] / m) + 1e-12, r
    assert (tau > 0).sum() > 200  # most rays cross the grid


def test_grid_collision_depth_is_the_one_asked():
    rng = seeded_rng()
    grid, o, d, L = _random_grid_rays(rng)
    u = rng.random(len(L))
    t, hit = grid.sample_distance(o, d, L, u)
    assert 0.2 < hit.mean() < 0.8
    # the optical depth up to the sampled collision is -ln(1 - u); no collision: the whole depth is below it
    np.testing.assert_allclose(grid.optical_depth(o[hit], d[hit], t[hit]), -np.log1p(-u[hit]), rtol=1e-9, atol=1e-12)
    assert np.all(grid.optical_depth(o[~hit], d[~hit], L[~hit]) <= -np.log1p(-u[~hit]))
    assert np.array_equal(t[~hit], L[~hit])
