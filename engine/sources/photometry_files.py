"""Photometric files: IES LM-63 (1986-2019) and EULUMDAT (.ldt) type-C tables read into a `Photometry`.

Errors name the file (`where`) and the line; the stored C planes are expanded to 0..360 deg by the
file's symmetry (none, rotational, bilateral about C0-C180 or C90-C270, quadrant).
"""

from __future__ import annotations

import math
import re
import sys
from dataclasses import dataclass

import numpy as np

from owcsim.engine.sources.photometry import Photometry, PhotometryError

# ----------------------------------------------------------------------------- symmetry
_FOLDS = {  # symmetry -> the maps C -> C' that leave the distribution unchanged [deg]
    "none": (lambda c: c,),
    "bilateral_c0_c180": (lambda c: c, lambda c: 360.0 - c),
    "bilateral_c90_c270": (lambda c: c, lambda c: 180.0 - c),
    "quadrant": (lambda c: c, lambda c: 360.0 - c, lambda c: 180.0 - c, lambda c: 180.0 + c),
}


def _expand(c_deg: np.ndarray, rows: np.ndarray, symmetry: str, where: str) -> tuple[np.ndarray, np.ndarray]:
    """Stored C planes (any subset of [0, 360)) and a symmetry -> full table on C in [0, 360]."""
    if symmetry == "rotational":
        return np.array([0.0, 360.0]), np.vstack([rows[0], rows[0]])
    values: dict[float, np.ndarray] = {}
    for fold in _FOLDS[symmetry]:
        for angle, row in zip(c_deg, rows):
            key = round(float(fold(angle)) % 360.0, 6)
            if key in values and not np.allclose(values[key], row, rtol=1e-6, atol=1e-9 * rows.max()):
                raise PhotometryError(
                    f"{where}: the C-plane at {key:g} deg is given twice with different "
                    f"intensities (symmetry {symmetry})"
                )
            values.setdefault(key, row)
    if 0.0 not in values:
        raise PhotometryError(f"{where}: no C-plane at 0 deg (or its mirror image): cannot cover 0..360 deg")
    keys = sorted(values)
    return np.array(keys + [360.0]), np.vstack([values[k] for k in keys] + [values[0.0]])


# ----------------------------------------------------------------------------- IES LM-63
_IES_TAGS = {
    "IESNA:LM-63-1995": "IES LM-63-1995",
    "IESNA:LM-63-2002": "IES LM-63-2002",
    "IES:LM-63-2019": "IES LM-63-2019",
    "IESNA91": "IES LM-63-1991",
    "IESNA:LM-63-1991": "IES LM-63-1991",
}
_NUMBER = re.compile(r"^[+-]?(\d+\.?\d*|\.\d+)([eE][+-]?\d+)?$")
_PAST_MAX = f"beyond the largest number a double holds ({sys.float_info.max:.4g})"


@dataclass(frozen=True)
class _TableNames:
    """How errors name a table's entries: the value, its row and column angles, the factor applied to it."""

    value: str  # "candela value"
    row: str  # "horizontal angle"
    rows: np.ndarray  # [deg]
    col: str  # "vertical angle"
    cols: np.ndarray  # [deg]
    factor: str  # "the candela multiplier 10"


