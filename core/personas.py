"""The personas of appendix A, read from the data file `data/personas.json`.

Rule: one data file holds every persona; features the thesis's text does not
state are listed per persona under "inferred" with the story they come from.
The file ships with the package and is read once at import, like a table.
"""

from __future__ import annotations

from importlib import resources

import msgspec

from pairplay.schemas.config import Persona


class _PersonaFile(msgspec.Struct, forbid_unknown_fields=True):
    scale: str
    note: str
    personas: list[Persona]


def parse_personas(data: bytes) -> dict[str, Persona]:
    """Personas by key from the JSON text of a persona file."""
    personas = msgspec.json.decode(data, type=_PersonaFile).personas
    return {p.key: p for p in personas}


PERSONAS: dict[str, Persona] = parse_personas(
    resources.files("pairplay.core").joinpath("data/personas.json").read_bytes())


def persona(key: str) -> Persona:
    """A persona by key (case-insensitive) or by its full name."""
    k = key.lower()
    if k in PERSONAS:
        return PERSONAS[k]
    for p in PERSONAS.values():
        if p.name.lower() == k:
            return p
    raise KeyError(f"unknown persona {key!r}; known: {', '.join(PERSONAS)}")
