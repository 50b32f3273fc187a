"""The command line: outputs, overrides, located errors, exit codes."""

import json
import subprocess
import sys
from pathlib import Path

import pytest

from owcsim.cli import main
from tests.scenes import EXAMPLES

BARRY = str(EXAMPLES / "barry_config_a.json")


def test_run_writes_result_csv_png(tmp_path, capsys):
    out = tmp_path / "out"
    assert (
        main(
            [
                "run",
                BARRY,
                "--out",
                str(out),
                "--paths",
                "4000",
                "--seed",
                "3",
                "--max-reflections",
                "2",
                "--set",
                "receivers.0.fov_deg=60",
                "--set",
                'simulation.direction="forward"',
            ]
        )
        == 0
    )
    res = json.loads((out / "result.json").read_text())
    link = res["links"][0]
    for key in (
        "transmitter",
        "receiver",
        "dc_gain",
        "dc_gain_stderr",
        "mean_delay_s",
        "rms_delay_spread_s",
        "dc_gain_by_reflection_order",
    ):
        assert key in link
    assert len(link["dc_gain_by_reflection_order"]) == 3
    assert res["scene"]["receivers"][0]["fov_deg"] == 60  # the exact inputs are echoed
    assert res["scene"]["simulation"]["paths"] == 4000 and res["scene"]["simulation"]["seed"] == 3
    assert link["direction"] == "forward" and link["paths"] == 4000
    csv = (out / "cir.csv").read_text().splitlines()
    assert csv[0].startswith("transmitter,receiver,t_start_s,t_end_s,h_per_s")
    assert len(csv) == 1 + res["time_bins"]["n_bins"]
    assert (out / "cir.svg").read_text().startswith("<svg ")  # formats/svg.py: no matplotlib
    assert not (out / "cir.png").exists()
    assert "H0 =" in capsys.readouterr().out


def test_target_rel_error_flag_replaces_paths(tmp_path):
    out = tmp_path / "o"
    assert main(["run", BARRY, "--out", str(out), "--target-rel-error", "0.02", "--max-reflections", "1"]) == 0
    res = json.loads((out / "result.json").read_text())
    assert res["run"]["stop_reason"] == "target_reached"
    assert res["scene"]["simulation"]["paths"] is None


def test_validate_reports_located_errors(tmp_path, capsys):
    doc = json.loads(Path(BARRY).read_text())
    doc["receivers"][0]["fov_deg"] = 120
    doc["room"]["reflectance"]["floor"] = 1.5
    bad = tmp_path / "bad.json"
    bad.write_text(json.dumps(doc))
    assert main(["validate", str(bad)]) == 2
    err = capsys.readouterr().err
    assert "receivers.0.fov_deg" in err and "room.reflectance.floor" in err and "Traceback" not in err
    assert main(["validate", BARRY]) == 0


@pytest.mark.parametrize(
    "args,message",
    [
        (["--set", "receivers.5.fov_deg=60"], "not an index"),
        (["--set", "nonsense"], "PATH=VALUE"),
        (["--algorithm", "7"], "simulation.algorithm"),
    ],
)
def test_bad_overrides_are_errors(tmp_path, capsys, args, message):
    assert main(["run", BARRY, "--out", str(tmp_path), "--paths", "100", *args]) == 2
    assert message in capsys.readouterr().err


def test_not_json_is_an_error(tmp_path, capsys):
    p = tmp_path / "x.json"
    p.write_text("{ nope")
    assert main(["validate", str(p)]) == 2
    assert "not valid JSON" in capsys.readouterr().err


def test_entry_point_runs_as_module(tmp_path):
    proc = subprocess.run([sys.executable, "-m", "owcsim", "validate", BARRY], capture_output=True, text=True)
    assert proc.returncode == 0 and "valid" in proc.stdout


def test_unreadable_scene_and_unusable_out_folder_are_errors(tmp_path, capsys):
    (tmp_path / "folder.json").mkdir()
    (tmp_path / "binary.json").write_bytes(b"\xff\xfe{}")
    (tmp_path / "afile").write_text("")
    cases = [
        (["validate", str(tmp_path / "folder.json")], "cannot read it"),
        (["validate", str(tmp_path / "binary.json")], "not a UTF-8 text file"),
        (["run", BARRY, "--out", str(tmp_path / "afile"), "--paths", "64"], "cannot use it as the output folder"),
        (["run", BARRY, "--out", str(tmp_path / "afile" / "sub"), "--paths", "64"], "cannot use it as the output"),
    ]
    for argv, message in cases:
        assert main(argv) == 2, argv
        assert message in capsys.readouterr().err


