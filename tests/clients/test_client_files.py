"""Files the client reads, and tables in documents (issue 25, items 6, 7, 8, 12).

- Mesh and photometric files named by a scene go through one reader (clients.scene.read_input_file):
  a FIFO, a device, a folder, a symbolic link, a file over the limit or an unreadable one is refused
  with an InputFileError naming the file, at once; before, a photometric FIFO hung, /dev/zero was read
  until memory ran out and links were followed; a mesh folder raised IsADirectoryError.
- Scene files (the client's `scene_document`, the command line's `load_scene`) are read up to
  MAX_SCENE_BYTES: /dev/zero is refused, not read until memory runs out.
- Photometric tables with a value past the float max (as written, or once the candela multiplier or
  the conversion factor is applied) are refused naming the line and the angles, not as "every intensity
  is 0"; a table whose luminous flux exceeds 1e8 lm is refused; over HTTP all these are 422 problems
  located at the transmitter's `data_base64`, never a 500.

Every read that could hang or eat memory on the old code runs in a forked child with a 1 GiB address
space, killed after 10 s, so the test fails instead of stalling or swapping.
"""

from __future__ import annotations

import base64
import json
import multiprocessing as mp
import os
import re
import resource
import sys

import numpy as np
import pytest

from owcsim.clients import scene as client_scene
from owcsim.engine.sources.photometry import Photometry, PhotometryError
from owcsim.engine.sources.photometry_files import parse_ies, parse_ldt
from tests.engine.test_photometry import ies_text, ldt_text
from tests.server.helpers import app_client, quick_doc

G5 = np.arange(0.0, 95.0, 5.0)  # vertical angles of the test tables [deg]
IS_ROOT = hasattr(os, "geteuid") and os.geteuid() == 0


# ----------------------------------------------------------------------------- reads in a bounded child
def _address_space() -> int:
    """This process's virtual memory size [bytes] (VmSize): a forked child starts with it."""
    with open("/proc/self/status") as f:
        return next(int(line.split()[1]) * 1024 for line in f if line.startswith("VmSize:"))


def _child(conn, fn, args):
    cap = _address_space() + 2**30  # 1 GiB beyond what the child inherits (the test process's size varies)
    resource.setrlimit(resource.RLIMIT_AS, (cap, cap))
    try:
        fn(*args)
        conn.send(("returned", "", ""))
    except BaseException as exc:  # noqa: BLE001 (reported to the parent)
        conn.send((type(exc).__name__, str(exc), ",".join(c.__name__ for c in type(exc).__mro__)))


def _outcome(fn, *args, timeout: float = 10.0) -> tuple[str, str, str]:
    """(exception class name, message, names of its classes) of fn(*args) in a forked child; "hung" if it
    did not end within `timeout` seconds."""
    ctx = mp.get_context("fork")
    parent, child = ctx.Pipe(duplex=False)
    proc = ctx.Process(target=_child, args=(child, fn, args), daemon=True)
    proc.start()
    child.close()
    ready = parent.poll(timeout)
    out = parent.recv() if ready else ("hung", "", "")
    proc.kill()
    proc.join()
    return out


def _special(tmp_path, kind: str, content: bytes = b"solid x\nendsolid x\n", name: str = "file"):
    """A path of the given kind: fifo, device, symlink (to a readable file), folder, too-large, unreadable."""
    target = tmp_path / name
    if kind == "fifo":
        os.mkfifo(target)
    elif kind == "device":
        return "/dev/zero"
    elif kind == "symlink":
        (tmp_path / "secret").write_bytes(content)
        target.symlink_to(tmp_path / "secret")
    elif kind == "folder":
        target.mkdir()
    elif kind == "too-large":
        with open(target, "wb") as f:
            f.truncate(client_scene.MAX_MESH_BYTES + 1)  # sparse: no disk used
    elif kind == "unreadable":
        if IS_ROOT:  # root reads a file of mode 0; reading this regular file fails for everyone (EIO)
            return "/proc/self/mem"
        target.write_bytes(content)
        target.chmod(0)
    return str(target)


KINDS = ["fifo", "device", "symlink", "folder", "too-large", "unreadable"]


def _inline(doc, base):
    client_scene.scene_document(doc, base)


# ----------------------------------------------------------------------------- items 6 and 12: the reader
@pytest.mark.parametrize("kind", KINDS)
def test_6_photometric_files_get_the_checks_meshes_get(tmp_path, kind):
    path = _special(tmp_path, kind, ies_text(G5, [0.0], np.ones((1, len(G5)))).encode(), "lamp.ies")
    doc = quick_doc()
    doc["transmitters"][0]["photometry"] = {"file": path, "format": "ies"}
    name, msg, classes = _outcome(_inline, doc, tmp_path)
    assert "PhotometryFileError" in classes.split(","), (kind, name, msg)
    assert "InputFileError" in classes.split(",") and path in msg, msg


