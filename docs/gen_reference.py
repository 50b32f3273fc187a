"""The reference pages of the documentation, generated from the pydantic models so they cannot drift.

`pages()` returns {page path: Markdown} for the scene document (`SceneSpec`), the result document
(`SimulationResultPublic`) and the service settings (`Settings`). Each page has one section per model
reachable from its root, in the order met, with one table row per field: name, type (nested models
linked), unit, default, bounds and description. The description is the field's own (`Field(description=
...)`); for fields that have none yet, `NOTES` below supplies it, and a note naming a field the model does
not have is an error, so the notes cannot outlive the fields either.

MkDocs runs this through `docs/hooks.py`; `python docs/gen_reference.py OUTDIR` writes the pages to a folder.
"""

from __future__ import annotations

import enum
import inspect
import json
import re
import sys
import types
import typing
from dataclasses import dataclass, field
from pathlib import Path

import annotated_types as at
from pydantic import BaseModel
from pydantic.fields import FieldInfo
from pydantic_core import PydanticUndefined

#: Descriptions of fields whose model has none yet, keyed "Model.field" (better: move them into the model).
NOTES = {
    "SceneSpec.name": "copied into the result",
    "SceneSpec.description": "copied into the result",
    "SceneSpec.room": "the parametric box room",
    "SceneSpec.furniture": "solid axis-aligned boxes (two-sided Lambertian surfaces)",
    "SceneSpec.meshes": "triangle meshes",
    "SceneSpec.transmitters": "point emitters; at least one",
    "SceneSpec.receivers": "photodiodes; at least one receiver in total (here or in `receiver_grids`)",
    "SceneSpec.receiver_grids": "receivers on a rectangle (coverage maps); expanded after `receivers`",
    "SceneSpec.medium": "smoke (absent: clear air)",
    "SceneSpec.simulation": "how to estimate",
    "TransmitterSpec.id": "unique; default `tx0`, `tx1`, ... by position",
    "TransmitterSpec.position": "position [m]",
    "TransmitterSpec.normal": "pointing direction",
    "ReceiverSpec.id": "unique; default `rx0`, `rx1`, ... by position (grids included)",
    "ReceiverSpec.position": "position [m]",
    "ReceiverSpec.normal": "facing direction",
    "ReceiverGridSpec.id_prefix": "receiver ids are `{id_prefix}[i,j]`",
    "ReceiverGridSpec.origin": "the corner of the rectangle, receiver [0,0] [m]",
    "ReceiverGridSpec.u": "first direction spanning the plane",
    "ReceiverGridSpec.v": "second direction spanning the plane, orthogonal to `u`",
    "ReceiverGridSpec.normal": "facing direction of every receiver",
    "ReceiverGridSpec.area": "detector area A of each receiver [m^2]",
    "ReceiverGridSpec.filter_gain": "optical filter gain T_s",
    "ReceiverGridSpec.concentrator_index": "concentrator refractive index n_c",
    "RoomSpec.origin": "the corner with the smallest coordinates [m]",
    "RoomSpec.reflectance": "Lambertian reflectance of each face",
    "BoxSpec.name": "a label",
    "BoxSpec.min": "corner with the smallest coordinates [m]",
    "BoxSpec.max": "opposite corner, above `min` on every axis [m]",
    "MeshSpec.name": "a label",
    "MeshSpec.vertices": "inline points [m] (with `faces`)",
    "MeshSpec.faces": "inline triangles: 0-based vertex indices (with `vertices`)",
    "MeshSpec.file": "a mesh file, relative to the scene document (not accepted by the service)",
    "MeshSpec.data_base64": "the file's content, base64-encoded (with `format`)",
    "MeshSpec.format": "file format (default: from the file's suffix)",
    "HomogeneousMediumSpec.phase": "phase function (default isotropic)",
    "HomogeneousMediumSpec.region": "where the medium is (default: the whole scene)",
    "GridMediumSpec.min": "corner of the grid's box with the smallest coordinates [m]",
    "GridMediumSpec.max": "opposite corner of the grid's box [m]",
    "GridMediumSpec.shape": "cells along x, y, z (at most 1000 each, 2e7 in all)",
    "GridMediumSpec.phase": "phase function of every cell (default isotropic)",
    "BoxRegionSpec.min": "corner with the smallest coordinates [m]",
    "BoxRegionSpec.max": "opposite corner [m]",
    "MeshRegionSpec.vertices": "points of a closed triangle mesh [m]",
    "MeshRegionSpec.faces": "its triangles: 0-based vertex indices; inside = an odd number of crossings",
    "SchlickPhaseSpec.k": "Schlick's k (give k or g)",
    "SchlickPhaseSpec.g": "mean cosine; owcsim uses the k whose mean cosine is exactly g",
    "MixturePhaseSpec.components": "weighted phase functions (e.g. two-term Henyey-Greenstein)",
    "SimulationSpec.algorithm": "estimator 1..5 (see Physics and algorithms), or chosen from the scene",
    "SimulationSpec.direction": "forward (from transmitters), backward (from receivers), or picked per link",
    "SimulationSpec.seed": "random seed: the same document and seed give the same bits",
    "SimulationSpec.russian_roulette": "unbiased path termination from `rr_start_depth` on",
    "HenyeyGreensteinPhaseSpec.g": "mean cosine; g > 0 scatters forward",
    "MixtureComponent.weight": "relative weight (normalised over the components)",
    "MixtureComponent.phase": "the component's phase function",
    "CirPublic.total": "power per bin per watt, bins from `time_bins.t_min_s`",
    "CirPublic.total_stderr": "one standard error per bin (batch means over 16 groups); null without groups",
    "LinkPublic.transmitter": "transmitter id",
    "LinkPublic.receiver": "receiver id",
    "LinkPublic.transmitter_index": "position in the scene's `transmitters`",
    "LinkPublic.receiver_index": "position in the scene's receivers (grids expanded after `receivers`)",
    "LinkPublic.direction": "the estimator used for this link (`both`: algorithm 4; `none`: unreachable)",
    "LinkPublic.paths": "Monte Carlo paths behind this link",
    "LinkPublic.dc_gain": "H0 per watt, including power outside the time window",
    "LinkPublic.dc_gain_stderr": "standard error of H0 (from independent samples: paths, or quasi-random blocks)",
    "LinkPublic.path_loss_db": "-10 log10 H0 [dB]; null if H0 = 0",
    "LinkPublic.received_power_w": "H0 x transmitter power [W]",
    "LinkPublic.mean_delay_s": "tau0, power-weighted, absolute (from emission) [s]",
    "LinkPublic.mean_delay_s_stderr": "standard error of tau0 (delta method) [s]",
    "LinkPublic.rms_delay_spread_s": "tau_rms, power-weighted [s]",
    "LinkPublic.rms_delay_spread_s_stderr": "standard error of tau_rms (delta method) [s]",
    "LinkPublic.mean_delay_h2_s": "h^2-weighted mean delay from the binned CIR, in-window power only [s]",
    "LinkPublic.rms_delay_spread_h2_s": "h^2-weighted RMS delay spread from the binned CIR [s]",
    "LinkPublic.rms_delay_spread_h2_s_stderr": "jackknife over 16 batch groups [s]",
    "LinkPublic.bandwidth_3db_hz": "smallest f > 0 with |H(f)|^2 = |H(0)|^2 / 2, from the binned CIR [Hz]; null "
    "when |H| stays above it up to the Nyquist frequency",
    "LinkPublic.bandwidth_3db_hz_stderr": "jackknife over 16 batch groups [Hz]",
    "LinkPublic.los_gain": "exact line-of-sight gain (0 if outside the FOV, behind a device, or blocked)",
    "LinkPublic.los_delay_s": "d / c, the direct path's delay [s]",
    "LinkPublic.dc_gain_by_reflection_order": "H0 split by reflection order k = 0..K (k = 0 is the LOS)",
    "LinkPublic.dc_gain_by_reflection_order_stderr": "standard errors of the split by k",
    "LinkPublic.dc_gain_by_scattering_order": "H0 split by scattering order s = 0..S",
    "LinkPublic.dc_gain_by_scattering_order_stderr": "standard errors of the split by s",
    "LinkPublic.cir": "the binned impulse response",
    "TimeBinsPublic.t_min_s": "start of the window [s]",
    "TimeBinsPublic.time_bin_s": "bin width dt [s]",
    "TimeBinsPublic.n_bins": "number of bins",
    "RunPublic.stop_reason": "why the run stopped (`nothing_to_simulate`: every receiver unreachable)",
    "RunPublic.target_rel_error": "the accuracy asked, if any",
    "RunPublic.max_dc_gain_rel_stderr": "worst stderr(H0) / H0 of what simulation.target_scope names",
    "RunPublic.wall_time_s": "wall time of the run [s]",
    "RunPublic.workers": "worker processes (or Dask workers at the start)",
    "RunPublic.batches": "batches traced",
    "RunPublic.paths_total": "paths traced (a forward path serves every receiver of its transmitter)",
    "RunPublic.rays_intersect": "closest-hit rays cast",
    "RunPublic.rays_occluded": "shadow rays cast",
    "RunPublic.direction_choice": "the rule that chose the directions and, for a pilot, its measurements",
    "DiagnosticsPublic.power_on_surfaces": "per transmitter: power per watt reaching surfaces (forward paths)",
    "DiagnosticsPublic.escaped_power": "per transmitter: power per watt leaving the scene (forward paths)",
    "DiagnosticsPublic.medium_evaluations": "segments on which the medium was evaluated",
    "SimulationResultPublic.owcsim_version": "version of the engine that ran",
    "SimulationResultPublic.algorithm": "the algorithm that ran (1..5)",
    "SimulationResultPublic.families": "the path families the algorithm estimates, in words",
    "SimulationResultPublic.time_bins": "the binning of every CIR",
    "SimulationResultPublic.links": "one per (transmitter, receiver) pair, transmitter-major",
    "SimulationResultPublic.run": "how the run went",
    "SimulationResultPublic.diagnostics": "power balance",
    "SimulationResultPublic.scene": "the validated scene, defaults filled in and overrides applied",
}