def test_a_zero_delay_spread_prints_as_zero(tmp_path, capsys):
    # Line of sight only: tau_rms is exactly 0 (printed as such, not as nan).
    assert main(["run", BARRY, "--out", str(tmp_path), "--paths", "256", "--set", "room=null"]) == 0
    assert "tau_rms = 0.000 ns" in capsys.readouterr().out


def test_json_python_cannot_use_is_an_error_not_a_trace(tmp_path, capsys):
    big = tmp_path / "big.json"
    big.write_text('{"simulation": {"seed": ' + "9" * 5000 + "}}")  # past the 4300-digit integer limit
    deep = tmp_path / "deep.json"
    deep.write_text("[" * 100_000 + "]" * 100_000)
    for path, message in ((big, "not usable JSON"), (deep, "nested too deeply")):
        assert main(["validate", str(path)]) == 2
        assert message in capsys.readouterr().err
    assert main(["validate", BARRY, "--set", "simulation.seed=" + "9" * 5000]) == 2
    assert "--set simulation.seed: the value is not usable JSON" in capsys.readouterr().err


def test_validate_a_scene_with_an_automatic_window(tmp_path, capsys):
    """The default scene leaves t_max_s automatic: validate says so instead of failing."""
    doc = json.loads(Path(BARRY).read_text())
    doc["simulation"] = {}
    scene = tmp_path / "auto.json"
    scene.write_text(json.dumps(doc))
    assert main(["validate", str(scene)]) == 0
    assert "chosen when it runs" in capsys.readouterr().out


def test_validate_counts_masked_grid_points_not_their_orientation_samples(tmp_path, capsys):
    doc = json.loads(Path(BARRY).read_text())
    doc["receiver_grids"] = [
        {"id_prefix": "g", "origin": [1.0, 1.0, 0.8], "size": [2.0, 2.0], "shape": [3, 3], "area": 1e-4,
         "exclude": [{"min": [-0.1, -0.1], "max": [0.1, 0.1]}], "orientation": {"samples": 8}}
    ]  # fmt: skip
    scene = tmp_path / "held.json"
    scene.write_text(json.dumps(doc))
    assert main(["validate", str(scene)]) == 0
    assert "(1 grid points masked)" in capsys.readouterr().out


def test_version_flag(capsys):
    with pytest.raises(SystemExit) as exc:
        main(["--version"])
    assert exc.value.code == 0 and capsys.readouterr().out.startswith("owcsim ")


def test_algorithm_flag_takes_auto(tmp_path, capsys):
    out = tmp_path / "o"
    assert (
        main(["run", BARRY, "--out", str(out), "--paths", "2000", "--max-reflections", "1", "--algorithm", "auto"]) == 0
    )
    res = json.loads((out / "result.json").read_text())
    assert res["scene"]["simulation"]["algorithm"] == "auto" and res["algorithm"] == 1  # no medium: vacuum paths


@pytest.mark.parametrize("algorithm,extra,S", [(4, [], 2), (2, [], 1), (4, ["simulation.max_scattering=1"], 1)])
def test_algorithm_flag_drops_an_s_the_algorithm_cannot_honour(tmp_path, algorithm, extra, S):
    """The smoky room's S = 20 is algorithm 5's: `--algorithm N` leaves it out where N cannot honour it (N counts
    its own orders); a `--set` of S still wins."""
    out = tmp_path / "o"
    sets = [arg for e in extra for arg in ("--set", e)]
    smoky = str(EXAMPLES / "smoky_room.json")
    args = ["run", smoky, "--out", str(out), "--paths", "300", "--max-reflections", "1", "--no-plot"]
    assert main(args + ["--algorithm", str(algorithm)] + sets) == 0
    res = json.loads((out / "result.json").read_text())
    assert res["modeled"]["max_scattering"] == S and len(res["links"][0]["dc_gain_by_scattering_order"]) == S + 1


