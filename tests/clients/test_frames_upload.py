"""The client sends a timeline's frames file (netCDF) or FDS case folder as `data_base64` (the server refuses
paths); the engine reads the upload to the same frames as the path."""

import numpy as np
import pytest

from owcsim.clients.scene import InputFileError, scene_document
from owcsim.engine.media.frame_sources import frames_from_spec
from owcsim.schemas.frames import FdsFramesSpec
from tests.fds_data import office_fire

pytest.importorskip("fdsreader", reason="pip install 'owcsim[fire]' (scripts/test installs it)")


def _doc(frames):
    return {"timeline": {"frames": frames}}


def test_an_fds_case_folder_is_sent_as_a_zip_that_reads_to_the_same_frames(tmp_path):
    case = office_fire()
    frames = {
        "type": "fds",
        "path": str(case),
        "slice_id": "EXT_3D_CELL",
        "albedo": 0.2,
        "origin": [0, 0, 0],
        "times_s": [45.0, 90.0],
    }
    sent = scene_document(_doc(dict(frames)), base_dir=tmp_path)["timeline"]["frames"]
    assert "path" not in sent and len(sent["data_base64"]) > 1000
    by_path = frames_from_spec(FdsFramesSpec(**frames))
    by_upload = frames_from_spec(FdsFramesSpec(**sent))
    assert np.array_equal(by_path.sigma_t, by_upload.sigma_t) and np.array_equal(by_path.times, by_upload.times)
    assert by_path.sigma_t.max() > 1.0  # real smoke: the comparison is not of two empty grids


def test_a_missing_or_empty_fds_case_is_a_clear_error(tmp_path):
    with pytest.raises(InputFileError, match="not a folder"):
        scene_document(_doc({"type": "fds", "path": "nowhere", "origin": [0, 0, 0]}), base_dir=tmp_path)
    (tmp_path / "case").mkdir()
    with pytest.raises(InputFileError, match="no .smv"):
        scene_document(_doc({"type": "fds", "path": "case", "origin": [0, 0, 0]}), base_dir=tmp_path)
