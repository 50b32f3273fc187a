"""From a request body to an accepted scene document: size, JSON, text lengths, schema, server limits,
engine pre-flight (in its own process, see preflight.py) and the job's memory estimate.

Every refusal is a ProblemError that names the wrong field. Runs in a worker thread of
the server's limiter for heavy work (never the one health and status requests use).
"""

from __future__ import annotations

import hashlib
import json
from collections.abc import Callable
from dataclasses import dataclass

from fastapi import Request
from pydantic import ValidationError

from owcsim.schemas import SceneSpec
from owcsim.schemas.errors import ProblemField
from owcsim.schemas.medium import MAX_MIXTURE_COMPONENTS

from .preflight import Preflight, Preflighter, as_tuple
from .prescan import Found, GridOverflow, check_photometry, count_receivers, scan
from .problems import MAX_LISTED_ERRORS, ProblemError, field_errors
from .settings import Settings

JSON_TYPES = ("application/json",)


async def read_body(request: Request, max_bytes: int) -> bytes:
    """The request body, refused with 413 past `max_bytes` (declared or streamed) and 415 if not JSON."""
    ctype = request.headers.get("content-type", "").split(";")[0].strip().lower()
    if ctype and ctype not in JSON_TYPES and not ctype.endswith("+json"):
        raise ProblemError(
            415, "unsupported-media-type", f"the scene document must be sent as application/json, not {ctype}"
        )
    too_big = ProblemError(
        413,
        "body-too-large",
        f"the request body is larger than this server's limit of {max_bytes:,d} bytes (setting max_body_bytes)",
        max_body_bytes=max_bytes,
    )
    declared = request.headers.get("content-length")
    if declared is not None and declared.isdigit() and int(declared) > max_bytes:
        raise too_big
    chunks, size = [], 0
    async for chunk in request.stream():
        size += len(chunk)
        if size > max_bytes:
            raise too_big
        chunks.append(chunk)
    return b"".join(chunks)


def _invalid(
    errors: list[ProblemField], kind: str = "invalid-scene", status: int = 422, count: int | None = None
) -> ProblemError:
    """A refusal that lists the first MAX_LISTED_ERRORS errors and counts all (`error_count`; `count` when the
    errors given are only the first of more)."""
    count = max(count or 0, len(errors))
    listed = errors[:MAX_LISTED_ERRORS]
    detail = "; ".join(f"{e.loc}: {e.msg}" for e in listed[:5])
    if count > 5:
        detail += f"; and {count - 5:,d} more"
    if count > len(listed):
        detail += f" (the first {len(listed)} listed)"
    return ProblemError(status, kind, detail, errors=listed, error_count=count)


def parse_scene(body: bytes, settings: Settings) -> SceneSpec:
    """JSON -> SceneSpec, after the cheap size checks that keep validation itself bounded."""
    try:
        doc = json.loads(body)
    except (json.JSONDecodeError, UnicodeDecodeError) as exc:
        where = f" (line {exc.lineno}, column {exc.colno})" if isinstance(exc, json.JSONDecodeError) else ""
        msg = exc.msg if isinstance(exc, json.JSONDecodeError) else "not UTF-8 text"
        raise _invalid(
            [ProblemField(loc="body", msg=f"not valid JSON{where}: {msg}", type="json_invalid")], "malformed-json", 400
        ) from None
    except RecursionError:
        raise _invalid(
            [ProblemField(loc="body", msg="JSON nested too deeply", type="json_invalid")], "malformed-json", 400
        ) from None
    except ValueError as exc:  # e.g. an integer of more than 4300 digits
        raise _invalid(
            [ProblemField(loc="body", msg=f"not valid JSON: {exc}", type="json_invalid")], "malformed-json", 400
        ) from None
    if not isinstance(doc, dict):
        raise _invalid([ProblemField(loc="body", msg="a scene document is a JSON object", type="dict_type")])
    _check_counts(doc, settings)
    try:
        return SceneSpec.model_validate(doc)
    except ValidationError as err:
        first = err.errors(include_url=False)[:MAX_LISTED_ERRORS]
        raise _invalid(field_errors(first, ("body",)), count=err.error_count()) from None
    except RecursionError:
        raise _invalid([ProblemField(loc="body", msg="document nested too deeply", type="value_error")]) from None
    except ArithmeticError as exc:  # a rule of the schema met a number it cannot compute with
        raise _invalid([_out_of_range("body", exc)]) from None


def _out_of_range(loc: str, exc: ArithmeticError) -> ProblemField:
    return ProblemField(
        loc=loc, type="value_error", msg=f"a number is out of the range the simulator can compute with ({exc})"
    )


