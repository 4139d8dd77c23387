"""A JSON file or line that gives one key twice in one object is refused, naming the key.

Rule: every JSON input a user can edit (policy and fitted-user files, the robot config, the board
calibration, a study's settings.json and journal lines, a sweep's cell files, an output folder's
manifest; the Zenoh config, JSON5, alike) is checked by `refuse_repeated` before it is read; a repeated key is a
msgspec.ValidationError "Object contains the key `K` more than once - at `$.WHERE`", which every
caller already refuses and words (`jsonfile.in_words`: "WHERE: the key `K` is given twice ...").

Why: msgspec (and json) keep the last of two values of one key without a word, so a second
`"partial": ""` erased a policy's partial flag and `combine` passed the partial input off as whole,
and a second `"participant"` moved a policy to another participant (a hostile user's trial,
trial28 F16). TOML refuses the same ("Cannot overwrite a value"); JSON read here now does too.

How, cheaply: msgspec has no option for it, so the text is parsed once more by the standard json
module (C) with an `object_pairs_hook`, which is Python only once per object (a policy's tables are
arrays of numbers: few objects). Text json cannot parse is left to the caller's own decode, which
says what is wrong with it in its own words.
"""

from __future__ import annotations

from typing import Any, Callable

import msgspec

from .nesting import json_loads

Loads = Callable[..., Any]  # a reader of JSON text taking `object_pairs_hook` (json's loads; json5's for the Zenoh config)


class _Repeated(Exception):
    """Raised by the hook: the key given twice and the object (as json built it, last-wins) it is in."""

    def __init__(self, key: str):
        super().__init__(key)
        self.key = key


def _pairs(pairs: list[tuple[str, object]]) -> dict:
    """The object of `pairs`, as json builds it; _Repeated at its first key given twice."""
    value = dict(pairs)
    if len(value) != len(pairs):  # the one common case costs one dict and a len
        seen: set[str] = set()
        for key, _ in pairs:
            if key in seen:
                raise _Repeated(key)
            seen.add(key)
    return value


def _where(data: bytes | str, key: str, loads: Loads) -> str:
    """msgspec's path (`learner`, `q[0]`; "" at the top) of the first object of `data` holding `key` twice:
    parsed again (only for a file being refused) with a hook that records, for each object, whether it repeats
    `key`, then the tree walked for the object that does."""
    found: list[dict] = []

    def mark(pairs: list[tuple[str, object]]) -> dict:
        value = dict(pairs)
        if len(value) != len(pairs) and sum(1 for k, _ in pairs if k == key) > 1:
            found.append(value)
        return value

    top = loads(data, object_pairs_hook=mark)
    if not found:
        return ""
    target = found[0]

    def walk(value: object, where: str) -> str | None:
        if value is target:
            return where
        if isinstance(value, dict):
            items = ((f"{where}.{k}" if where else k, v) for k, v in value.items())
        elif isinstance(value, list):
            items = ((f"{where}[{n}]", v) for n, v in enumerate(value))
        else:
            return None
        for step, item in items:
            if (at := walk(item, step)) is not None:
                return at
        return None

    try:
        return walk(top, "") or ""
    except RecursionError:  # json read it, this walk (more frames a level) did not: the key alone is said
        return ""


def repeated_key(data: bytes | str, loads: Loads = json_loads) -> tuple[str, str] | None:
    """(where, key) of the first key given twice in one object of the JSON text `data` (where as msgspec
    writes a path, "" at the top), or None if none is, or if `data` is not JSON that `loads` reads (its
    reader says why)."""
    try:
        loads(data, object_pairs_hook=_pairs)
    except _Repeated as repeated:
        return _where(data, repeated.key, loads), repeated.key
    except (ValueError, RecursionError):  # not JSON (UnicodeDecodeError, too many digits too): the reader says
        return None
    return None


def refuse_repeated(data: bytes | str, loads: Loads = json_loads) -> None:
    """msgspec.ValidationError naming the key (and where) if the JSON text `data` gives a key twice in one
    object (module rule); nothing otherwise. `loads`: what reads it (json5.loads for a JSON5 file)."""
    if (found := repeated_key(data, loads)) is not None:
        where, key = found
        raise msgspec.ValidationError(f"Object contains the key `{key}` more than once"
                                      + (f" - at `${'' if where.startswith('[') else '.'}{where}`" if where else ""))