#: Units read from a field name's suffix when its description has no `[unit]`.
SUFFIX_UNITS = (
    ("_deg", "deg"),
    ("_hz", "Hz"),
    ("_db", "dB"),
    ("_w", "W"),
    ("_s", "s"),
    ("_m", "m"),
    ("_bytes", "bytes"),
)
#: What the shared validators of schemas/base.py do, by function name.
VALIDATOR_WORDS = {"_unit_vec": "direction, normalised on input (zero length is an error)", "_finite_vec": "finite"}


@dataclass
class Page:
    """One reference page: its root model and the models documented on other pages (linked, not repeated)."""

    path: str
    title: str
    intro: str
    root: type[BaseModel]
    elsewhere: dict[type, str] = field(default_factory=dict)
    env_prefix: str | None = None


def _unit(name: str, description: str) -> str:
    m = re.search(r"\[(1/m|m\^2|m|s|W|deg|dB|Hz|bytes)\]", description)
    if m:
        return m.group(1)
    for suffix, unit in SUFFIX_UNITS:
        if name.endswith(suffix):
            return unit
    return ""


def _num(x) -> str:
    if isinstance(x, float) and x.is_integer() and abs(x) < 1e15:
        return str(int(x))
    return f"{x:g}" if isinstance(x, float) else str(x)


