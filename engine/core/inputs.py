"""Files a scene document names: given inline (base64) or as a path (command line only)."""

from __future__ import annotations

import base64
from pathlib import Path

from owcsim.engine.core.errors import SceneError


def read_input(
    file: str | None, data_base64: str | None, base_dir: Path | None, what: str
) -> tuple[bytes, Path | None]:
    """(bytes, path or None) of an input given as `file` (relative paths from `base_dir`, the scene file's
    folder) or inline as `data_base64`; SceneError "`what` ... not found" for a missing file."""
    if file is None:
        assert data_base64 is not None, f"{what}: neither a file nor inline data (the schema requires one)"
        return base64.b64decode(data_base64, validate=True), None
    path = Path(file)
    if not path.is_absolute() and base_dir is not None:
        path = base_dir / path
    if not path.is_file():
        raise SceneError(f"{what} {str(path)!r} not found")
    return path.read_bytes(), path
