"""A module's private names (a leading underscore) are its own: no other module of pairplay imports one.

Found by a helper (streamverbs): services/biasfile.py imported pairplay/outputs.py's `_remove_dead_temps`,
and five more did the same (core/actionlevel.py combine's `_HEAD`, `_SPEECH`, `_exempt_*`; core/simulate.py
learning's `_policy_table`; replay/reader.py events' `_decoder`; report/counterfactual.py plots' `_pyplot`,
`_save`; services/recorder.py reader's `_listed`; bench/core.py kernels' `_draw`): a name another module
needs is public, or the helper moves. The whole kind: every `from <pairplay module> import _name` and every
`<imported pairplay module>._name` in the code (tests are white-box and may reach in)."""

from __future__ import annotations

import ast

from test_path_words import ROOT, code_files

PACKAGES = {"core", "replay", "report", "services", "schemas", "cli", "pairplay", "bench", "gym"}


def _ours(module: str | None, level: int) -> bool:
    return level > 0 or (module or "").split(".")[0] in {"pairplay", *PACKAGES}


def test_no_module_imports_or_reaches_into_another_modules_private_names():
    found = []
    for path in code_files():
        tree = ast.parse(path.read_text(), str(path))
        modules = set()  # the names our imported modules are bound to here
        for node in ast.walk(tree):
            if isinstance(node, ast.ImportFrom) and _ours(node.module, node.level):
                for alias in node.names:
                    if alias.name.startswith("_") and not alias.name.startswith("__"):
                        found.append(f"{path.relative_to(ROOT)}:{node.lineno}: imports {alias.name}")
                    else:
                        modules.add(alias.asname or alias.name)
            elif isinstance(node, ast.Import):
                for alias in node.names:
                    if _ours(alias.name, 0):
                        modules.add((alias.asname or alias.name).split(".")[0])
        for node in ast.walk(tree):
            if isinstance(node, ast.Attribute) and isinstance(node.value, ast.Name) and node.value.id in modules \
                    and node.attr.startswith("_") and not node.attr.startswith("__"):
                found.append(f"{path.relative_to(ROOT)}:{node.lineno}: {node.value.id}.{node.attr}")
    assert not found, "\n".join(found)
