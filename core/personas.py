"""The personas of appendix A, read from the data file `data/personas.json`.

Rule: one data file holds every persona; features the thesis's text does not
state are listed per persona under "inferred" with the story they come from.
The file ships with the package and is read once at import, like a table.
`data/reading_personas.json` holds the personas of future work 1 (core/actionlevel.py),
who read some suggestion pairs as one whole (`reads`, core/interpretation.py
READINGS); they are kept apart, in READING_PERSONAS, so that the default study's
list (and its pinned results) never includes them.
"""

from __future__ import annotations

from importlib import resources

import msgspec

from pairplay.nearest import nearest
from pairplay.schemas.config import Persona

from .interpretation import reading_code
from pairplay.schemas.nesting import json_decode


class _PersonaFile(msgspec.Struct, forbid_unknown_fields=True):
    scale: str
    note: str
    personas: list[Persona]


class ReadingPersona(Persona, frozen=True, forbid_unknown_fields=True):
    """A persona who reads some suggestion pairs as one whole (core/interpretation.py READINGS)."""

    reads: tuple[str, ...] = ()

    def __post_init__(self) -> None:
        super().__post_init__()
        reading_code(self.reads)  # ValueError naming an unknown reading


class _ReadingPersonaFile(msgspec.Struct, forbid_unknown_fields=True):
    scale: str
    note: str
    personas: list[ReadingPersona]


def parse_personas(data: bytes, kind=_PersonaFile) -> dict[str, Persona]:
    """Personas by key from the JSON text of a persona file."""
    personas = json_decode(data, type=kind).personas
    return {p.key: p for p in personas}


PERSONAS: dict[str, Persona] = parse_personas(
    resources.files("pairplay.core").joinpath("data/personas.json").read_bytes())
READING_PERSONAS: dict[str, ReadingPersona] = parse_personas(
    resources.files("pairplay.core").joinpath("data/reading_personas.json").read_bytes(), _ReadingPersonaFile)


def persona(key: str) -> Persona:
    """A persona by key (case-insensitive) or by its full name."""
    k = key.lower()
    if k in PERSONAS:
        return PERSONAS[k]
    for p in PERSONAS.values():
        if p.name.lower() == k:
            return p
    near = nearest(k, PERSONAS)  # `ashly`: the one meant, before the list
    raise KeyError(f"unknown persona {key!r}" + (f" (did you mean {near!r}?)" if near else "")
                   + f"; known: {', '.join(PERSONAS)}")