class _Tokens:
    """Whitespace/comma separated numbers with their line numbers, for located errors."""

    def __init__(self, lines: list[str], first_line: int, where: str):
        self.items = [
            (tok, first_line + k) for k, line in enumerate(lines) for tok in re.split(r"[\s,]+", line.strip()) if tok
        ]
        self.pos, self.where = 0, where
        self.last_line = first_line + len(lines) - 1

    def number(self, what: str, *, integer: bool = False, finite: bool = True) -> float:
        """The next number; `finite`: one past the float max ('1e999') is refused here (a table's values are
        checked by `check_table`, which names their angles)."""
        if self.pos >= len(self.items):
            raise PhotometryError(f"{self.where}: the file ends (line {self.last_line}) before {what}")
        tok, line = self.items[self.pos]
        self.pos += 1
        if not _NUMBER.match(tok):
            raise PhotometryError(f"{self.where}: line {line}: {what} should be a number, found {tok!r}")
        val = float(tok)
        if finite and not math.isfinite(val):
            raise PhotometryError(f"{self.where}: line {line}: {what} is {tok!r}, {_PAST_MAX}")
        if integer and val != int(val):
            raise PhotometryError(f"{self.where}: line {line}: {what} should be a whole number, found {tok!r}")
        return val

    def numbers(self, n: int, what: str, *, finite: bool = True) -> np.ndarray:
        return np.array([self.number(f"{what} ({k + 1} of {n})", finite=finite) for k in range(n)])

    def check_table(self, start: int, table: np.ndarray, scaled: np.ndarray, names: _TableNames) -> None:
        """Refuse a table (read from token `start` on) with a value past the float max, as written or once
        `scaled` (the file's multiplier applied), naming its line, its angles and the token."""
        bad = np.argwhere(~np.isfinite(scaled))
        if not len(bad):
            return
        j, i = (int(x) for x in bad[0])
        tok, line = self.items[start + j * table.shape[1] + i]
        at = f"{names.row} {names.rows[j]:g} deg, {names.col} {names.cols[i]:g} deg"
        if not math.isfinite(table[j, i]):
            raise PhotometryError(f"{self.where}: line {line}: the {names.value} at {at} is {tok!r}, {_PAST_MAX}")
        raise PhotometryError(
            f"{self.where}: line {line}: the {names.value} at {at} ({tok}) times {names.factor} is {_PAST_MAX}"
        )

    def line(self) -> int:
        return self.items[min(self.pos, len(self.items) - 1)][1] if self.items else self.last_line


def _decode(data: bytes) -> list[str]:
    if data[:3] == b"\xef\xbb\xbf":
        data = data[3:]
    try:
        text = data.decode("utf-8")
    except UnicodeDecodeError:
        text = data.decode("latin-1")  # files from Windows tools; every byte decodes
    return text.replace("\r\n", "\n").replace("\r", "\n").split("\n")


def _check_angles(values: np.ndarray, what: str, lo: float, hi: float, where: str, line: int) -> None:
    if np.any(np.diff(values) <= 0):
        raise PhotometryError(f"{where}: near line {line}: {what} must increase strictly: {values.tolist()}")
    if values[0] < lo - 1e-9 or values[-1] > hi + 1e-9:
        raise PhotometryError(
            f"{where}: near line {line}: {what} must lie in [{lo:g}, {hi:g}] deg, found {values[0]:g}..{values[-1]:g}"
        )


@dataclass(frozen=True)
class _IesHeader:
    """The numbers of an IES file's header that the table needs."""

    n_lamps: float
    lumens: float  # per lamp [lm]; -1: absolute photometry
    multiplier: float  # candela multiplier
    n_v: int  # vertical angles
    n_h: int  # horizontal angles
    ballast: float  # ballast factor


def parse_ies(data: bytes, where: str = "photometry") -> Photometry:
    """Parse an IES LM-63 file (1986/1991/1995/2002/2019), type-C photometry.

    Layout (LM-63-2002 sec. 5, LM-63-2019 sec. 5): a version line, keyword lines,
    `TILT=NONE|INCLUDE` (tilt data is read and not applied: it corrects lamp output for
    a tilted HID lamp, and we take the luminaire as measured), then the numbers:
    lamps, lumens per lamp (-1: absolute photometry), candela multiplier, number of
    vertical and horizontal angles, photometric type (1 = C), units, width, length,
    height, ballast factor, a reserved/file-generation field, input watts, the vertical
    angles, the horizontal angles and the candela values (one row per horizontal angle).
    """
    lines = _decode(data)
    source, tok = _ies_preamble(lines, where)
    head = _ies_header(tok, where)
    n_v, n_h = head.n_v, head.n_h
    line = tok.line()
    v = tok.numbers(n_v, "vertical angles")
    _check_angles(v, "vertical angles", 0.0, 180.0, where, line)
    line = tok.line()
    h = tok.numbers(n_h, "horizontal angles")
    _check_angles(h, "horizontal angles", 0.0, 360.0, where, line)
    line, start = tok.line(), tok.pos
    cd = tok.numbers(n_h * n_v, "candela values", finite=False).reshape(n_h, n_v)
    if tok.pos < len(tok.items):
        extra, at = tok.items[tok.pos]
        raise PhotometryError(f"{where}: line {at}: unexpected value {extra!r} after the {n_h} x {n_v} candela table")
    if np.any(cd < 0):
        raise PhotometryError(f"{where}: near line {line}: negative candela values")
    with np.errstate(over="ignore"):
        scaled = cd * head.multiplier
    names = _TableNames(
        "candela value", "horizontal angle", h, "vertical angle", v, f"the candela multiplier {head.multiplier:g}"
    )
    tok.check_table(start, cd, scaled, names)
    symmetry, h, cd = _ies_symmetry(h, scaled, where, line)
    c_full, rows = _expand(h, cd, symmetry, where)
    declared = None if head.lumens == -1 else float(head.n_lamps * head.lumens * head.multiplier * head.ballast)
    return Photometry.from_table(
        v,
        c_full,
        rows,
        declared_flux=declared,
        source=source,
        symmetry=symmetry,
        where=where,
        candela_scale=head.ballast,
    )