def _bounds(metadata) -> list[str]:
    """'>= 0', '<= 90', 'length >= 1' from annotated-types metadata."""
    out = []
    for m in metadata:
        for attr, sym in (("ge", ">="), ("gt", ">"), ("le", "<="), ("lt", "<")):
            v = getattr(m, attr, None)
            if isinstance(m, (at.Ge, at.Gt, at.Le, at.Lt, at.Interval)) and v is not None:
                out.append(f"{sym} {_num(v)}")
        if isinstance(m, at.MinLen):
            out.append(f"length >= {m.min_length}")
        if isinstance(m, at.MaxLen):
            out.append(f"length <= {m.max_length}")
    return out


class _Writer:
    def __init__(self, page: Page):
        self.page = page
        self.queue: list[tuple[type[BaseModel], str]] = [(page.root, "")]
        self.where: dict[type, list[str]] = {page.root: ["(the document)"]}
        self.order: list[type[BaseModel]] = []

    def link(self, model: type) -> str:
        if model in self.page.elsewhere:
            return f"[{model.__name__}]({self.page.elsewhere[model]}#{model.__name__.lower()})"
        return f"[{model.__name__}](#{model.__name__.lower()})"

    def meet(self, model: type[BaseModel], path: str) -> None:
        if model in self.page.elsewhere:
            return
        self.where.setdefault(model, [])
        if path not in self.where[model] and len(self.where[model]) < 6:
            self.where[model].append(path)
        if model not in self.order and all(model is not q for q, _ in self.queue):
            self.queue.append((model, path))

    def type_of(self, tp, path: str, extra: list[str]) -> str:
        """Markdown for a type annotation; inner bounds and validator notes go to `extra`."""
        origin, args = typing.get_origin(tp), typing.get_args(tp)
        if origin is typing.Annotated:
            inner, *meta = args
            for m in meta:
                if isinstance(m, FieldInfo):
                    extra.extend(_bounds(m.metadata))
                    if m.description:
                        extra.append(f"({m.description})")
                    if m.discriminator:
                        extra.append(f"chosen by `{m.discriminator}`")
                elif hasattr(m, "func") and getattr(m.func, "__name__", "") in VALIDATOR_WORDS:
                    extra.append(VALIDATOR_WORDS[m.func.__name__])
                else:
                    extra.extend(_bounds([m]))
            return self.type_of(inner, path, extra)
        if origin in (typing.Union, types.UnionType):
            parts = [a for a in args if a is not type(None)]
            body = " or ".join(self.type_of(a, path, extra) for a in parts)
            return body + (" or null" if len(parts) < len(args) else "")
        if origin is typing.Literal:
            return " or ".join(f"`{json.dumps(a)}`" for a in args)
        if origin in (list, tuple, set, frozenset):
            if origin is tuple and args and args[-1] is not Ellipsis:
                return "[" + ", ".join(self.type_of(a, path, []) for a in args) + "]"
            return f"list of {self.type_of(args[0], path + '[]', extra)}" if args else "list"
        if origin is dict:
            return f"object of {self.type_of(args[1], path + '.*', extra)}" if args else "object"
        if inspect.isclass(tp) and issubclass(tp, BaseModel):
            self.meet(tp, path)
            return self.link(tp)
        if inspect.isclass(tp) and issubclass(tp, enum.Enum):
            return " or ".join(f"`{json.dumps(m.value)}`" for m in tp)
        names = {
            float: "number",
            int: "integer",
            str: "string",
            bool: "boolean",
            dict: "object",
            type(None): "null",
            Path: "path",
        }
        return names.get(tp, getattr(tp, "__name__", str(tp)))

    def default(self, info: FieldInfo) -> str:
        if info.default_factory is not None:
            value = info.default_factory()
            if isinstance(value, BaseModel):
                return "all defaults" if not value.model_dump(exclude_defaults=True) else f"`{value.model_dump_json()}`"
            return f"`{json.dumps(value)}`"
        if info.default is PydanticUndefined:
            return "**required**"
        value = info.default
        if isinstance(value, enum.Enum):
            value = value.value
        if isinstance(value, Path):
            value = str(value)
        if isinstance(value, float):
            return f"`{_num(value)}`"
        return f"`{json.dumps(value)}`"

    def rows(self, model: type[BaseModel], path: str) -> list[str]:
        env = self.page.env_prefix is not None and model is self.page.root
        head = (
            "| field | " + ("environment variable | " if env else "") + "type | unit | default | bounds | description |"
        )
        out = [head, "|" + "---|" * (head.count("|") - 1)]
        for attr, info in model.model_fields.items():
            name = info.validation_alias if isinstance(info.validation_alias, str) else attr  # the document's name
            extra: list[str] = []
            sub = f"{path}.{name}" if path else name
            tp = self.type_of(info.annotation, sub, extra)
            desc = info.description or NOTES.get(f"{model.__name__}.{name}", "")
            if not desc and name == "type" and typing.get_origin(info.annotation) is typing.Literal:
                desc = "selects this kind"
            bounds = _bounds(info.metadata) + [e for e in extra if not e.startswith("(")]
            bounds += [
                VALIDATOR_WORDS[f.__name__]
                for m in info.metadata
                if (f := getattr(m, "func", None)) is not None and getattr(f, "__name__", "") in VALIDATOR_WORDS
            ]
            desc_extra = " ".join(e[1:-1] for e in extra if e.startswith("(") and e[1:-1] != desc)
            desc = "; ".join(d for d in (desc, desc_extra) if d)
            cells = [f"`{name}`"]
            if env:
                cells.append(f"`{self.page.env_prefix}{name.upper()}`")
            cells += [tp, _unit(name, desc), self.default(info), ", ".join(dict.fromkeys(bounds)), desc]
            out.append("| " + " | ".join(c.replace("|", "\\|").replace("\n", " ") for c in cells) + " |")
        return out

    def render(self) -> str:
        lines = [f"# {self.page.title}", "", self.page.intro.strip(), ""]
        while self.queue:
            model, path = self.queue.pop(0)
            if model in self.order:
                continue
            self.order.append(model)
            body = self.rows(model, path)  # meets nested models: their places are known after this
            doc = inspect.cleandoc(model.__doc__ or "") if model.__doc__ and model.__doc__ != BaseModel.__doc__ else ""
            lines += [f"## {model.__name__}", ""]
            if model is not self.page.root:
                lines += ["At " + ", ".join(f"`{w}`" for w in self.where.get(model, [])) + ".", ""]
            if doc and not doc.startswith(("Usage docs", "A base class")):
                lines += [doc, ""]
            lines += body + [""]
        return "\n".join(lines)


