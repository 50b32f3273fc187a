"""The generated reference (docs/gen_reference.py) covers every field of the scene, result and settings models.

The check walks the models' JSON schemas (pydantic's own output, not the generator's walk), so a
field the generator skipped, a model it never reached, or a page it stopped writing is caught.
"""

from __future__ import annotations

import importlib.util
import re
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="module")
def gen():
    spec = importlib.util.spec_from_file_location("owcsim_docs_gen_reference", ROOT / "docs" / "gen_reference.py")
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module
    spec.loader.exec_module(module)
    return module


@pytest.fixture(scope="module")
def pages(gen):
    return gen.pages()


def _fields_by_model(schema: dict) -> dict[str, set[str]]:
    """{model title: its property names} for the root and every $defs entry that is an object with properties."""
    out = {}
    for node in [schema, *schema.get("$defs", {}).values()]:
        if node.get("type") == "object" and "properties" in node:
            out[node["title"]] = set(node["properties"])
    return out


def _sections(markdown: str) -> dict[str, set[str]]:
    """{section heading: field names of its table rows} of a generated page."""
    out, current = {}, None
    for line in markdown.splitlines():
        if line.startswith("## "):
            current = line[3:].strip()
            out[current] = set()
        elif current and (m := re.match(r"\| `([^`]+)` \|", line)):
            out[current].add(m.group(1))
    return out


def _models():
    from owcsim.schemas import SceneSpec
    from owcsim.schemas.results import SimulationResultPublic
    from owcsim.server.settings import Settings

    return [
        ("reference/scene.md", SceneSpec.model_json_schema(mode="validation")),
        ("reference/result.md", SimulationResultPublic.model_json_schema(mode="serialization")),
        ("reference/settings.md", Settings.model_json_schema()),
    ]


@pytest.mark.parametrize("page,schema", _models(), ids=lambda x: x if isinstance(x, str) else "")
def test_every_field_of_every_model_is_in_the_reference(pages, page, schema):
    sections = _sections(pages[page])
    expected = _fields_by_model(schema)
    if page == "reference/result.md":  # the scene inside the result is documented on the scene page
        scene_models = _fields_by_model(_models()[0][1])
        expected = {k: v for k, v in expected.items() if k not in scene_models}
    missing = {model: sorted(fields - sections.get(model, set())) for model, fields in expected.items()}
    missing = {m: f for m, f in missing.items() if f}
    assert not missing, f"{page}: fields missing from the generated reference: {missing}"
    assert len(expected) >= 3 if page != "reference/settings.md" else len(expected) == 1


def test_the_result_page_links_the_scene_it_embeds(pages):
    assert "[SceneSpec](scene.md#scenespec)" in pages["reference/result.md"]


def test_rows_carry_type_default_bounds_and_unit(pages):
    """A few rows checked by hand against schemas/ (the point is the columns, not these values)."""
    rows = {
        re.match(r"\| `([^`]+)` \|", ln).group(1): ln
        for ln in pages["reference/scene.md"].splitlines()
        if ln.startswith("| `")
    }
    assert "| `fov_deg` | number | deg | `90` | >= 1e-06, <= 90 |" in rows["fov_deg"]
    assert "| `time_bin_s` | number | s | `2.5e-10` | >= 1e-15 |" in rows["time_bin_s"]
    assert "**required**" in rows["transmitters"] and "length >= 1" in rows["transmitters"]
    settings = pages["reference/settings.md"]
    assert "| `max_receivers` | `OWCSIM_MAX_RECEIVERS` | integer |  | `100000` | >= 1 |" in settings


def test_a_note_for_a_field_that_does_not_exist_is_an_error(gen, monkeypatch):
    monkeypatch.setitem(gen.NOTES, "ReceiverSpec.no_such_field", "stale")
    with pytest.raises(ValueError, match="ReceiverSpec.no_such_field"):
        gen.pages()


def test_the_check_would_catch_a_missing_field(pages):
    """Power check: drop one row of the generated scene page and the coverage test's comparison fails."""
    from owcsim.schemas import SceneSpec

    page = "\n".join(ln for ln in pages["reference/scene.md"].splitlines() if not ln.startswith("| `rr_start_depth`"))
    sections = _sections(page)
    expected = _fields_by_model(SceneSpec.model_json_schema(mode="validation"))
    assert expected["SimulationSpec"] - sections["SimulationSpec"] == {"rr_start_depth"}