def _ies_preamble(lines: list[str], where: str) -> tuple[str, _Tokens]:
    """(the LM-63 version, the numbers after the TILT line and its tilt data)."""
    first = lines[0].strip() if lines else ""
    source = _IES_TAGS.get(first.upper(), "IES LM-63-1986")
    if source == "IES LM-63-1986" and first.upper().startswith("IES"):
        raise PhotometryError(
            f"{where}: line 1: unknown IES version tag {first!r} (known: {', '.join(sorted(_IES_TAGS))})"
        )
    tilt = next((k for k, line in enumerate(lines) if line.strip().upper().startswith("TILT")), None)
    if tilt is None:
        raise PhotometryError(f"{where}: no TILT= line: not an IES LM-63 file")
    mode = lines[tilt].split("=", 1)[1].strip().upper() if "=" in lines[tilt] else ""
    tok = _Tokens(lines[tilt + 1 :], tilt + 2, where)
    if mode == "INCLUDE":
        tok.number("the lamp-to-luminaire geometry (TILT=INCLUDE)", integer=True)
        n_tilt = int(tok.number("the number of tilt angles", integer=True))
        tok.numbers(n_tilt, "tilt angles")
        tok.numbers(n_tilt, "tilt multiplying factors")
    elif mode != "NONE":
        raise PhotometryError(
            f"{where}: line {tilt + 1}: TILT={mode or '?'} names an external tilt file; "
            "only TILT=NONE or TILT=INCLUDE can be read"
        )
    return source, tok


def _ies_header(tok: _Tokens, where: str) -> _IesHeader:
    """The header numbers (lamps .. input watts), checked."""
    n_lamps = tok.number("the number of lamps", integer=True)
    lumens = tok.number("the lumens per lamp")
    multiplier = tok.number("the candela multiplier")
    line = tok.line()
    n_v = int(tok.number("the number of vertical angles", integer=True))
    n_h = int(tok.number("the number of horizontal angles", integer=True))
    ptype = int(tok.number("the photometric type", integer=True))
    tok.number("the units type", integer=True)
    for what in ("the luminous width", "the luminous length", "the luminous height"):
        tok.number(what)
    ballast = tok.number("the ballast factor")
    tok.number("the ballast-lamp factor / file generation type")
    tok.number("the input watts")
    if n_lamps < 1 or not (lumens > 0 or lumens == -1) or not multiplier > 0 or not ballast > 0:
        raise PhotometryError(
            f"{where}: near line {line}: need lamps >= 1, lumens per lamp > 0 (or -1), "
            f"candela multiplier > 0 and ballast factor > 0; found {n_lamps:g}, {lumens:g}, "
            f"{multiplier:g}, {ballast:g}"
        )
    if ptype != 1:
        raise PhotometryError(
            f"{where}: near line {line}: photometric type {ptype} ({'B' if ptype == 2 else 'A'}) "
            "is not supported: owcsim reads type C (1), the type of indoor luminaires"
        )
    if n_v < 2 or n_h < 1:
        raise PhotometryError(
            f"{where}: near line {line}: need at least 2 vertical angles and 1 horizontal angle, found {n_v} and {n_h}"
        )
    return _IesHeader(n_lamps, lumens, multiplier, n_v, n_h, ballast)


