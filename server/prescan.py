"""Structural pre-scan of a parsed scene document: counts before any model is built (issue 25).

pydantic validates a whole document before it answers, and lists every error it finds: a
body of a million unknown keys, or of 100,000 receivers with a wrong position, builds a
million error objects. The pre-scan walks the parsed JSON once (no model, no copy) and
refuses, each with located messages (at most `MAX_LISTED_ERRORS` and a count):

- strings and keys longer than `max_text_chars` (file content excepted);
- keys that no model of the scene document has (the names come from the document's JSON
  schema; the keys of free-key maps such as `group_reflectance` are the user's);
- objects with more than `MAX_OBJECT_KEYS` keys;
- more transmitters than `max_transmitters`, more receivers than `max_receivers` (grids
  counted from their shapes), more inline triangles than `max_triangles`;
- a phase-function mixture of more than `MAX_MIXTURE_COMPONENTS` components;
- a photometric file (IES LM-63) whose table has more than `MAX_PHOTOMETRY_ANGLES` angles
  on an axis or `MAX_PHOTOMETRY_CELLS` cells, read from the file's header only.
"""

from __future__ import annotations

import base64
import binascii
import functools
import math
import re
from dataclasses import dataclass, field

from pydantic import ValidationError

from owcsim.schemas import ReceiverGridSpec, SceneSpec
from owcsim.schemas.errors import ProblemField
from owcsim.schemas.orientation import OrientationSpec
from owcsim.schemas.photometry import MAX_PHOTOMETRY_ANGLES, MAX_PHOTOMETRY_CELLS

from .problems import MAX_LISTED_ERRORS

#: Most keys of one JSON object of a scene document (the largest model has fewer than 60 fields).
MAX_OBJECT_KEYS = 256


@functools.cache
def vocabulary() -> tuple[frozenset[str], frozenset[str]]:
    """(every field name of every model of the scene document, the fields whose value is a free-key map)."""
    schema = SceneSpec.model_json_schema()
    names: set[str] = set()
    free: set[str] = set()
    for model in [schema, *schema.get("$defs", {}).values()]:
        for name, prop in model.get("properties", {}).items():
            names.add(name)
            if _is_map(prop):
                free.add(name)
    return frozenset(names), frozenset(free)


#: child_keys()'s entry for the document itself (the keys of SceneSpec)
ROOT = ""


@functools.cache
def child_keys() -> dict[str, frozenset[str] | None]:
    """{a field name: the keys an object given as its value (or as an item of its list) may have}, the union
    over every model that has a field of that name (ROOT: the document's own keys). None where any such
    field can hold an object of free keys (a map, a model that allows extra keys): not checked."""
    schema = SceneSpec.model_json_schema()
    defs = schema.get("$defs", {})
    out: dict[str, frozenset[str] | None] = {}
    for model in [schema, *defs.values()]:
        for name, prop in model.get("properties", {}).items():
            keys: set[str] = set()
            closed = _object_keys(prop, defs, keys, set())
            before = out.get(name, frozenset())
            out[name] = None if before is None or not closed else before | keys
    out[ROOT] = frozenset(schema["properties"])
    return out


@functools.cache
def required_keys() -> dict[str, frozenset[str]]:
    """{a field name: the keys every object given as its value (or in its list) must have}: the keys that every
    model reachable from every field of that name requires (none where any is open or not a model)."""
    schema = SceneSpec.model_json_schema()
    defs = schema.get("$defs", {})
    out: dict[str, frozenset[str]] = {}
    for model in [schema, *defs.values()]:
        for name, prop in model.get("properties", {}).items():
            models: list[dict] = []
            common = frozenset(_required_of(prop, defs, models, set()) or ())
            if not models or not _object_keys(prop, defs, set(), set()):
                common = frozenset()
            out[name] = common if name not in out else out[name] & common
    return out


