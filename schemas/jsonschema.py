"""JSON Schemas of the events, generated from the Structs and flattened.

Rule: the schema of a channel is the schema of its event class, with every
`$ref` into `$defs` inlined, so the root is the object itself (viewers such as
Foxglove need not resolve a `$ref` root). The committed copies in schemas/json/
are regenerated with `python -m pairplay.schemas.jsonschema` and a test checks
they match the code.
"""

from __future__ import annotations

import inspect
import json
import sys
from pathlib import Path
from typing import Any

import msgspec

from .events import EVENT_TYPES
from .envelope import Event, schema_hook

JSON_DIR = Path(__file__).parent / "json"


def _clean_docs(node: Any) -> Any:
    """Docstring text as Python 3.13 and msgspec 0.23 give it, whatever made it.

    msgspec copies a Struct's docstring into `description`; whether its
    indentation survives depends on the Python (3.13 strips it at compile time)
    and on msgspec (0.23 strips it too). `inspect.cleandoc` is idempotent, so
    cleaning here makes the schema bytes the same under every combination.
    """
    if isinstance(node, dict):
        return {
            k: inspect.cleandoc(v) if k in ("description", "title") and isinstance(v, str) else _clean_docs(v)
            for k, v in node.items()
        }
    if isinstance(node, list):
        return [_clean_docs(v) for v in node]
    return node


def _inline(node: Any, defs: dict[str, Any], seen: tuple[str, ...]) -> Any:
    if isinstance(node, dict):
        ref = node.get("$ref")
        if isinstance(ref, str) and ref.startswith("#/$defs/"):
            name = ref.removeprefix("#/$defs/")
            if name in seen:
                raise ValueError(f"recursive schema through {name}: cannot flatten")
            rest = {k: v for k, v in node.items() if k != "$ref"}
            return {**_inline(defs[name], defs, seen + (name,)), **_inline(rest, defs, seen)}
        return {k: _inline(v, defs, seen) for k, v in node.items()}
    if isinstance(node, list):
        return [_inline(v, defs, seen) for v in node]
    return node


def flat_schema(event_type: type[Event]) -> dict[str, Any]:
    """The JSON Schema of one event class with no `$ref` left."""
    raw = msgspec.json.schema(event_type, schema_hook=schema_hook)
    defs = raw.pop("$defs", {})
    flat = _clean_docs(_inline(raw, defs, ()))
    flat["$schema"] = "https://json-schema.org/draft/2020-12/schema"
    return flat


def schema_text(event_type: type[Event]) -> str:
    return json.dumps(flat_schema(event_type), indent=1, sort_keys=True) + "\n"


def write_all(directory: Path = JSON_DIR) -> list[Path]:
    directory.mkdir(parents=True, exist_ok=True)
    paths = []
    for t in EVENT_TYPES:
        path = directory / f"{t.__struct_config__.tag}.json"
        path.write_text(schema_text(t))
        paths.append(path)
    return paths


if __name__ == "__main__":
    for p in write_all(Path(sys.argv[1]) if len(sys.argv) > 1 else JSON_DIR):
        print(p)
