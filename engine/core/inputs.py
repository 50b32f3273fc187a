"""Files a scene document names: given inline (base64) or as a path (command line only)."""

from __future__ import annotations

import base64
import stat
from pathlib import Path

from owcsim.engine.core.errors import SceneError


def read_input(
    file: str | None, data_base64: str | None, base_dir: Path | None, what: str
) -> tuple[bytes, Path | None]:
    """(bytes, path or None) of an input given as `file` (relative paths from `base_dir`, the scene file's
    folder) or inline as `data_base64`; SceneError "`what` ... not found" for a missing file, "... is a FIFO, not a
    regular file" for a FIFO, a device or a folder (which would hang or never end), "cannot read it" without
    permission. Read on the user's own machine (`owcsim run`, `validate`): symbolic links are followed."""
    if file is None:
        assert data_base64 is not None, f"{what}: neither a file nor inline data (the schema requires one)"
        return base64.b64decode(data_base64, validate=True), None
    path = Path(file)
    if not path.is_absolute() and base_dir is not None:
        path = base_dir / path
    try:
        mode = path.stat().st_mode
    except (OSError, ValueError):  # missing, a dangling link, a name with a NUL byte
        raise SceneError(f"{what} {str(path)!r} not found") from None
    if not stat.S_ISREG(mode):
        kind = "a folder" if stat.S_ISDIR(mode) else "a FIFO" if stat.S_ISFIFO(mode) else "a device"
        raise SceneError(f"{what} {str(path)!r} is {kind}, not a regular file")
    try:
        return path.read_bytes(), path
    except OSError as exc:  # no permission
        raise SceneError(f"{what} {str(path)!r}: cannot read it ({exc.strerror})") from None
