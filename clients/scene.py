"""The scene document a client sends: from a SceneSpec, a dict or a JSON file, files made self-contained.

The server takes no file paths: a mesh or a luminaire's photometric file given as `file` is
read here (relative to the scene file's folder, or `base_dir`) and sent as `data_base64` +
`format`. Both go through one reader, `read_input_file`: only a regular file is read (not a
FIFO, a device, a folder or a symbolic link: a scene document from elsewhere must not make
you upload any file you can read), and at most `MAX_MESH_BYTES` (meshes) or
`MAX_PHOTOMETRY_BYTES` (photometric files). A scene file itself is read through
`read_scene_file` (at most `MAX_SCENE_BYTES`, the command line's bound).
"""

from __future__ import annotations

import base64
import copy
import errno
import io
import json
import os
import stat
import zipfile
from pathlib import Path

from owcsim.docs import MAX_SCENE_BYTES
from owcsim.schemas import SceneSpec


class InputFileError(ValueError):
    """A file named by a scene that the client will not read: not a regular file, a symbolic link, too large,
    unreadable. The message names the file."""


class MeshFileError(InputFileError):
    """A mesh `file` the client will not read: not a regular file, a symbolic link, too large."""


class PhotometryFileError(InputFileError):
    """A luminaire's photometric `file` (.ies, .ldt) the client will not read: as MeshFileError."""


#: Largest mesh file read for a submission [bytes] (the server's default body limit).
MAX_MESH_BYTES = 32 * 2**20
#: Largest photometric file read for a submission [bytes]: the largest EULUMDAT table (721 C planes x 361
#: angles) is about 2 MB of text.
MAX_PHOTOMETRY_BYTES = 4 * 2**20
#: Largest frames input read for a submission [bytes]: a netCDF file, or an FDS case folder (all its files).
MAX_FRAMES_BYTES = 24 * 2**20  # base64 makes it 32 MiB: the default max_body_bytes

_OPEN_FLAGS = os.O_RDONLY | os.O_NONBLOCK | getattr(os, "O_CLOEXEC", 0)


def read_input_file(
    path: Path,
    what: str,
    max_bytes: int,
    error: type[InputFileError] = InputFileError,
    *,
    follow_links: bool = False,
    regular_only: bool = True,
) -> bytes:
    """The bytes of the file `path` (`what` names it in messages: "mesh file"), at most `max_bytes`.

    FileNotFoundError if it does not exist; `error` (an InputFileError) naming the path if it is a symbolic
    link (unless `follow_links`), not a regular file (a FIFO, a device, a folder; unless `regular_only` is
    False, for a scene file named on the command line, which may be a pipe such as `<(...)`; a folder is
    always refused), larger than `max_bytes`, or unreadable. Opened without following a final symbolic link
    and without blocking (a FIFO would wait for a writer forever), then checked on the open descriptor;
    at most `max_bytes` + 1 bytes are ever read (/dev/zero is refused, not read until memory runs out).
    """
    name = f"{what} {str(path)!r}"
    flags = _OPEN_FLAGS if follow_links else _OPEN_FLAGS | os.O_NOFOLLOW
    if not regular_only:
        flags &= ~os.O_NONBLOCK  # a pipe given on purpose is read as it comes
    try:
        fd = os.open(path, flags)
    except ValueError:  # a NUL byte in the name
        raise error(f"{name} is not a usable file name (it contains a NUL byte)") from None
    except OSError as exc:
        if not follow_links and os.path.islink(path):
            raise error(f"{name} is a symbolic link: give the file itself") from None
        if exc.errno in (errno.ENOENT, errno.ENOTDIR):
            raise FileNotFoundError(f"{name}: {exc.strerror}") from None
        raise error(f"{name}: cannot read it ({exc.strerror})") from None
    try:
        st = os.fstat(fd)
        if stat.S_ISDIR(st.st_mode) or (regular_only and not stat.S_ISREG(st.st_mode)):
            kind = "a folder" if stat.S_ISDIR(st.st_mode) else "a FIFO" if stat.S_ISFIFO(st.st_mode) else "a device"
            raise error(f"{name} is {kind}, not a regular file")
        if st.st_size > max_bytes:
            raise error(f"{name} has {st.st_size:,d} bytes, more than the {max_bytes:,d} a submission takes")
        chunks, size = [], 0
        while size <= max_bytes:  # a device or a pipe has no size: read until the end or the limit
            chunk = os.read(fd, min(max_bytes + 1 - size, 2**20))
            if not chunk:
                break
            chunks.append(chunk)
            size += len(chunk)
    except OSError as exc:
        raise error(f"{name}: cannot read it ({exc.strerror})") from None
    finally:
        os.close(fd)
    if size > max_bytes:  # it grew while being read, or a device without end
        raise error(f"{name} has more than {max_bytes:,d} bytes, more than a submission takes")
    return b"".join(chunks)


