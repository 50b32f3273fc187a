"""MkDocs hook: add the reference pages generated from the pydantic models (docs/gen_reference.py) to the build.

They are never written into docs/, so there is nothing to commit and nothing that can go stale.
"""
from __future__ import annotations

import importlib.util
import sys
from pathlib import Path

from mkdocs.structure.files import File, Files


def _generator():
    spec = importlib.util.spec_from_file_location("owcsim_docs_gen_reference", Path(__file__).with_name("gen_reference.py"))
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module  # dataclasses look their module up there
    spec.loader.exec_module(module)
    return module


def on_files(files: Files, config) -> Files:
    for path, text in _generator().pages().items():
        files.append(File.generated(config, path, content=text))
    return files