def _ies_symmetry(h: np.ndarray, cd: np.ndarray, where: str, line: int) -> tuple[str, np.ndarray, np.ndarray]:
    """(symmetry, horizontal angles, candela rows) from the horizontal angles' range (a 0..360 table drops 360)."""
    if len(h) == 1:
        if h[0] != 0:
            raise PhotometryError(f"{where}: near line {line}: a single horizontal angle must be 0 deg")
        symmetry = "rotational"
    elif h[0] == 0 and h[-1] == 90:
        symmetry = "quadrant"
    elif h[0] == 0 and h[-1] == 180:
        symmetry = "bilateral_c0_c180"
    elif h[0] == 90 and h[-1] == 270:
        symmetry = "bilateral_c90_c270"
    elif h[0] == 0 and h[-1] > 180:
        symmetry = "none"
        if h[-1] == 360:
            if not np.allclose(cd[-1], cd[0], rtol=1e-6, atol=1e-9 * cd.max()):
                raise PhotometryError(f"{where}: the horizontal angles 0 and 360 deg have different candela values")
            h, cd = h[:-1], cd[:-1]
    else:
        raise PhotometryError(
            f"{where}: horizontal angles {h[0]:g}..{h[-1]:g} deg: LM-63 type C allows 0 (one "
            "angle), 0..90, 0..180, 90..270 or 0..360"
        )
    return symmetry, h, cd


# ----------------------------------------------------------------------------- EULUMDAT
_LDT_SYMMETRY = {0: "none", 1: "rotational", 2: "bilateral_c0_c180", 3: "bilateral_c90_c270", 4: "quadrant"}


class _LdtLines:
    """The numbered lines of a EULUMDAT file, read as numbers with located errors (decimal commas accepted)."""

    def __init__(self, lines: list[str], where: str):
        self.lines, self.where = lines, where

    def __call__(self, n: int, what: str, *, integer: bool = False) -> float:
        lines, where = self.lines, self.where
        if n > len(lines):
            raise PhotometryError(f"{where}: the file ends before line {n} ({what})")
        text = lines[n - 1].strip().replace(",", ".")
        if not _NUMBER.match(text):
            raise PhotometryError(f"{where}: line {n}: {what} should be a number, found {lines[n - 1].strip()!r}")
        val = float(text)
        if not math.isfinite(val):
            raise PhotometryError(f"{where}: line {n}: {what} is {text!r}, {_PAST_MAX}")
        if integer and val != int(val):
            raise PhotometryError(f"{where}: line {n}: {what} should be a whole number, found {text!r}")
        return val