@pytest.mark.parametrize("kind", KINDS)
def test_12_mesh_files_of_every_kind_are_refused_with_the_mesh_file_error(tmp_path, kind):
    path = _special(tmp_path, kind, name="mesh.stl")
    doc = quick_doc()
    doc["meshes"] = [{"file": path, "reflectance": 0.5, "format": "stl"}]
    name, msg, classes = _outcome(_inline, doc, tmp_path)
    assert name == "MeshFileError" and path in msg, (kind, name, msg)  # a folder: IsADirectoryError before


def test_regular_files_are_inlined_and_missing_ones_are_file_not_found(tmp_path):
    ies = ies_text(G5, [0.0], np.ones((1, len(G5)))).encode()
    (tmp_path / "lamp.ies").write_bytes(ies)
    (tmp_path / "m.stl").write_bytes(b"solid x\nendsolid x\n")
    doc = quick_doc()
    doc["transmitters"][0]["photometry"] = {"file": "lamp.ies"}
    doc["meshes"] = [{"file": "m.stl", "reflectance": 0.5}]
    out = client_scene.scene_document(doc, tmp_path)
    phot = out["transmitters"][0]["photometry"]
    assert base64.b64decode(phot["data_base64"]) == ies and phot["format"] == "ies" and "file" not in phot
    assert out["meshes"][0]["format"] == "stl"
    for where in ("transmitters", "meshes"):
        bad = quick_doc()
        if where == "transmitters":
            bad["transmitters"][0]["photometry"] = {"file": "nope.ies"}
        else:
            bad["meshes"] = [{"file": "nope.stl", "reflectance": 0.5}]
        with pytest.raises(FileNotFoundError, match=re.escape(str(tmp_path / "nope"))):
            client_scene.scene_document(bad, tmp_path)


def test_a_file_exactly_at_the_limit_is_read_and_one_byte_more_is_refused(tmp_path):
    path = tmp_path / "lamp.ldt"
    path.write_bytes(b"x" * 1000)
    assert client_scene.read_photometry_file(path, max_bytes=1000) == b"x" * 1000
    path.write_bytes(b"x" * 1001)
    with pytest.raises(client_scene.PhotometryFileError, match="1,001 bytes, more than the 1,000"):
        client_scene.read_photometry_file(path, max_bytes=1000)
    assert client_scene.MAX_PHOTOMETRY_BYTES == 4 * 2**20 and client_scene.MAX_MESH_BYTES == 32 * 2**20


# ----------------------------------------------------------------------------- scene files
def _load_scene(path):
    from owcsim.docs import load_scene

    load_scene(path)


@pytest.mark.parametrize("reader", ["client", "cli"])
def test_a_scene_file_that_never_ends_is_refused_not_read_until_memory_runs_out(tmp_path, reader):
    fn = _inline if reader == "client" else _load_scene
    args = ("/dev/zero", tmp_path) if reader == "client" else ("/dev/zero",)
    name, msg, _ = _outcome(fn, *args)
    assert name in ("InputFileError", "InputError") and "more than 268,435,456 bytes" in msg, (name, msg)
    name, msg, _ = _outcome(fn, *((str(tmp_path),) + args[1:]))
    assert name in ("InputFileError", "InputError") and ("folder" in msg or "Is a directory" in msg), (name, msg)


def test_a_scene_given_as_a_pipe_is_still_read(tmp_path):
    import threading

    fifo = tmp_path / "scene.json"
    os.mkfifo(fifo)
    text = json.dumps(quick_doc()).encode()

    def write():
        with open(fifo, "wb") as f:
            f.write(text)

    t = threading.Thread(target=write, daemon=True)
    t.start()
    assert client_scene.scene_document(fifo)["simulation"]["paths"] == 2000  # `owcsim submit <(...)`
    t.join(5)


# ----------------------------------------------------------------------------- the command line
def test_owcsim_submit_says_which_photometric_file_it_refuses(tmp_path, capsys):
    from owcsim.cli import main

    (tmp_path / "secret").write_text("not for the server")
    (tmp_path / "lamp.ies").symlink_to(tmp_path / "secret")
    doc = quick_doc()
    tx = doc["transmitters"][0]
    for k in ("lambertian_order", "half_power_semi_angle_deg"):
        tx.pop(k, None)
    tx["photometry"] = {"file": "lamp.ies"}
    (tmp_path / "scene.json").write_text(json.dumps(doc))
    code = main(["submit", str(tmp_path / "scene.json"), "--server", "http://127.0.0.1:9", "--no-wait"])
    err = capsys.readouterr().err
    assert code == 2 and "photometric file" in err and "is a symbolic link" in err and "Traceback" not in err, err


