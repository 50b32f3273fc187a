"""Where the real FDS test case lives (FDS 6.9.1 output of an office fire; its README describes it).

Found from env OWCSIM_FDS_DATA, else `<repo>/../shared/data/fds`, else /work/shared/data/fds. Tests only
read it: fdsreader's cache file is switched off by the code under test and by `tests/fds_writer.read_back`.
"""

from __future__ import annotations

import os
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parent.parent


def fds_data_dir() -> Path | None:
    """The folder holding `office_fire/` (None when it is nowhere)."""
    candidates = [os.environ.get("OWCSIM_FDS_DATA"), REPO.parent / "shared" / "data" / "fds", "/work/shared/data/fds"]
    for c in candidates:
        if c and (Path(c) / "office_fire" / "office_fire.smv").is_file():
            return Path(c)
    return None


def office_fire() -> Path:
    """The office_fire case folder; skips the test when the data is not on this machine."""
    root = fds_data_dir()
    if root is None:
        pytest.skip("the FDS test data (office_fire) is not here: set OWCSIM_FDS_DATA to its folder")
    return root / "office_fire"