def parse_ldt(data: bytes, where: str = "photometry") -> Photometry:
    """Parse a EULUMDAT file (Stockmar 1990, "EULUMDAT: Datenformat"; line numbers as there).

    Lines 1-12: company, Ityp, Isym, Mc, Dc, Ng, Dg, report, name, number, file name,
    date; 13-21 dimensions [mm]; 22 DFF, 23 LOR [%], 24 conversion factor, 25 tilt,
    26 number n of lamp sets, then n x (number of lamps, type, flux [lm], colour,
    CRI, watts), 10 direct ratios, Mc C angles, Ng gamma angles, and the intensities
    [cd/klm] of the stored C planes (Isym 0: all Mc; 1: one; 2: C0..C180; 3: C270..C90
    through C0; 4: C0..C90), Ng values each. Decimal commas are accepted.
    """
    lines = _decode(data)
    field_ = _LdtLines(lines, where)
    isym, mc, ng = _ldt_layout(field_, where)
    lor = field_(23, "LORL (light output ratio) [%]")
    factor = field_(24, "the conversion factor for intensities")
    n_sets = int(field_(26, "the number of lamp sets", integer=True))
    if n_sets < 1:
        raise PhotometryError(f"{where}: line 26: need at least one lamp set, found {n_sets}")
    lamp_flux = sum(field_(27 + 2 * n_sets + k, f"the luminous flux of lamp set {k + 1} [lm]") for k in range(n_sets))
    first = 27 + 6 * n_sets + 10  # first line of the C angles
    tok = _Tokens([ln.replace(",", ".") for ln in lines[first - 1 :]], first, where)
    c = tok.numbers(mc, "C angles")
    line = tok.line()
    g = tok.numbers(ng, "gamma angles")
    _check_angles(c, "C angles", 0.0, 360.0, where, first)
    _check_angles(g, "gamma angles", 0.0, 180.0, where, line)
    stored = _ldt_stored(isym, mc, where)
    line, start = tok.line(), tok.pos
    values = tok.numbers(len(stored) * ng, "intensities [cd/klm]", finite=False).reshape(len(stored), ng)
    if tok.pos < len(tok.items):
        extra, at = tok.items[tok.pos]
        raise PhotometryError(f"{where}: line {at}: unexpected value {extra!r} after the intensity table")
    if np.any(values < 0):
        raise PhotometryError(f"{where}: near line {line}: negative intensities")
    if not factor > 0 or not lamp_flux > 0:
        raise PhotometryError(f"{where}: lines 24-26: the conversion factor and the lamp flux must be positive")
    with np.errstate(over="ignore"):
        scaled = values * factor * lamp_flux / 1000.0
    factors = f"the conversion factor {factor:g} and the lamp flux {lamp_flux:g} lm / 1000"
    tok.check_table(start, values, scaled, _TableNames("intensity [cd/klm]", "C", c[stored], "gamma", g, factors))
    expect = {2: (0.0, 180.0), 3: (270.0, 90.0), 4: (0.0, 90.0)}.get(isym)
    c_stored = c[stored]
    if expect is not None and (abs(c_stored[0] - expect[0]) > 1e-6 or abs(c_stored[-1] - expect[1]) > 1e-6):
        raise PhotometryError(
            f"{where}: line {first}: with Isym = {isym} the stored C planes must run from "
            f"{expect[0]:g} to {expect[1]:g} deg, found {c_stored[0]:g}..{c_stored[-1]:g}"
        )
    symmetry = _LDT_SYMMETRY[isym]
    c_full, rows = _expand(c_stored, scaled, symmetry, where)
    return Photometry.from_table(
        g,
        c_full,
        rows,
        declared_flux=float(lamp_flux * lor / 100.0) if lor > 0 else None,
        source="EULUMDAT",
        symmetry=symmetry,
        where=where,
    )


def _ldt_layout(field_: _LdtLines, where: str) -> tuple[int, int, int]:
    """(Isym, Mc, Ng) of lines 3, 4 and 6, checked."""
    isym = int(field_(3, "Isym (symmetry indicator)", integer=True))
    mc = int(field_(4, "Mc (number of C planes)", integer=True))
    ng = int(field_(6, "Ng (number of intensities per C plane)", integer=True))
    if isym not in _LDT_SYMMETRY:
        raise PhotometryError(f"{where}: line 3: Isym must be 0..4, found {isym}")
    if not 1 <= mc <= 721 or not 2 <= ng <= 361:
        raise PhotometryError(f"{where}: lines 4 and 6: need 1 <= Mc <= 721 and 2 <= Ng <= 361, found {mc} and {ng}")
    if (isym in (2, 3) and mc % 2) or (isym == 4 and mc % 4):
        raise PhotometryError(f"{where}: line 4: Mc = {mc} cannot be split by the symmetry Isym = {isym}")
    return isym, mc, ng


def _ldt_stored(isym: int, mc: int, where: str) -> np.ndarray:
    """Indices of the C planes whose intensities the file stores, for symmetry Isym."""
    stored = {
        0: np.arange(mc),
        1: np.arange(1),
        2: np.arange(mc // 2 + 1),
        3: (3 * mc // 4 + np.arange(mc // 2 + 1)) % mc,
        4: np.arange(mc // 4 + 1),
    }[isym]
    if isym == 3 and mc % 4:
        raise PhotometryError(f"{where}: line 4: Isym = 3 needs Mc divisible by 4, found {mc}")
    return stored


def parse_photometry(data: bytes, fmt: str, where: str = "photometry") -> Photometry:
    """Dispatch on the format ("ies" or "ldt")."""
    if fmt == "ies":
        return parse_ies(data, where)
    if fmt == "ldt":
        return parse_ldt(data, where)
    raise PhotometryError(f"{where}: unknown photometric format {fmt!r} (ies, ldt)")