def _required_of(node: dict, defs: dict, models: list[dict], seen: set[str]) -> set[str] | None:
    """The keys every model `node` may hold requires (their intersection; None: no model), collecting them."""
    found: list[set[str]] = []
    ref = node.get("$ref")
    if isinstance(ref, str):
        name = ref.rsplit("/", 1)[-1]
        if name not in seen:
            seen.add(name)
            sub = _required_of(defs[name], defs, models, seen)
            if sub is not None:
                found.append(sub)
    for sub_node in [*node.get("anyOf", ()), *node.get("oneOf", ())]:
        sub = _required_of(sub_node, defs, models, seen)
        if sub is not None:
            found.append(sub)
    if isinstance(node.get("items"), dict):
        sub = _required_of(node["items"], defs, models, seen)
        if sub is not None:
            found.append(sub)
    if "properties" in node:
        models.append(node)
        found.append(set(node.get("required", ())))
    return set.intersection(*found) if found else None


@functools.cache
def number_lists() -> frozenset[str]:
    """Field names whose list values hold numbers only, in every model that has a field of that name."""
    schema = SceneSpec.model_json_schema()
    yes: set[str] = set()
    no: set[str] = set()
    for model in [schema, *schema.get("$defs", {}).values()]:
        for name, prop in model.get("properties", {}).items():
            arrays = [o for o in (prop, *prop.get("anyOf", ()), *prop.get("oneOf", ())) if o.get("type") == "array"]
            if arrays:
                numbers = all(isinstance(o.get("items"), dict) and o["items"].get("type") in NUMBER for o in arrays)
                (yes if numbers else no).add(name)
    return frozenset(yes - no)


NUMBER = ("number", "integer")


def _not_a_number(v: object) -> str | None:
    """The error type pydantic gives an item of a list of numbers, for what is surely not one; else None."""
    t = type(v)
    if t is int or t is float or t is bool:
        return None
    if t is str:
        try:
            float(v)  # type: ignore[arg-type]
        except ValueError:
            return "float_parsing"
        return None
    return "float_type"


def _object_keys(node: dict, defs: dict, keys: set[str], seen: set[str]) -> bool:
    """Add the keys of the objects `node` (a JSON schema) may hold, through references, unions and lists;
    False if one of them may have keys no schema names."""
    closed = True
    ref = node.get("$ref")
    if isinstance(ref, str):
        name = ref.rsplit("/", 1)[-1]
        if name not in seen:
            seen.add(name)
            closed &= _object_keys(defs[name], defs, keys, seen)
    for sub in [*node.get("anyOf", ()), *node.get("oneOf", ()), *node.get("allOf", ()), *node.get("prefixItems", ())]:
        closed &= _object_keys(sub, defs, keys, seen)
    if isinstance(node.get("items"), dict):
        closed &= _object_keys(node["items"], defs, keys, seen)
    if "properties" in node:
        keys.update(node["properties"])
        closed &= node.get("additionalProperties") is False
    elif node.get("type") == "object" or "additionalProperties" in node:
        closed = False
    if not any(k in node for k in ("type", "$ref", "anyOf", "oneOf", "allOf", "const", "enum")):
        closed = False  # any value (a field of type Any)
    if node.get("type") == "array" and not isinstance(node.get("items"), dict) and "prefixItems" not in node:
        closed = False  # a list of anything
    return closed


def _is_map(prop: dict) -> bool:
    options = [prop, *prop.get("anyOf", ())]
    return any(o.get("type") == "object" and isinstance(o.get("additionalProperties"), dict) for o in options)


class Found:
    """Errors of the pre-scan: the first MAX_LISTED_ERRORS kept, all counted."""

    def __init__(self) -> None:
        self.listed: list[ProblemField] = []
        self.count = 0

    def add(self, loc: str, msg: str, type_: str) -> None:
        self.count += 1
        if len(self.listed) < MAX_LISTED_ERRORS:
            self.listed.append(ProblemField(loc=loc, msg=msg, type=type_))


