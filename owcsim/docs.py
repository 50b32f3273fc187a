"""Load a scene document from disk with overrides, and format validation errors for people."""

from __future__ import annotations

import json
from collections.abc import Sequence
from pathlib import Path

from pydantic import ValidationError

from owcsim.schemas import SceneSpec
from owcsim.schemas.errors import located

#: Largest scene document read [bytes]: a larger file (or a device such as /dev/zero) is refused before it is
#: parsed (parsed JSON takes about ten times its size in memory).
MAX_SCENE_BYTES = 256 * 2**20


class InputError(Exception):
    """A problem with the user's input, already worded for them."""


def set_path(doc: dict, dotted: str, value) -> None:
    """Set `doc[a][b][0][c] = value` for `dotted` = "a.b.0.c" (list indices as integers)."""
    keys = dotted.split(".")
    node = doc
    for depth, key in enumerate(keys):
        last = depth == len(keys) - 1
        if isinstance(node, list):
            try:
                idx = int(key)
                node[idx]
            except (ValueError, IndexError):
                raise InputError(
                    f"--set {dotted}: {'.'.join(keys[:depth]) or 'document'} is a list "
                    f"of {len(node)}; {key!r} is not an index in it"
                ) from None
            if last:
                node[idx] = value
            else:
                node = node[idx]
        elif isinstance(node, dict):
            if last:
                node[key] = value
            else:
                node = node.setdefault(key, {})
        else:
            raise InputError(f"--set {dotted}: {'.'.join(keys[:depth])} is a value, not an object or list")


def parse_assignment(text: str) -> tuple[str, object]:
    """PATH=VALUE with VALUE parsed as JSON (a bare word that is not JSON is taken as a string)."""
    if "=" not in text:
        raise InputError(f"--set {text!r}: expected PATH=VALUE, e.g. receivers.0.fov_deg=60")
    path, raw = text.split("=", 1)
    try:
        value = json.loads(raw)
    except json.JSONDecodeError:
        value = raw
    except (ValueError, RecursionError) as exc:  # JSON, but not usable: e.g. an integer of 5000 digits
        raise InputError(f"--set {path.strip()}: the value is not usable JSON ({type(exc).__name__})") from None
    return path.strip(), value


def format_validation_error(err: ValidationError) -> str:
    lines = [f"the scene has {err.error_count()} problem{'s' if err.error_count() > 1 else ''}:"]
    lines += [f"  {loc or '(document)'}: {msg}" for loc, msg in located(err.errors())]
    return "\n".join(lines)


def load_scene(
    path: str | Path, overrides: Sequence[tuple[str, object]] = (), assignments: Sequence[str] = ()
) -> tuple[SceneSpec, dict]:
    """Read, override and validate a scene document; returns (spec, raw document).

    `overrides` are (dotted path, value) pairs applied first (a callable value is called with the
    document so far and its return value set), then the `--set` style `assignments` ("PATH=JSON").
    """
    path = Path(path)
    try:
        with open(path, "rb") as f:  # a pipe (`<(...)`) is read as it comes; at most MAX_SCENE_BYTES + 1 bytes
            raw = f.read(MAX_SCENE_BYTES + 1)
        if len(raw) > MAX_SCENE_BYTES:
            raise InputError(f"{path}: more than {MAX_SCENE_BYTES:,d} bytes: too large for a scene document")
        doc = json.loads(raw.decode("utf-8"))
    except FileNotFoundError:
        raise InputError(f"{path}: no such file") from None
    except UnicodeDecodeError:
        raise InputError(f"{path}: not a UTF-8 text file (a scene is a JSON document)") from None
    except OSError as exc:  # a folder, a file we may not read, ...
        raise InputError(f"{path}: cannot read it ({exc.strerror or exc})") from None
    except json.JSONDecodeError as exc:
        raise InputError(f"{path}: not valid JSON (line {exc.lineno}, column {exc.colno}: {exc.msg})") from None
    except RecursionError:
        raise InputError(f"{path}: not usable JSON (nested too deeply)") from None
    except ValueError as exc:  # e.g. an integer of more than 4300 digits
        raise InputError(f"{path}: not usable JSON ({exc})") from None
    if not isinstance(doc, dict):
        raise InputError(f"{path}: a scene document is a JSON object")
    for dotted, value in overrides:
        set_path(doc, dotted, value(doc) if callable(value) else value)
    for a in assignments:
        set_path(doc, *parse_assignment(a))
    try:
        return SceneSpec.model_validate(doc), doc
    except ValidationError as err:
        raise InputError(f"{path}: " + format_validation_error(err)) from None
    except RecursionError:
        raise InputError(f"{path}: the document is nested too deeply") from None
    except ArithmeticError as exc:  # a rule of the schema met a number it cannot compute with
        raise InputError(f"{path}: a number is out of the range owcsim can compute with ({exc})") from None
