"""The house rule: imports point one way, read from the code itself.

schemas <- core <- gym <- replay <- report <- services <- bench <- cli: a module may
import its own package and the packages before it, never one after it. Only
`services` (and `bench`, which measures it) may import the bus, the robot
clients, the web stack or rerun; `core` imports numpy, numba (its compiled
kernels) and the standard library and nothing that does I/O.
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
ORDER = ["schemas", "core", "gym", "replay", "report", "services", "bench", "cli"]
WIRE = {"zenoh", "rerun", "websockets", "starlette", "uvicorn"}


def _modules():
    for package in ORDER:
        for path in sorted((ROOT / package).rglob("*.py")):
            yield package, path


def _imports(path: Path) -> list[tuple[int, str]]:
    tree = ast.parse(path.read_text(), str(path))
    found = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            found += [(node.lineno, a.name) for a in node.names]
        elif isinstance(node, ast.ImportFrom):
            if node.level:  # a relative import stays inside its own package
                continue
            found.append((node.lineno, node.module or ""))
    return found


def test_every_package_has_a_docstring_that_says_what_belongs_in_it():
    for package in ORDER + ["services/robot", "services/view"]:
        init = ROOT / package / "__init__.py"
        doc = ast.get_docstring(ast.parse(init.read_text()))
        assert doc and len(doc) > 80, f"{package}/__init__.py needs a docstring saying what belongs there"


@pytest.mark.parametrize("package,path", list(_modules()), ids=lambda v: str(v.relative_to(ROOT)) if isinstance(v, Path) else v)
def test_imports_point_one_way(package, path):
    rank = ORDER.index(package)
    for line, name in _imports(path):
        parts = name.split(".")
        if parts[0] == "pairplay" and len(parts) > 1 and parts[1] in ORDER:
            assert ORDER.index(parts[1]) <= rank, (
                f"{path.relative_to(ROOT)}:{line} imports {name}: {package} may import only {ORDER[:rank + 1]}")
        if parts[0] in WIRE:
            assert package in ("services", "bench", "cli"), f"{path.relative_to(ROOT)}:{line} imports {name}"
        if parts[0] == "gymnasium":  # RL interop stays in its room: core is numpy only
            assert package == "gym", f"{path.relative_to(ROOT)}:{line} imports {name}"


def test_the_public_api_resolves_every_name_it_lists():
    import pairplay

    for name in pairplay.API:
        assert getattr(pairplay, name) is not None, name
    assert set(pairplay.__all__) == {"__version__", *pairplay.API}