@dataclass
class Scan:
    """What one walk of the document found: texts too long, unknown keys and oversized objects, mixtures."""

    text: Found = field(default_factory=Found)
    keys: Found = field(default_factory=Found)
    misplaced: Found = field(default_factory=Found)  # keys of some model, but not of the field they are under
    numbers: Found = field(default_factory=Found)  # items of a list of numbers that are no number
    missing: Found = field(default_factory=Found)  # keys that every model of the field they are under requires
    mixtures: list[tuple[str, int]] = field(default_factory=list)  # (location of `components`, their number)


#: Fields whose text may be long: file content.
LONG_TEXT = frozenset({"data_base64"})


def scan(doc: dict, max_chars: int) -> Scan:
    """One walk of the parsed document (locations are built for containers and errors only): every string
    and key at most `max_chars` long (file content excepted), keys no model has, objects of more than
    MAX_OBJECT_KEYS keys (their unknown keys counted, their values not walked), mixtures' components."""
    names, free = vocabulary()
    allowed_under, number_fields, needed_under = child_keys(), number_lists(), required_keys()
    out = Scan()
    # (node, its location, whether its keys are free (a map's), the field it is the value of: None in a map)
    stack: list[tuple[object, str, bool, str | None]] = [(doc, "body", False, ROOT)]
    while stack:
        node, loc, is_map, under = stack.pop()
        if type(node) is list:
            numbers = under in number_fields
            for i, v in enumerate(node):
                t = type(v)
                if numbers and (wrong := _not_a_number(v)) is not None:
                    msg = "Input should be a valid number" + (
                        ", unable to parse string as a number" if t is str else ""
                    )
                    out.numbers.add(f"{loc}.{i}", msg, wrong)
                elif t is dict or t is list:
                    stack.append((v, f"{loc}.{i}", False, under))
                elif t is str and len(v) > max_chars:
                    out.text.add(f"{loc}.{i}", _too_long_text(len(v), max_chars), "string_too_long")
            continue
        assert type(node) is dict
        too_many = len(node) > MAX_OBJECT_KEYS
        if too_many:
            out.keys.add(loc, f"an object of {len(node):,d} keys; at most {MAX_OBJECT_KEYS} are accepted", "too_long")
        if node.get("type") == "mixture" and type(node.get("components")) is list:
            out.mixtures.append((f"{loc}.components", len(node["components"])))
        allowed = None if is_map or under is None else allowed_under.get(under)
        if allowed is not None and under is not None and not too_many:
            for k in needed_under.get(under, ()):
                if k not in node:
                    out.missing.add(f"{loc}.{k}", "Field required", "missing")
        for k, v in node.items():
            if len(k) > max_chars:
                msg = f"a key of {len(k):,d} characters; at most {max_chars:,d} (setting max_text_chars)"
                out.text.add(loc, msg, "string_too_long")
            elif not is_map and k not in names:
                out.keys.add(f"{loc}.{k}", "Extra inputs are not permitted", "extra_forbidden")
            elif too_many or k in LONG_TEXT:
                continue
            else:
                if allowed is not None and k not in allowed:
                    out.misplaced.add(f"{loc}.{k}", "Extra inputs are not permitted", "extra_forbidden")
                if type(v) is dict or type(v) is list:
                    stack.append((v, f"{loc}.{k}", not is_map and k in free, None if is_map else k))
                elif type(v) is str and len(v) > max_chars:
                    out.text.add(f"{loc}.{k}", _too_long_text(len(v), max_chars), "string_too_long")
    return out


def _too_long_text(n: int, max_chars: int) -> str:
    return f"text of {n:,d} characters; this server accepts at most {max_chars:,d} (setting max_text_chars)"


class GridOverflow(ArithmeticError):
    """A receiver grid whose shape a number overflows: `index` in `receiver_grids`."""

    def __init__(self, index: int, exc: ArithmeticError):
        super().__init__(str(exc))
        self.index = index