def test_algorithm_flag_with_an_s_it_cannot_honour_set_is_refused(tmp_path, capsys):
    smoky = str(EXAMPLES / "smoky_room.json")
    args = ["run", smoky, "--out", str(tmp_path / "o"), "--algorithm", "4", "--set", "simulation.max_scattering=7"]
    assert main(args) == 2
    err = capsys.readouterr().err
    assert "`max_scattering` 7 cannot be honoured: give 1 or 2" in err and "Traceback" not in err


def test_plot_format_png_draws_with_matplotlib(tmp_path):
    out = tmp_path / "o"
    assert main(["run", BARRY, "--out", str(out), "--paths", "2000", "--plot-format", "png"]) == 0
    assert (out / "cir.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" and not (out / "cir.svg").exists()


def test_default_plot_imports_no_matplotlib(tmp_path):
    """The default figure is SVG written directly: the command never imports matplotlib (nor trimesh, scipy)."""
    out = tmp_path / "o"
    code = (
        "import sys; from owcsim.cli import main; "
        f"assert main(['run', {BARRY!r}, '--out', {str(out)!r}, '--paths', '2000']) == 0; "
        "print(sorted(m for m in ('matplotlib', 'trimesh', 'scipy') if m in sys.modules))"
    )
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True, cwd=tmp_path)
    assert proc.stdout.strip().splitlines()[-1] == "[]"
    assert sorted(p.name for p in out.iterdir()) == ["cir.csv", "cir.svg", "links.csv", "result.json"]


def test_map_heatmaps_are_svg_png_or_none(tmp_path):
    """A map's heatmaps follow --plot-format; --no-plot draws none (the netCDF and .mat files stay)."""
    doc = json.loads((EXAMPLES / "komine_map.json").read_text())
    doc["receiver_grids"][0]["spacing"] = 1.225  # 5 x 5 points
    doc["simulation"] = {"max_reflections": 0}
    scene = tmp_path / "map.json"
    scene.write_text(json.dumps(doc))
    drawn = {}
    for flags, ext in (([], "svg"), (["--plot-format", "png"], "png"), (["--no-plot"], None)):
        out = tmp_path / f"o{ext}"
        assert main(["run", str(scene), "--out", str(out), *flags]) == 0
        names = {p.name for p in out.iterdir()}
        assert {"result.json", "links.csv", "map_plane.nc", "maps.mat"} <= names
        drawn[ext] = sorted(n for n in names if n.startswith("map_plane_"))
    assert "map_plane_ceiling_illuminance_lx.svg" in drawn["svg"] and drawn[None] == []
    assert [n.replace(".svg", ".png") for n in drawn["svg"]] == drawn["png"]


def test_no_plot_skips_the_figure_and_matplotlib(tmp_path):
    """--no-plot writes every file but the figure, and the command never imports matplotlib (nor trimesh, scipy)."""
    out = tmp_path / "o"
    code = (
        "import sys; from owcsim.cli import main; "
        f"assert main(['run', {BARRY!r}, '--out', {str(out)!r}, '--paths', '2000', '--no-plot']) == 0; "
        "print(sorted(m for m in ('matplotlib', 'trimesh', 'scipy') if m in sys.modules))"
    )
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True, cwd=tmp_path)
    assert proc.stdout.strip().splitlines()[-1] == "[]"
    assert sorted(p.name for p in out.iterdir()) == ["cir.csv", "links.csv", "result.json"]


def test_progress_bar_draws_the_engines_progress_on_a_terminal_only():
    import io

    from owcsim.cli import _progress_bar
    from owcsim.engine.run.simulate import Progress

    class Terminal(io.StringIO):
        def isatty(self):
            return True

    for stream, drawn in ((Terminal(), True), (io.StringIO(), False)):
        update, close = _progress_bar(stream)
        update(Progress(fraction=1.0, paths=2048, batches=2, dc_gain_rel_stderr=0.01, elapsed_s=0.5))
        close()
        text = stream.getvalue()
        assert (
            (
                text.startswith("\r[")
                and "100.0%" in text
                and "2,048 paths" in text
                and "rel.err(H0) 1.00e-02" in text
                and text.endswith("0.5 s\n")
            )
            if drawn
            else text == ""
        )
