"""Issue 22's combination matrix (tests/matrix.py): every cell holds against an independent estimate or is
refused with one sentence; a fast pairwise tier in the default run, the full matrix in the slow set."""

from __future__ import annotations

import itertools
import json
import subprocess
import sys

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from tests import matrix

#: Cells that fail only because of an item of issue 22 fixed on another branch (strict: the lead removes an
#: entry when its fix is merged and the cell passes). Keys are `matrix.cell_id`s.
ITEM_1 = "issue 22 item 1: algorithm 5 in a furnished room, medium_nee.connection_weight on a zero-size array"
ITEM_2 = "issue 22 item 2: spectral scene, more than 8 receivers, automatic settings (IndexError)"
ITEM_3 = "issue 22 item 3: algorithm 5 without a medium (AttributeError in auto._max_albedo)"
ITEM_4 = "issue 22 item 4: automatic K stops at the pilot's cap in a bright room, H0 low without a warning"
ITEM_5 = "issue 22 item 5: error bars at |g| = 0.999 (forward and backward disagree beyond them, or too wide)"
KNOWN_FAILURES: dict[str, str] = {}

#: Cells that hold but whose comparison cannot see a 10 % error at the matrix's path counts (the combined
#: relative error of cell and reference is above 10 % / 4.5): a limit of the matrix, not of owcsim.
UNDERPOWERED = "the matrix: combined relative error {} at these path counts, a planted 10 % error stays under z = 4.5"
KNOWN_FAILURES.update(
    {
        "mesh-homogeneous-grey-lambert-lambertian-a3-map9-opticaldepth30": UNDERPOWERED.format(
            "1.5 %, the cell 3 % below its reference"
        ),
        "empty-homogeneous-grey-lambert-lambertian-a4-links1-FOV1deg": UNDERPOWERED.format(
            "2.4 % (FOV 1 deg, algorithm 4 at K = 0 against algorithm 5)"
        ),
        "empty-homogeneous-grey-lambert-lambertian-a4-links1-g+0.999": UNDERPOWERED.format(
            "3.9 % (g = +0.999, algorithm 4 against the swapped devices; the error bars cover, z 0.93)"
        ),
    }
)


def _params(cells):
    out = []
    for cell in cells:
        cid = matrix.cell_id(cell)
        why = KNOWN_FAILURES.get(cid)
        marks = [pytest.mark.xfail(strict=True, reason=why)] if why else []
        out.append(pytest.param(cell, id=cid, marks=marks))
    return out


FAST = matrix.fast_cells()
FULL = [c for c in matrix.full_cells() if c not in FAST]


def _check(cell):
    out = matrix.run(cell)
    assert out.status in ("pass", "refused", "flagged"), f"{out.id}: {out.status}: {out.message}"
    if out.status == "pass" and not out.power:
        assert cell["extreme"] in matrix.IMPRECISE_OK and out.combined_rel_stderr >= 0.05, (
            f"{out.id}: a 10 % error on H0 would pass (z_max {out.z_max:.2f}, combined relative error "
            f"{out.combined_rel_stderr:.2%}); more paths needed"
        )
    return out


@pytest.mark.parametrize("cell", _params(FAST))
def test_fast_tier_cell_holds(cell):
    _check(cell)


@pytest.mark.slow
@pytest.mark.parametrize("cell", _params(FULL))
def test_full_matrix_cell_holds(cell):
    _check(cell)


def test_fast_tier_has_every_axis_value_and_the_full_matrix_every_pair():
    """Checked here by brute force, not by the generator's own bookkeeping."""
    names = list(matrix.AXES)
    for axis in names:
        for value in matrix.AXES[axis]:
            assert any(c[axis] == value for c in FAST), f"{axis}={value} is in no fast cell"
    everything = FAST + FULL
    for a, b in itertools.combinations(names, 2):
        for va, vb in itertools.product(matrix.AXES[a], matrix.AXES[b]):
            if matrix.forbidden((a, va), (b, vb)):
                continue
            assert any(c[a] == va and c[b] == vb for c in everything), f"{a}={va}, {b}={vb} is in no cell"
    assert all(matrix.valid(c) for c in everything)
    ids = [matrix.cell_id(c) for c in everything]
    assert len(set(ids)) == len(ids)


def test_the_comparison_has_the_stated_false_alarm_rate_and_power():
    """z <= Z_MAX: two-sided Gaussian tail 6.8e-6; a 10 % error at 1.5 % combined relative error is caught."""
    from math import erfc, sqrt

    assert erfc(matrix.Z_MAX / sqrt(2)) < 1e-5
    a, b = np.array([1.0]), np.array([1.0])
    se = np.array([0.015 / sqrt(2)])
    assert matrix._z(a, se, b, se)[0] == 0.0
    assert matrix._z(a * 1.1, se * 1.1, b, se)[0] > matrix.Z_MAX
    assert matrix._z(np.array([0.0]), np.array([0.0]), np.array([0.0]), np.array([0.0]))[0] == 0.0