def count_receivers(doc: dict, stop_above: int, grids: bool = True) -> int:
    """Receivers of the document, a lower bound counted without building the scene: explicit receivers and
    their orientation samples, each grid's points (from its shape) times 1 + its orientation samples, and each
    angle-diversity receiver's photodiodes; stops counting past `stop_above`; `grids`: False counts lists only
    (no grid is validated). GridOverflow: a grid's shape overflows."""
    receivers, shapes, adrs = (doc.get(k) for k in ("receivers", "receiver_grids", "angle_diversity_receivers"))
    count = 0
    for r in receivers if isinstance(receivers, list) else []:
        count += 1 + _samples(r)
    for i, g in enumerate(shapes if grids and isinstance(shapes, list) else []):
        if count > stop_above:
            break
        try:
            count += ReceiverGridSpec.model_validate(g).count * (1 + _samples(g))
        except ArithmeticError as exc:  # e.g. size / spacing overflows
            raise GridOverflow(i, exc) from None
        except (ValidationError, ValueError, TypeError):
            pass  # reported by the full validation
    for a in adrs if isinstance(adrs, list) else []:
        pds = a.get("photodiodes") if isinstance(a, dict) else None
        count += len(pds) if isinstance(pds, list) else 1
    return count


def _samples(device: object) -> int:
    orientation = device.get("orientation") if isinstance(device, dict) else None
    if not isinstance(orientation, dict):
        return 0
    samples = orientation.get("samples", OrientationSpec.model_fields["samples"].default)
    return samples if _is_int(samples) and samples > 0 else 0


def _is_int(x: object) -> bool:
    return isinstance(x, int) and not isinstance(x, bool)


def _is_num(x: object) -> bool:
    return isinstance(x, int | float) and not isinstance(x, bool) and math.isfinite(x)


_TOKEN = re.compile(rb"[^\s,]+")
_TILT = re.compile(rb"^[ \t]*TILT[ \t]*=[ \t]*([^\r\n]*)", re.MULTILINE | re.IGNORECASE)


def ies_table_size(data_base64: str) -> tuple[int, int] | None:
    """(vertical angles, horizontal angles) an IES LM-63 file declares, from its header; None if unreadable
    (the engine's parser reports why)."""
    try:
        head = base64.b64decode(data_base64[: 1 << 16], validate=False)  # a header fits in 48 KB
    except (binascii.Error, ValueError):
        return None
    tilt = _TILT.search(head)
    if tilt is None:
        return None
    tokens = _TOKEN.finditer(head, tilt.end())
    try:
        if tilt.group(1).strip().upper() == b"INCLUDE":
            next(tokens)  # lamp-to-luminaire geometry
            n_tilt = int(float(next(tokens).group()))
            for _ in range(2 * min(n_tilt, 10_000)):
                next(tokens)
        values = [float(next(tokens).group()) for _ in range(5)]
    except (StopIteration, ValueError, OverflowError):
        return None
    n_v, n_h = values[3], values[4]
    if not (math.isfinite(n_v) and math.isfinite(n_h)):
        return None
    return int(n_v), int(n_h)


def check_photometry(doc: dict, found: Found) -> None:
    """Table sizes of the transmitters' IES files, from their headers."""
    transmitters = doc.get("transmitters")
    for i, t in enumerate(transmitters if isinstance(transmitters, list) else []):
        p = t.get("photometry") if isinstance(t, dict) else None
        if not isinstance(p, dict) or p.get("format") != "ies" or not isinstance(p.get("data_base64"), str):
            continue
        size = ies_table_size(p["data_base64"])
        if size is None:
            continue
        n_v, n_h = size
        if max(n_v, n_h) > MAX_PHOTOMETRY_ANGLES or n_v * n_h > MAX_PHOTOMETRY_CELLS:
            found.add(
                f"body.transmitters.{i}.photometry.data_base64",
                f"the photometric file's table has {n_v:,d} vertical x {n_h:,d} horizontal angles; this server "
                f"accepts at most {MAX_PHOTOMETRY_ANGLES:,d} angles on an axis and {MAX_PHOTOMETRY_CELLS:,d} "
                "candela values",
                "limit_exceeded",
            )
