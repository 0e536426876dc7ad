"""The package's layers, as its docstring numbers them: an import never runs back up.

The numbered list in :mod:`tltrack`'s docstring is the map; a module may import its own layer and
those below it, at the top of a file or inside a function alike.
"""

from __future__ import annotations

import ast
import re
from pathlib import Path

import pytest
import tltrack

pytestmark = pytest.mark.unit

PACKAGE = Path(tltrack.__file__).parent


def layers() -> dict[str, int]:
    """Each top-level module's layer number, from the docstring's numbered items."""
    items = re.split(r"^(\d+)\. ", tltrack.__doc__ or "", flags=re.M)
    out: dict[str, int] = {}
    for number, text in zip(items[1::2], items[2::2], strict=True):
        for name in re.findall(r"tltrack\.(\w+)", text):
            out.setdefault(name, int(number))
    return out


def _top(module: str) -> str | None:
    parts = module.split(".")
    return parts[1] if parts[0] == "tltrack" and len(parts) > 1 else None


def _imports(path: Path) -> list[tuple[int, str]]:
    found = []
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        if isinstance(node, ast.Import):
            found += [(node.lineno, a.name) for a in node.names]
        elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            found.append((node.lineno, node.module))
    return found


def test_every_part_of_the_package_has_a_layer() -> None:
    """A new module or folder of Python must be placed in the list (access/ holds data only)."""
    parts = {p.stem for p in PACKAGE.iterdir() if p.suffix == ".py" or any(p.glob("*.py"))}
    assert parts - {"__init__", "__main__"} == set(layers())


def test_no_import_runs_back_up_the_layers() -> None:
    rank = layers()
    assert len(set(rank.values())) >= 9, rank  # the list was read
    upward = []
    checked = 0
    for top, own in rank.items():
        files = [PACKAGE / f"{top}.py"] if (PACKAGE / f"{top}.py").exists() else []
        files += sorted((PACKAGE / top).rglob("*.py")) if (PACKAGE / top).is_dir() else []
        for path in files:
            for line, module in _imports(path):
                target = _top(module)
                checked += 1
                if target in rank and rank[target] > own:
                    upward.append(f"{path.relative_to(PACKAGE)}:{line} imports {module}")
    assert checked > 500
    assert not upward, "\n".join(upward)
