"""A luminaire's emission from a photometric file (IES LM-63 or EULUMDAT), for a transmitter.

The file is inline (`data_base64` + `format`) or, from the command line only, a `file`
path relative to the scene document (as meshes are). The luminaire's gamma = 0 axis
points along the transmitter's `normal` (its aiming direction); the C = 0 half-plane
contains `c0_direction` (default world +x, or +y for a luminaire aimed along x), turned
by `rotation_deg` about the aiming axis (C = 90 deg lies counter-clockwise seen from
behind the luminaire: from above a downlight).
"""

from __future__ import annotations

import base64
import binascii
import math
from typing import Literal

from pydantic import Field, model_validator

from .base import Direction, SpecModel

PHOTOMETRY_FORMATS = ("ies", "ldt")
#: Most angles on one axis of a photometric table (0.05 deg steps over 180 deg, 0.1 deg over 360 deg).
MAX_PHOTOMETRY_ANGLES = 3601
#: Most candela values of a photometric table: EULUMDAT's largest (721 C planes x 361 gamma angles).
MAX_PHOTOMETRY_CELLS = 721 * 361


class PhotometrySpec(SpecModel):
    """Photometric file of a luminaire and its orientation (type-C photometry)."""

    file: str | None = Field(
        None, description="path to a .ies or .ldt file, relative to the scene document (command line only)"
    )
    data_base64: str | None = Field(None, description="the file's content, base64")
    format: Literal["ies", "ldt"] | None = Field(None, description="file format; from the file suffix if omitted")
    c0_direction: Direction | None = Field(
        None, description="world direction of the C = 0 half-plane, made perpendicular to the aiming direction"
    )
    rotation_deg: float = Field(
        0.0,
        ge=-360.0,
        le=360.0,
        description="rotation of the C-planes about the aiming direction [deg]: positive turns C = 0 toward "
        "C = 90, counter-clockwise seen from behind the luminaire (from above a downlight)",
    )

    @model_validator(mode="after")
    def _one_source(self) -> "PhotometrySpec":
        if (self.file is None) == (self.data_base64 is None):
            raise ValueError("give exactly one of `file` and `data_base64` + `format`")
        if self.data_base64 is not None:
            if self.format is None:
                raise ValueError("`data_base64` needs `format` (ies or ldt)")
            try:
                base64.b64decode(self.data_base64, validate=True)
            except (binascii.Error, ValueError):
                raise ValueError("`data_base64` is not valid base64") from None
        if self.file is not None and self.format is None and self.suffix not in PHOTOMETRY_FORMATS:
            raise ValueError(f"cannot tell the format of {self.file!r}: give `format` (ies or ldt)")
        if not math.isfinite(self.rotation_deg):
            raise ValueError("rotation_deg must be finite")
        return self

    @property
    def suffix(self) -> str:
        return self.file.rsplit(".", 1)[-1].lower() if self.file and "." in self.file else ""

    @property
    def resolved_format(self) -> str:
        return self.format or self.suffix