def _check_notes(models: list[type[BaseModel]]) -> None:
    known = {f"{m.__name__}.{f}" for m in models for f in m.model_fields}
    stale = sorted(set(NOTES) - known)
    if stale:
        raise ValueError(f"docs/gen_reference.py NOTES name fields the models do not have: {stale}")


def pages() -> dict[str, str]:
    """{path under docs/: Markdown} of the generated reference pages."""
    from owcsim.schemas import SceneSpec
    from owcsim.schemas.results import SimulationResultPublic
    from owcsim.server.settings import Settings

    scene = Page(
        "reference/scene.md",
        "Scene document reference",
        """
The JSON document `owcsim run` reads and `POST /v1/jobs` takes (`owcsim.schemas.SceneSpec`). All units are
SI (m, s, W, 1/m); angles are in degrees, in the fields ending in `_deg`. Unknown fields are errors, numbers
must be finite, and every error names its field by its dotted path (e.g. `receivers.0.fov_deg`).
*This page is generated from the pydantic models (`docs/gen_reference.py`): it is what the code accepts.*
""",
        SceneSpec,
    )
    result = Page(
        "reference/result.md",
        "Result document reference",
        """
What `owcsim run` writes as `result.json`, `GET /v1/jobs/{id}/result` returns and the Python client parses
(`owcsim.schemas.results.SimulationResultPublic`). Gains are per watt transmitted; delays are absolute
(from emission). Every Monte Carlo figure has a `_stderr` twin (one standard error); a figure that does
not exist is null. See [the result document](../results.md) for the sums and how the errors are obtained.
*Generated from the pydantic models (`docs/gen_reference.py`).*
""",
        SimulationResultPublic,
        elsewhere={SceneSpec: "scene.md"},
    )
    settings = Page(
        "reference/settings.md",
        "Service settings reference",
        """
Settings of `owcsim serve` (`owcsim.server.settings.Settings`), read from `OWCSIM_*` environment variables;
the flags of `owcsim serve` override the ones they name (`--db`, `--max-concurrent-jobs`, `--workers-per-job`,
`--api-keys-file`, `--scheduler`). *Generated from the pydantic model (`docs/gen_reference.py`).*
""",
        Settings,
        env_prefix=Settings.model_config.get("env_prefix", ""),
    )
    out, seen = {}, []
    for page in (scene, result, settings):
        writer = _Writer(page)
        out[page.path] = writer.render()
        seen += writer.order
    _check_notes(seen)
    return out


if __name__ == "__main__":
    target = Path(sys.argv[1] if len(sys.argv) > 1 else "site-reference")
    for rel, text in pages().items():
        (target / rel).parent.mkdir(parents=True, exist_ok=True)
        (target / rel).write_text(text)
        print(target / rel)
