"""The scene document a client sends: from a SceneSpec, a dict or a JSON file, meshes made self-contained.

The server takes no file paths: a mesh given as `file` is read here (relative to the
scene file's folder, or `base_dir`) and sent as `data_base64` + `format`. Only a regular
file is read (not a FIFO, a device or a symbolic link: a scene document from elsewhere must
not make you upload any file you can read), and at most `MAX_MESH_BYTES`.
"""

from __future__ import annotations

import base64
import copy
import json
import os
import stat
from pathlib import Path

from owcsim.schemas import SceneSpec


class MeshFileError(ValueError):
    """A mesh `file` the client will not read: not a regular file, a symbolic link, too large."""


#: Largest mesh file read for a submission [bytes] (the server's default body limit).
MAX_MESH_BYTES = 32 * 2**20


def read_mesh_file(path: Path, max_bytes: int = MAX_MESH_BYTES) -> bytes:
    """The bytes of a regular file of at most `max_bytes`; FileNotFoundError or MeshFileError naming
    the path otherwise. Opened without following a final symbolic link and without blocking
    (a FIFO would wait for a writer forever), then checked on the open descriptor."""
    try:
        fd = os.open(path, os.O_RDONLY | os.O_NOFOLLOW | os.O_NONBLOCK | getattr(os, "O_CLOEXEC", 0))
    except OSError as exc:
        if path.is_symlink():
            raise MeshFileError(f"mesh file {str(path)!r} is a symbolic link: give the file itself") from None
        raise FileNotFoundError(f"mesh file {str(path)!r}: {exc.strerror}") from None
    with os.fdopen(fd, "rb") as f:
        st = os.fstat(f.fileno())
        if not stat.S_ISREG(st.st_mode):
            raise MeshFileError(f"mesh file {str(path)!r} is not a regular file (a FIFO, device or folder)")
        if st.st_size > max_bytes:
            raise MeshFileError(
                f"mesh file {str(path)!r} has {st.st_size:,d} bytes, more than the {max_bytes:,d} a submission takes"
            )
        data = f.read(max_bytes + 1)
    if len(data) > max_bytes:  # it grew while being read
        raise MeshFileError(f"mesh file {str(path)!r} has more than {max_bytes:,d} bytes")
    return data


def scene_document(scene: SceneSpec | dict | str | Path, base_dir: str | Path | None = None) -> dict:
    """The JSON document to submit. A str or Path is a scene file; its folder resolves mesh files."""
    if isinstance(scene, (str, Path)):
        path = Path(scene)
        doc = json.loads(path.read_text())
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
            try:
                data = path.read_bytes()
            except OSError as exc:
                raise FileNotFoundError(f"photometric file {str(path)!r}: {exc.strerror}") from None
            if not phot.get("format"):
                phot["format"] = path.suffix[1:].lower() or None
            phot["data_base64"] = base64.b64encode(data).decode("ascii")
    return doc