def _check_counts(doc: dict, settings: Settings) -> None:
    """The pre-scan (prescan.py), before any model builds: the lengths of the large lists first (no walk),
    then text lengths and unknown keys (one walk), then grids, mixtures and photometric tables."""
    _check_receivers(doc, settings, grids=False)
    transmitters = doc.get("transmitters")
    if isinstance(transmitters, list) and len(transmitters) > settings.max_transmitters:
        raise _limit(
            "body.transmitters",
            f"the scene has {len(transmitters):,d} transmitters; this server accepts at most "
            f"{settings.max_transmitters:,d} (setting max_transmitters)",
        )
    meshes, furniture = doc.get("meshes"), doc.get("furniture")
    faces = (
        sum(
            len(m["faces"])
            for m in (meshes if isinstance(meshes, list) else [])
            if isinstance(m, dict) and isinstance(m.get("faces"), list)
        )
        + 12 * (len(furniture) if isinstance(furniture, list) else 0)
        + (12 if doc.get("room") else 0)
    )  # boxes: 12
    if faces > settings.max_triangles:
        raise _limit(
            "body.meshes",
            f"the scene has {faces:,d} triangles; this server accepts at most "
            f"{settings.max_triangles:,d} (setting max_triangles)",
        )
    walked = scan(doc, settings.max_text_chars)
    if walked.text.count:
        raise _invalid(walked.text.listed, "limit-exceeded", count=walked.text.count)
    keys = walked.keys
    if keys.count > MAX_LISTED_ERRORS or any(e.type != "extra_forbidden" for e in keys.listed):
        raise _invalid(keys.listed, count=keys.count)  # (a few unknown keys: reported with the other errors)
    misplaced = walked.misplaced  # keys of another model than the one they are in (e.g. `faces` in a receiver)
    if misplaced.count > MAX_LISTED_ERRORS:
        raise _invalid(keys.listed + misplaced.listed, count=keys.count + misplaced.count)
    if walked.numbers.count > MAX_LISTED_ERRORS:  # e.g. [[], [], ...] in a phase table: 3 bytes an error
        raise _invalid(walked.numbers.listed, count=walked.numbers.count)
    if walked.missing.count > MAX_LISTED_ERRORS:  # e.g. [{}, {}, ...] as receivers: 3 bytes, 3 errors
        raise _invalid(walked.missing.listed, count=walked.missing.count)
    _check_receivers(doc, settings, grids=True)
    found = Found()
    for loc, n in walked.mixtures:
        if n > MAX_MIXTURE_COMPONENTS:
            found.add(loc, f"a mixture of {n:,d} components; at most {MAX_MIXTURE_COMPONENTS} are accepted", "too_long")
    check_photometry(doc, found)
    if found.count:
        raise _invalid(found.listed, "limit-exceeded", count=found.count)


def _check_receivers(doc: dict, settings: Settings, grids: bool) -> None:
    try:
        count = count_receivers(doc, settings.max_receivers, grids=grids)
    except GridOverflow as exc:  # e.g. size / spacing overflows
        raise _invalid([_out_of_range(f"body.receiver_grids.{exc.index}", exc)]) from None
    if count > settings.max_receivers:
        raise _limit(
            "body.receiver_grids",
            f"the scene has at least {count:,d} receivers, counting each orientation sample and angle-diversity "
            f"photodiode; this server accepts at most {settings.max_receivers:,d} (setting max_receivers)",
        )


def _limit(loc: str, msg: str) -> ProblemError:
    return _invalid([ProblemField(loc=loc, msg=msg, type="limit_exceeded")], "limit-exceeded")