def test_one_sentence_accepts_located_errors_and_rejects_tracebacks():
    assert matrix.one_sentence("the scene has 1 problem:\n  room.size.0: Input should be greater than 0")
    assert not matrix.one_sentence("the scene has 1 problem:\n  a\n  b")
    assert not matrix.one_sentence('Traceback (most recent call last):\n  File "x.py", line 1')
    assert not matrix.one_sentence("")


#: Combinations refused by design, each with the words its sentence must contain.
REFUSED = {
    "spectral surfaces with a mirror": (
        dict(matrix.fast_cells()[0], spectral="on", surfaces="mirror", extreme="none"),
        "mirror",
    ),
}


@pytest.mark.parametrize("case", sorted(REFUSED))
def test_refused_combinations_say_why_in_one_sentence(case):
    cell, words = REFUSED[case]
    out = matrix.run(cell)
    assert out.status == "refused", out.message
    assert words in out.message


def _cli(tmp_path, doc):
    path = tmp_path / "scene.json"
    path.write_text(json.dumps(doc))
    return subprocess.run(
        [sys.executable, "-m", "owcsim", "run", str(path), "--out", str(tmp_path / "out")],
        capture_output=True,
        text=True,
        timeout=300,
    )


CLI_CELLS = {
    "smoke, desks, algorithm 1": dict(
        furnishing="desks",
        medium="homogeneous",
        spectral="off",
        surfaces="phong",
        luminaire="ies",
        algorithm="1",
        output="links",
        receivers="9",
        extreme="none",
    ),
    "spectral map, automatic": dict(
        furnishing="empty",
        medium="none",
        spectral="on",
        surfaces="lambert",
        luminaire="lambertian",
        algorithm="auto",
        output="map",
        receivers="1",
        extreme="area 1e-8 m2",
    ),
}


@pytest.mark.parametrize("case", sorted(CLI_CELLS))
def test_cli_runs_cells_without_a_traceback(tmp_path, case):
    proc = _cli(tmp_path, matrix.scene(CLI_CELLS[case], paths=2048))
    assert proc.returncode == 0 and "Traceback" not in proc.stderr, proc.stderr[-2000:]
    result = json.loads((tmp_path / "out" / "result.json").read_text())
    assert all(np.isfinite(link["dc_gain"]) for link in result["links"])


def test_cli_refuses_with_one_sentence_and_no_traceback(tmp_path):
    proc = _cli(tmp_path, matrix.scene(REFUSED["spectral surfaces with a mirror"][0], paths=2048))
    assert proc.returncode != 0
    assert "Traceback" not in proc.stderr and "mirror" in proc.stderr
    assert len(proc.stderr.strip().splitlines()) <= 2, proc.stderr


CELLS = st.fixed_dictionaries({axis: st.sampled_from(values) for axis, values in matrix.AXES.items()})
PROFILE = settings(
    max_examples=150,
    derandomize=True,
    database=None,
    deadline=None,
    suppress_health_check=[HealthCheck.too_slow, HealthCheck.filter_too_much],
)


@PROFILE
@given(CELLS)
def test_every_cell_of_the_product_builds_a_valid_scene(cell):
    """The generator over the whole product (not only the tiers): a valid cell gives a document the schema
    accepts, and a cell with a forbidden pair is one the matrix never builds."""
    from owcsim.schemas import SceneSpec

    if not matrix.valid(cell):
        return
    doc = matrix.scene(cell, paths=1024)
    spec = SceneSpec.model_validate(doc)
    assert len(spec.transmitters) == 1
    n = int(cell["receivers"])
    explicit = len(doc.get("receivers", []))
    grid = doc.get("receiver_grids", [])
    points = explicit + sum(
        round(g["size"][0] / g["spacing"] + 1) * round(g["size"][1] / g["spacing"] + 1) for g in grid
    )
    assert points == (n + 1 if cell["output"] == "map" and cell["extreme"] == "Tx-Rx 1 mm" else n)


@settings(max_examples=5, derandomize=True, database=None, deadline=None)
@given(st.integers(0, 10_000))
def test_any_seed_gives_a_covering_array(seed):
    cells = matrix.covering(strength=2, seed=seed, candidates=5)
    names = list(matrix.AXES)
    seen = {((a, c[a]), (b, c[b])) for c in cells for a, b in itertools.combinations(names, 2)}
    for a, b in itertools.combinations(names, 2):
        for va, vb in itertools.product(matrix.AXES[a], matrix.AXES[b]):
            assert matrix.forbidden((a, va), (b, vb)) or ((a, va), (b, vb)) in seen
    assert all(matrix.valid(c) for c in cells)