# ----------------------------------------------------------------------------- item 8: tables past the float max
IES_ONES = ies_text(G5, [0.0, 90.0], np.full((2, len(G5)), 100.0))


def _ies_with(token: str, row: int, col: int, **kw) -> bytes:
    """The 2 x 19 IES table of 100 cd with entry (row, col) written as `token`."""
    values = [["100"] * len(G5) for _ in range(2)]
    values[row][col] = token
    text = ies_text(G5, [0.0, 90.0], np.full((2, len(G5)), 100.0), **kw)
    head, _, _ = text.partition("\r\n100 100")
    lines = head.split("\r\n")
    return ("\r\n".join(lines + [" ".join(r) for r in values]) + "\r\n").encode()


def test_8_an_ies_value_past_the_float_max_is_refused_naming_its_line_and_angles():
    parse_ies(_ies_with("100", 1, 3))  # the fixture itself is good
    with pytest.raises(PhotometryError) as err:
        parse_ies(_ies_with("1e999", 1, 3), "transmitters[0].photometry")
    msg = str(err.value)
    assert "line 13: the candela value at horizontal angle 90 deg, vertical angle 15 deg is '1e999'" in msg, msg
    assert "beyond the largest number a double holds" in msg and "emits nothing" not in msg
    with pytest.raises(PhotometryError) as err:  # finite as written, infinite with the multiplier
        parse_ies(_ies_with("1e300", 0, 18, multiplier=1e10))
    msg = str(err.value)
    assert "line 12: the candela value at horizontal angle 0 deg, vertical angle 90 deg (1e300)" in msg, msg
    assert "times the candela multiplier 1e+10 is beyond" in msg
    with pytest.raises(PhotometryError, match=r"line 6: the candela multiplier is '1e999', beyond"):
        parse_ies(ies_text(G5, [0.0], np.ones((1, len(G5)))).replace(" -1 1 19 ", " -1 1e999 19 ").encode())


def test_8_an_ldt_value_past_the_float_max_is_refused_naming_its_angles():
    c_all = np.arange(0.0, 360.0, 30.0)
    good = ldt_text(G5, c_all, np.full((12, len(G5)), 100.0), 0)
    parse_ldt(good.encode())
    lines = good.split("\n")
    first = len(lines) - 1 - 12 * len(G5)  # the first intensity's line (index), one value a line
    at = first + 2 * len(G5) + 4  # C plane 2 (60 deg), gamma index 4 (20 deg)
    bad = lines[:at] + ["1e999"] + lines[at + 1 :]
    with pytest.raises(PhotometryError) as err:
        parse_ldt("\n".join(bad).encode())
    msg = str(err.value)
    assert f"line {at + 1}: the intensity [cd/klm] at C 60 deg, gamma 20 deg is '1e999', beyond" in msg, msg
    with pytest.raises(PhotometryError, match="the conversion factor 1e\\+300 and the lamp flux 1000 lm / 1000 is"):
        parse_ldt(ldt_text(G5, c_all, np.full((12, len(G5)), 1e10), 0, factor=1e300).encode())
    with pytest.raises(PhotometryError, match="line 29: the luminous flux of lamp set 1 \\[lm\\] is '1e999'"):
        parse_ldt(ldt_text(G5, c_all, np.ones((12, len(G5))), 0).replace("\n1000\n", "\n1e999\n").encode())


def test_8_tables_given_directly_are_checked_and_normalised_without_overflow():
    with pytest.raises(PhotometryError, match="the intensity at C = 90 deg, gamma = 10 deg is nan, not a finite"):
        table = np.ones((3, len(G5)))
        table[1, 2] = np.nan
        Photometry.from_table(G5, [0.0, 90.0, 360.0], table)
    with pytest.raises(PhotometryError, match="luminous flux is beyond the largest number a double holds"):
        Photometry.from_table(G5, [0.0, 360.0], np.full((2, len(G5)), 1e308))
    with pytest.raises(
        PhotometryError,
        match=r"luminous flux is 6\.283e\+09 lm \(intensities up to 1e\+09 cd\), more than the 1e\+08 lm",
    ):
        Photometry.from_table(G5, [0.0, 360.0], np.full((2, len(G5)), 1e9))
    # a table of constant intensity I over gamma in [0, 90]: flux 2 pi I exactly; the response 1 / (2 pi)
    for intensity in (1.0, 1e7 / (2 * np.pi) * 0.999):
        p = Photometry.from_table(G5, [0.0, 360.0], np.full((2, len(G5)), intensity))
        assert p.flux == pytest.approx(2 * np.pi * intensity, rel=1e-12)
        assert np.allclose(p.intensity, 1 / (2 * np.pi), rtol=1e-12)