def check_limits(spec: SceneSpec, settings: Settings) -> None:
    """Server rules on a valid document: no mesh paths, triangles, paths, wall time."""
    errors = [
        ProblemField(
            loc=f"body.meshes.{i}.file",
            type="path_not_allowed",
            msg="a mesh cannot be a path on the server: send it inline (`vertices` + `faces`) "
            "or as `data_base64` + `format` (`owcsim submit` does this for you)",
        )
        for i, m in enumerate(spec.meshes)
        if m.file is not None
    ]
    errors += [
        ProblemField(
            loc=f"body.transmitters.{i}.photometry.file",
            type="path_not_allowed",
            msg="a photometric file cannot be a path on the server: send it as `data_base64` + "
            "`format` (`owcsim submit` does this for you)",
        )
        for i, t in enumerate(spec.transmitters)
        if t.photometry is not None and t.photometry.file is not None
    ]
    frames = spec.timeline.frames if spec.timeline is not None else None
    if frames is not None and getattr(frames, "path", None) is not None:
        errors.append(
            ProblemField(
                loc="body.timeline.frames.path",
                type="path_not_allowed",
                msg="frames cannot be read from a path on the server: send the file as `data_base64` (a netCDF "
                "file's bytes, or a zip of the FDS case folder)",
            )
        )
    if errors:
        raise _invalid(errors)
    n_rx = len(spec.receivers) + spec.grid_receiver_count()  # with the hidden ones: orientation, photodiodes
    if n_rx > settings.max_receivers:
        raise _limit(
            "body.receiver_grids",
            f"the scene has {n_rx:,d} receivers, counting each orientation sample and angle-diversity "
            f"photodiode; this server accepts at most {settings.max_receivers:,d} (setting max_receivers)",
        )
    triangles = (12 if spec.room else 0) + 12 * len(spec.furniture) + sum(len(m.faces or ()) for m in spec.meshes)
    if triangles > settings.max_triangles:
        raise _limit(
            "body.meshes",
            f"the scene has {triangles:,d} triangles; this server accepts at most "
            f"{settings.max_triangles:,d} (setting max_triangles)",
        )
    sim = spec.simulation
    if sim.n_paths is not None:
        n_tx = len(spec.transmitters)
        # source devices: exact for a fixed direction; for auto the fewest the engine can use
        sources = {"forward": n_tx, "backward": n_rx}.get(sim.direction, min(n_tx, n_rx))
        if sim.n_paths * sources > settings.max_paths_per_job:
            raise _limit(
                "body.simulation.paths",
                f"{sim.n_paths:,d} paths x {sources} source devices is more than this server's limit of "
                f"{settings.max_paths_per_job:,d} paths per job (setting max_paths_per_job)",
            )
    elif sim.time_budget_s > settings.max_wall_time_s:
        raise _limit(
            "body.simulation.time_budget_s",
            f"{sim.time_budget_s:g} s is longer than this server's limit of {settings.max_wall_time_s:g} s "
            "per job (setting max_wall_time_s)",
        )


def check_runnable(
    spec: SceneSpec, scene_json: str, settings: Settings, preflighter: Callable[[SceneSpec, str], Preflight]
) -> Preflight:
    """The server's limits, the engine's pre-flight and the memory estimate of a validated scene;
    returns the pre-flight's figures, raises ProblemError."""
    check_limits(spec, settings)
    out = preflighter(spec, scene_json)
    if out.triangles > settings.max_triangles:
        raise _limit(
            "body.meshes",
            f"the scene has {out.triangles:,d} triangles; this server accepts at most "
            f"{settings.max_triangles:,d} (setting max_triangles)",
        )
    cap = settings.job_memory_cap
    if out.memory_bytes > cap:
        raise _limit(
            "body.simulation",
            f"this job would need about {out.memory_bytes / 2**30:.3g} GB of memory "
            f"(estimated from its links, orders, time bins, batch_size and triangles); this server allows "
            f"{cap / 2**30:.3g} GB per job (setting max_job_memory_bytes): ask for fewer receivers, "
            "orders or time bins (give max_reflections and t_max_s: automatic ones are counted at the "
            "most the engine may choose), or a smaller batch_size",
        )
    return out


@dataclass(frozen=True)
class Admitted:
    """A valid document: its canonical JSON, name and hash; a large body's pre-flight figures (`checked`), or
    the spec of a small one to check with `check_runnable` (after the idempotency look-up)."""

    canonical: str
    name: str | None
    digest: str
    spec: SceneSpec | None  # a small body: checked in this process by the caller
    checked: Preflight | None  # a large body: already checked in a pre-flight process

    def small_spec(self) -> SceneSpec:
        """The spec of a small body (`checked` is None exactly then)."""
        assert self.spec is not None, "a large body is checked in its pre-flight process"
        return self.spec


def admit(body: bytes, settings: Settings, preflighter: Preflighter) -> Admitted:
    """Parse and validate a body. A body of at most `inprocess_body_bytes` is parsed here (its limits and
    pre-flight are the caller's: `check_runnable`); a larger one is parsed, pre-scanned, validated, limited and
    pre-flighted in a pre-flight process, so that the server's memory and interpreter stay free.
    Blocking (call it from a worker thread); raises ProblemError."""
    if len(body) <= settings.inprocess_body_bytes:
        spec = parse_scene(body, settings)
        canonical = spec.model_dump_json()
        return Admitted(canonical, spec.name, request_hash(canonical), spec, None)
    what = "the validation and pre-flight of this document"
    _, canonical, name, triangles, memory = preflighter.in_process(what, check_document, body, settings)
    checked = Preflight(triangles=triangles, memory_bytes=memory)
    return Admitted(canonical, name, request_hash(canonical), None, checked)