def test_cli_algorithm_5_without_a_medium_runs_or_refuses_in_one_sentence(tmp_path):
    cell = dict(CLI_CELLS["spectral map, automatic"], spectral="off", output="links")
    doc = matrix.scene(cell, paths=2048)
    doc["simulation"]["algorithm"] = 5  # K and S left automatic, as in the reproduction
    proc = _cli(tmp_path, doc)
    assert "Traceback" not in proc.stderr, proc.stderr[-2000:]
    assert proc.returncode == 0 or len(proc.stderr.strip().splitlines()) <= 2


def _forward_backward(cell, edit):
    import owcsim

    out = {}
    for direction in ("forward", "backward"):
        doc = matrix.scene(cell, paths=8192)
        doc["simulation"]["direction"] = direction
        edit(doc)
        out[direction] = owcsim.simulate(doc)
    return out


BASE = dict(
    furnishing="empty",
    medium="none",
    spectral="off",
    surfaces="lambert",
    luminaire="lambertian",
    algorithm="1",
    output="links",
    receivers="1",
)


def test_forward_run_1_mm_below_a_ceiling_light_agrees_with_backward_or_warns():
    runs = _forward_backward(dict(BASE, extreme="Tx-Rx 1 mm"), lambda doc: None)
    fw, bw = (runs[d].links[0] for d in ("forward", "backward"))
    z = abs(fw.dc_gain - bw.dc_gain) / np.hypot(fw.dc_gain_stderr, bw.dc_gain_stderr)
    warned = any("unreliable" in w or "near a surface" in w for w in runs["forward"].warnings)
    assert z <= matrix.Z_MAX or warned, (
        f"diffuse part (H0 - LOS) forward {fw.dc_gain - fw.los_gain:.3e} ± {fw.dc_gain_stderr:.1e}, "
        f"backward {bw.dc_gain - bw.los_gain:.3e} ± {bw.dc_gain_stderr:.1e}"
    )


def test_forward_run_with_fov_1_deg_reports_no_zero_error_bar_without_a_warning():
    def nine(doc):
        doc["receivers"] = [
            dict(doc["receivers"][0], id=f"rx{i}", position=[1.0 + 0.3 * i, 1.6, 0.85]) for i in range(9)
        ]

    runs = _forward_backward(dict(BASE, extreme="FOV 1 deg"), nine)
    assert all(link.dc_gain > 0 for link in runs["backward"].links)
    links = runs["forward"].links
    zero = [link.receiver for link in links if link.dc_gain == 0 and link.dc_gain_stderr == 0]
    wide = [link.receiver for link in links if link.dc_gain > 0 and link.dc_gain_stderr >= 0.5 * link.dc_gain]
    counted = [int(w.split()[0]) for w in runs["forward"].warnings if "unreliable error bar" in w]
    assert zero and wide  # what the run reports today: some links never reached, the others from one hit
    assert counted and counted[0] == len(zero) + len(wide), f"{zero} at 0 ± 0 not in {runs['forward'].warnings}"


PEAKED = dict(BASE, medium="homogeneous", algorithm="5")
#: (cell, the words of the peaked-phase warning, or None where the phase lobe covers the run): the cells whose
#: z reached 7-46 at |g| = 0.999 before the warning (spectral, mirror, backward peak with reflections) and
#: the ones that held (forward peak, diffuse walls; g = 0.7).
PEAKED_CASES = {
    "spectral": (dict(PEAKED, spectral="on", extreme="g +0.999"), "off in spectral scenes"),
    "mirror": (dict(PEAKED, surfaces="mirror", extreme="g -0.999"), "mirror images"),
    "backward peak, reflections": (dict(PEAKED, extreme="g -0.999"), "scatter back off the walls"),
    "forward peak, diffuse walls": (dict(PEAKED, extreme="g +0.999"), None),
    "g = 0.7, spectral": (dict(PEAKED, spectral="on", extreme="none"), None),
}


@pytest.mark.parametrize("case", sorted(PEAKED_CASES))
def test_a_peaked_phase_the_lobe_does_not_cover_is_flagged_unreliable(case):
    import owcsim

    cell, words = PEAKED_CASES[case]
    result = owcsim.simulate(matrix.scene(cell, paths=1024))
    peaked = [w for w in result.warnings if "phase function peaks" in w]
    if words is None:
        assert not peaked, peaked
    else:
        assert len(peaked) == 1 and words in peaked[0] and "unreliable error bar" in peaked[0], result.warnings
