"""MkDocs hook: add generated pages to the build.

- reference/scene.md, reference/result.md, reference/settings.md from the pydantic models
  (docs/gen_reference.py);
- changelog.md and contributing.md from CHANGELOG.md and CONTRIBUTING.md at the repository root,
  their links into docs/ rewritten to be relative to the site (`docs/physics.md` -> `physics.md`).

They are never written into docs/, so there is nothing to commit and nothing that can go stale.
"""

from __future__ import annotations

import importlib.util
import re
import sys
from pathlib import Path

from mkdocs.structure.files import File, Files


def _generator():
    spec = importlib.util.spec_from_file_location(
        "owcsim_docs_gen_reference", Path(__file__).with_name("gen_reference.py")
    )
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module  # dataclasses look their module up there
    spec.loader.exec_module(module)
    return module


#: Root files shown as site pages: {page: file at the repository root}.
ROOT_PAGES = {"changelog.md": "CHANGELOG.md", "contributing.md": "CONTRIBUTING.md"}


def root_page(text: str) -> str:
    """A root Markdown file as a page of the site: links into docs/ become site links."""
    return re.sub(r"\]\(docs/", "](", text)


def on_files(files: Files, config) -> Files:
    for path, text in _generator().pages().items():
        files.append(File.generated(config, path, content=text))
    root = Path(config["docs_dir"]).resolve().parent
    for page, name in ROOT_PAGES.items():
        files.append(File.generated(config, page, content=root_page((root / name).read_text())))
    return files