def read_mesh_file(path: Path, max_bytes: int = MAX_MESH_BYTES) -> bytes:
    """The bytes of a mesh file: `read_input_file` with MeshFileError."""
    return read_input_file(path, "mesh file", max_bytes, MeshFileError)


def read_photometry_file(path: Path, max_bytes: int = MAX_PHOTOMETRY_BYTES) -> bytes:
    """The bytes of a photometric file (.ies, .ldt): `read_input_file` with PhotometryFileError."""
    return read_input_file(path, "photometric file", max_bytes, PhotometryFileError)


def read_scene_file(path: Path, max_bytes: int = MAX_SCENE_BYTES) -> bytes:
    """The bytes of a scene file named by its user: `read_input_file` following symbolic links and reading
    pipes (`<(...)`), but never a folder and never more than `max_bytes` (InputFileError)."""
    return read_input_file(path, "scene file", max_bytes, follow_links=True, regular_only=False)


def scene_document(scene: SceneSpec | dict | str | Path, base_dir: str | Path | None = None) -> dict:
    """The JSON document to submit. A str or Path is a scene file; its folder resolves mesh files."""
    if isinstance(scene, (str, Path)):
        path = Path(scene)
        doc = json.loads(read_scene_file(path))
        base_dir = path.resolve().parent if base_dir is None else base_dir
    elif isinstance(scene, SceneSpec):
        doc = scene.model_dump(mode="json", exclude_unset=True)
    elif isinstance(scene, dict):
        doc = copy.deepcopy(scene)
    else:
        raise TypeError(f"a scene is a SceneSpec, a dict or a path to a JSON file, not {type(scene).__name__}")
    return inline_mesh_files(doc, Path(base_dir) if base_dir is not None else Path.cwd())


def inline_mesh_files(doc: dict, base_dir: Path) -> dict:
    """Replace each mesh's `file` by its content (`data_base64`) and `format` (from the suffix if not given)."""
    for mesh in doc.get("meshes") or []:
        if isinstance(mesh, dict) and isinstance(mesh.get("file"), str):
            path = Path(mesh.pop("file"))
            path = path if path.is_absolute() else base_dir / path
            data = read_mesh_file(path)
            if not mesh.get("format"):
                mesh["format"] = path.suffix[1:].lower() or None
            mesh["data_base64"] = base64.b64encode(data).decode("ascii")
    for tx in doc.get("transmitters") or []:  # luminaires' photometric files (.ies, .ldt), likewise
        phot = tx.get("photometry") if isinstance(tx, dict) else None
        if isinstance(phot, dict) and isinstance(phot.get("file"), str):
            path = Path(phot.pop("file"))
            path = path if path.is_absolute() else base_dir / path
            data = read_photometry_file(path)
            if not phot.get("format"):
                phot["format"] = path.suffix[1:].lower() or None
            phot["data_base64"] = base64.b64encode(data).decode("ascii")
    timeline = doc.get("timeline")
    frames = timeline.get("frames") if isinstance(timeline, dict) else None
    if isinstance(frames, dict) and isinstance(frames.get("path"), str):  # smoke over time: a file or FDS case
        path = Path(frames.pop("path"))
        path = path if path.is_absolute() else base_dir / path
        data = (
            _fds_case_zip(path)
            if frames.get("type") == "fds"
            else read_input_file(path, "frames file", MAX_FRAMES_BYTES)
        )
        frames["data_base64"] = base64.b64encode(data).decode("ascii")
    return doc


def _fds_case_zip(path: Path, max_bytes: int = MAX_FRAMES_BYTES) -> bytes:
    """A zip archive of the FDS case at `path` (its folder, or its .smv file's folder): every regular file of
    the folder but fdsreader's cache (*.pickle), each read by `read_input_file`, at most `max_bytes` in all."""
    folder = path.parent if path.suffix == ".smv" else path
    if not folder.is_dir():
        raise InputFileError(f"FDS case {str(path)!r} is not a folder holding a .smv file")
    names = sorted(p for p in folder.iterdir() if p.suffix != ".pickle" and not p.is_symlink() and p.is_file())
    if not any(p.suffix == ".smv" for p in names):
        raise InputFileError(f"FDS case {str(folder)!r} holds no .smv file")
    buffer, left = io.BytesIO(), max_bytes
    with zipfile.ZipFile(buffer, "w", zipfile.ZIP_DEFLATED) as archive:
        for p in names:
            data = read_input_file(p, "FDS output file", left)
            left -= len(data)
            archive.writestr(p.name, data)
    return buffer.getvalue()