def _inline(settings: Settings) -> Callable[[SceneSpec, str], Preflight]:
    """The engine's pre-flight in this process (inside a pre-flight process: no second one)."""
    return Preflighter(
        concurrency=1,
        timeout_s=settings.preflight_timeout_s,
        memory_bytes=settings.preflight_memory_bytes,
        max_triangles=settings.max_triangles,
        workers=settings.workers_per_job,
    ).inline


def check_document(body: bytes, settings: Settings) -> tuple:
    """In a pre-flight process: the whole admission of a body, as ("ok", canonical, name, triangles, memory)
    or a problem tuple."""
    try:
        spec = parse_scene(body, settings)
        canonical = spec.model_dump_json()
        checked = check_runnable(spec, canonical, settings, _inline(settings))
    except ProblemError as exc:
        return as_tuple(exc)
    return ("ok", canonical, spec.name, checked.triangles, checked.memory_bytes)


def estimate(body: bytes, settings: Settings, preflighter: Preflighter) -> dict:
    """POST /v1/preflight: the checks of a submission (`admit` + `check_runnable`, a large body in a pre-flight
    process as there) and the figures of the job it would be (`figures`). Blocking; raises ProblemError."""
    if len(body) <= settings.inprocess_body_bytes:
        spec = parse_scene(body, settings)
        return figures(spec, check_runnable(spec, spec.model_dump_json(), settings, preflighter))
    what = "the validation and pre-flight of this document"
    return preflighter.in_process(what, estimate_document, body, settings)[1]


def estimate_document(body: bytes, settings: Settings) -> tuple:
    """In a pre-flight process: `estimate` of a large body, as ("ok", figures) or a problem tuple."""
    try:
        spec = parse_scene(body, settings)
        return ("ok", figures(spec, check_runnable(spec, spec.model_dump_json(), settings, _inline(settings))))
    except ProblemError as exc:
        return as_tuple(exc)


def figures(spec: SceneSpec, checked: Preflight) -> dict:
    """What a job of a checked scene would run: memory, triangles, receivers, paths (None: until accuracy),
    its time budget and what it will model (`planned`)."""
    receivers = len(spec.receivers) + spec.grid_receiver_count()
    sim = spec.simulation
    paths = None
    if sim.n_paths is not None:
        sources = {"forward": len(spec.transmitters), "backward": receivers}
        paths = sim.n_paths * sources.get(sim.direction, min(len(spec.transmitters), receivers))
    return {
        "memory_bytes": checked.memory_bytes,
        "triangles": checked.triangles,
        "receivers": receivers,
        "paths": paths,
        "time_budget_s": sim.time_budget_s,
        "modeled": planned(spec),
    }


def planned(spec: SceneSpec) -> dict[str, str]:
    """What the job will model, said before it runs: the settings given, and the ones the engine will choose
    when the job starts (the result's `modeled` section then gives the values and reasons; docs/modeled.md)."""
    sim = spec.simulation
    pilot = "chosen when the job starts, by a short pilot run (docs/modeled.md)"
    if sim.algorithm != "auto":
        alg = f"algorithm {sim.algorithm} (requested)"
    elif spec.medium is None:
        alg = "algorithm 1: no medium, vacuum paths only"
    else:
        alg = (
            "chosen when the job starts: algorithm 1 if the medium does not scatter (sigma_s = 0) or lies outside "
            "the room, otherwise algorithm 5 (every scattering family)"
        )
    out = {
        "algorithm": alg,
        "max_reflections": pilot if sim.max_reflections is None else f"K = {sim.max_reflections} (given)",
        "time_window": pilot if sim.t_max_s is None else f"{sim.t_min_s:g} s to {sim.t_max_s:g} s (given)",
        "accuracy": (
            f"{sim.n_paths:,d} paths per source device"
            if sim.n_paths is not None
            else f"until the DC gain's relative error is {sim.target_rel_error:g} or {sim.time_budget_s:g} s"
        ),
        "rules": "docs/modeled.md: what the automatic settings choose, and what every job leaves out",
    }
    if spec.medium is not None:
        out["max_scattering"] = pilot if sim.max_scattering is None else f"S = {sim.max_scattering} (given)"
    return out


def request_hash(canonical: str) -> str:
    return hashlib.sha256(canonical.encode()).hexdigest()
