"""A number as a message shows it: as the user wrote it, not as the float it became.

Rule: a value a user gave (an option, a file's key) is echoed by `shown(value)`:
an integral float without its `.0` (`--psi 0` was said "got 0.0", `epsilon_start
= 2` "got 2.0": options and TOML integers become floats on the way in), any other
number as Python's shortest exact text (0.95, 1e-300, nan, inf), anything else
as str() (an integer of 21 digits or more as "a number of 31 digits"); a float of a file read under `typed_floats` as the file has it (`1e7`). `type_name(kind)` is a Python type's name as a sentence says it ("an
integer", not "a int"). A count is said with its noun by `counted(n, noun)`:
"1 participant", "2 participants" (a fixed plural said "1 participants"), and a word that agrees with a
count by `agreement(n, one, many)` ("1 game stays", "2 games stay").
Standard library only (every layer imports this).
"""

from __future__ import annotations

import contextlib
import contextvars
import math

# the text of each float a file being read gave (`typed_floats`): shown() says it as typed
_TYPED: contextvars.ContextVar[dict | None] = contextvars.ContextVar("pairplay_typed_floats", default=None)

HUGE = 10**20  # an integer this large or larger is said by its number of digits (`shown`)
# a type's name in a sentence: "is not an integer", "must be a number" (the sweep said "is not a int")
TYPE_NAMES = {"int": "an integer", "float": "a number", "str": "text", "bool": "true or false",
              "list": "a list", "dict": "a table", "array": "a list", "object": "a table"}  # (msgspec: array, object)


def shown(value: object) -> str:
    """`value` as a message echoes it (module rule)."""
    typed = _TYPED.get()
    if typed and isinstance(value, float) and value in typed:  # a file's `1e7`, not 10000000
        return typed[value]
    if isinstance(value, float) and math.isfinite(value) and value.is_integer() and abs(value) < 1e16:
        return str(int(value))
    if isinstance(value, int) and not isinstance(value, bool) and abs(value) >= HUGE:
        # by its size: a line stays short, and str() of an int over 4300 digits raises ValueError
        digits = len(str(abs(value))) if abs(value).bit_length() < 10_000 else f"about {int(abs(value).bit_length() * 0.30103)}"
        return f"{'-' if value < 0 else ''}a number of {digits} digits"
    return str(value)


@contextlib.contextmanager
def typed_floats():
    """While a TOML file is read and checked: tomllib's `parse_float`, which notes each float's text, so
    `shown` echoes a float as the file has it (`rounds = 1e7` was said "10000000"). The first text of a
    value wins; an integer has no hook (tomllib's ints are echoed as Python writes them)."""
    typed: dict = {}

    def parse_float(text: str) -> float:
        value = float(text)
        typed.setdefault(value, text)
        return value
    token = _TYPED.set(typed)
    try:
        yield parse_float
    finally:
        _TYPED.reset(token)


def type_name(kind: object) -> str:
    """A type (or its name) as a sentence says it: int -> "an integer" (module rule)."""
    name = kind if isinstance(kind, str) else getattr(kind, "__name__", str(kind))
    return TYPE_NAMES.get(name, f"a {name}")


def counted(n: object, noun: str, many: str = "", spec: str = "") -> str:
    """`n` and its noun, singular for exactly 1 (module rule): counted(1, "round") -> "1 round",
    counted(3, "policy", "policies") -> "3 policies". `many`: the plural when it is not noun + "s";
    `spec`: the number's format (",": 12,345)."""
    return f"{n:{spec}} {noun if n == 1 else many or noun + 's'}"


def agreement(n: int, one: str, many: str) -> str:
    """The word that agrees with a count `n` (module rule): agreement(1, "stays", "stay") -> "stays",
    agreement(2, "it", "them") -> "them"."""
    return one if n == 1 else many
