"""Import direction: schemas <- engine <- server; schemas <- formats <- clients, server; clients never import
engine or server; formats (file writers and plots) import schemas only."""

import ast
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
FORBIDDEN = {
    "schemas": {"engine", "server", "clients", "cli", "formats"},
    "formats": {"engine", "server", "clients", "cli"},
    "engine": {"server", "clients", "cli", "formats"},
    "clients": {"engine", "server"},
    "server": {"clients", "cli"},
}


def _layers(path: Path) -> set[str]:
    """The owcsim layers a file imports (`owcsim.engine...` -> engine); a bare `engine` import counts too."""
    tree = ast.parse(path.read_text())
    names = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            names |= {a.name for a in node.names}
        elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
            names.add(node.module)
    out = set()
    for name in names:
        parts = name.split(".")
        if parts[0] == "owcsim" and len(parts) > 1:
            out.add(parts[1])
        elif parts[0] in FORBIDDEN:
            out.add(f"bare {parts[0]}")
    return out


@pytest.mark.parametrize("package", sorted(FORBIDDEN))
def test_import_direction(package):
    files = list((ROOT / package).rglob("*.py"))
    assert files
    for f in files:
        layers = _layers(f)
        bad = (layers & FORBIDDEN[package]) | {x for x in layers if x.startswith("bare ")}
        assert not bad, f"{f.relative_to(ROOT)} imports {bad}"