# ----------------------------------------------------------------------------- the service
def _photometry_doc(data: bytes) -> dict:
    doc = quick_doc()
    tx = doc["transmitters"][0]
    for k in ("lambertian_order", "half_power_semi_angle_deg"):
        tx.pop(k, None)
    tx["photometry"] = {"data_base64": base64.b64encode(data).decode(), "format": "ies"}
    return doc


def test_8_photometry_sent_over_http_with_values_past_the_float_max_is_a_located_422(tmp_path):
    cases = {
        "inf": (_ies_with("1e999", 0, 0), "is '1e999', beyond the largest number"),
        "nan": (_ies_with("nan", 0, 0), "candela values (1 of 38) should be a number, found 'nan'"),
        "1e308": (ies_text(G5, [0.0], np.full((1, len(G5)), 1e308)).encode(), "luminous flux is beyond"),
        "multiplier": (_ies_with("1e300", 0, 0, multiplier=1e10), "times the candela multiplier 1e+10"),
    }
    with app_client(tmp_path) as c:
        assert c.post("/v1/jobs", json=_photometry_doc(IES_ONES.encode())).status_code == 202
        for name, (data, message) in cases.items():
            r = c.post("/v1/jobs", json=_photometry_doc(data))
            assert r.status_code == 422, (name, r.status_code, r.text)
            (error,) = r.json()["errors"]
            assert error["loc"] == "body.transmitters.0.photometry.data_base64", (name, error)
            assert message in error["msg"] and "emits nothing" not in error["msg"], (name, error)


def test_7_a_tabulated_phase_function_at_the_float_max_is_accepted_over_http(tmp_path):
    c = np.linspace(-1.0, 1.0, 5)
    doc = quick_doc()
    doc["medium"] = {
        "type": "homogeneous",
        "sigma_a": 0.01,
        "sigma_s": 0.1,
        "phase": {"type": "tabulated", "cos_theta": c.tolist(), "values": [sys.float_info.max] * 5},
    }
    body = json.dumps(doc)
    with app_client(tmp_path) as client:
        r = client.post("/v1/jobs", content=body, headers={"content-type": "application/json"})
        assert r.status_code == 202, r.text
        for token in ("1e999", "NaN", "Infinity"):  # JSON Python reads as inf or nan: refused at the value
            # the second of the five values becomes the token
            bad = body.replace(repr(sys.float_info.max), token, 2).replace(token, repr(sys.float_info.max), 1)
            r = client.post("/v1/jobs", content=bad, headers={"content-type": "application/json"})
            assert r.status_code == 422, (token, r.text)
            (error,) = r.json()["errors"]
            assert error["loc"] == "body.medium.homogeneous.phase.tabulated.values.1", (token, error)


# ----------------------------------------------------------------------------- adversarial pass: other readers
def test_a_file_name_with_a_nul_byte_is_an_input_file_error_not_a_trace(tmp_path):
    doc = quick_doc()
    doc["meshes"] = [{"file": "a\x00b.stl", "reflectance": 0.5}]
    with pytest.raises(client_scene.MeshFileError, match="not a usable file name"):
        client_scene.scene_document(doc, tmp_path)


def _engine_read(path):
    from owcsim.engine.core.inputs import read_input

    read_input(path, None, None, "mesh file")


@pytest.mark.parametrize("kind", ["fifo", "device", "folder", "unreadable"])
def test_owcsim_run_names_a_fifo_device_or_folder_instead_of_not_found(tmp_path, kind):
    """`owcsim run` / `validate` read files through the engine: a FIFO or a device is refused at once with the
    right reason (it was 'not found'), an unreadable file is a SceneError (an OSError traceback before)."""
    path = _special(tmp_path, kind, name="mesh.stl")
    name, msg, _ = _outcome(_engine_read, path)
    says = {
        "fifo": " is a FIFO, not a regular file",
        "device": " is a device, not a regular file",
        "folder": " is a folder, not a regular file",
        "unreadable": ": cannot read it",
    }[kind]
    assert name == "SceneError" and f"mesh file {path!r}{says}" in msg, (name, msg)
    name, msg, _ = _outcome(_engine_read, str(tmp_path / "none.stl"))
    assert name == "SceneError" and "not found" in msg, (name, msg)
