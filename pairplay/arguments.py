"""A public function's arguments, checked at its door (the API listed in pairplay/__init__.py).

Rule: every function of the public API checks what a caller hands it before any work, and a
caller's mistake raises a `pairplay.errors.UserError`: its one line says what is wrong and
where, the function and argument (`pairplay.read_log(path)`) or the file. A value of the wrong
kind (a number for a path, a path where a read policy is taken, text for a count) is an
`ArgumentError`, both an InputError and a TypeError; a value of the right kind that cannot be
used (an empty list, a file that does not exist) an InputError (a ValueError), a setting out of
range an OptionError (a ValueError), an output that exists an OutputError (`force=True` replaces
it). Errors deep inside (AttributeError 'strip', a comparison's TypeError, FileNotFoundError)
said where the mistake surfaced, never what the caller gave. Before the values, the call itself:
an argument the function or class does not take (with the one it resembles), one missing, too many
by position (`call_arguments`: Python's and msgspec's TypeErrors named neither the API nor a way
out). A bool is never an integer (True was taken as 1: `env.step(True)`); numpy's integers are.
Standard library only (every layer imports this).
"""

from __future__ import annotations

import numbers
import os
from pathlib import Path
from typing import Any

from pairplay.errors import ArgumentError, InputError
from pairplay.nearest import nearest


def at(function: str, name: str) -> str:
    """Where a mistake in argument `name` of `function` is: `pairplay.read_log(path)`."""
    return f"pairplay.{function}({name})"


def given(value: Any) -> str:
    """A value as a message says what was given: its type and (short) repr."""
    text = repr(value)
    text = text if len(text) <= 60 else text[:57] + "..."
    return f"{type(value).__name__} {text}"


def is_integer(value: Any) -> bool:
    """Whether `value` is an integer: Python's or numpy's, never a bool (numpy's neither)."""
    return isinstance(value, numbers.Integral) and type(value).__name__ not in ("bool", "bool_")


def path_argument(value: Any, function: str, name: str = "path") -> Path:
    """`value` as a Path: text or an os.PathLike naming something (ArgumentError otherwise)."""
    if not isinstance(value, (str, os.PathLike)) or isinstance(value, bytes):
        raise ArgumentError(f"{name} must be a path (text or a pathlib.Path), got {given(value)}", at(function, name))
    if not str(os.fspath(value)).strip():
        raise InputError(f"{name} is empty: it names no file", at(function, name))
    return Path(value)


def integer_argument(value: Any, function: str, name: str, low: int | None = None) -> int:
    """`value` as an int (module rule: no bool), at least `low` if given."""
    if not is_integer(value):
        raise ArgumentError(f"{name} must be an integer, got {given(value)}", at(function, name))
    if low is not None and value < low:
        raise InputError(f"{name} must be at least {low}, got {value}", at(function, name))
    return int(value)


def flag_argument(value: Any, function: str, name: str) -> bool:
    """`value`, which must be True or False (a "no" string is true to Python)."""
    if not isinstance(value, bool) and type(value).__name__ != "bool_":
        raise ArgumentError(f"{name} must be True or False, got {given(value)}", at(function, name))
    return bool(value)


def instance_argument(value: Any, kind: type | tuple, function: str, name: str, what: str) -> Any:
    """`value` if it is a `kind` (`what` says one in words: "a PolicyFile (pairplay.read_policy)")."""
    if not isinstance(value, kind):
        raise ArgumentError(f"{name} must be {what}, got {given(value)}", at(function, name))
    return value


def list_argument(values: Any, kind: type | tuple, function: str, name: str, what: str, empty_ok: bool = False) -> list:
    """`values` as a list, each a `kind` (`what`: one in words), at least one unless `empty_ok`."""
    if isinstance(values, (str, bytes, dict)) or not hasattr(values, "__iter__"):
        raise ArgumentError(f"{name} must be a list (each {what}), got {given(values)}", at(function, name))
    items = list(values)
    if not items and not empty_ok:
        raise InputError(f"{name} is empty: give one or more, each {what}", at(function, name))
    for place, item in enumerate(items):
        if not isinstance(item, kind):
            raise ArgumentError(f"{name}[{place}] must be {what}, got {given(item)}", at(function, name))
    return items


def call_arguments(name: str, signature, args: tuple, kwargs: dict) -> None:
    """A call of the public API's `name` (a function, or a class's constructor: `StudySettings`) with `args` and
    `kwargs`, checked against its `signature` (inspect.Signature) before it runs: an ArgumentError in the
    project's words where Python said "got an unexpected keyword argument 'bogus'" (msgspec: "Unexpected keyword
    argument 'bogus'"), "missing 1 required positional argument" or "takes 2 positional arguments but 3 were
    given". The values are the callee's own to check."""
    from inspect import Parameter as P

    params = [p for p in signature.parameters.values() if p.name != "self"]
    kinds = {p.kind for p in params}
    by_name = [p.name for p in params if p.kind in (P.POSITIONAL_OR_KEYWORD, P.KEYWORD_ONLY)]
    if P.VAR_KEYWORD not in kinds:
        for key in kwargs:
            if key not in by_name:
                near = nearest(key, by_name)
                raise ArgumentError(f"no argument `{key}` is known here" + (
                    f" (did you mean `{near}`?)" if near else f"; it takes {', '.join(by_name) or 'none by name'}"),
                    at(name, key))
    positional = [p.name for p in params if p.kind in (P.POSITIONAL_ONLY, P.POSITIONAL_OR_KEYWORD)]
    if P.VAR_POSITIONAL not in kinds and len(args) > len(positional):
        how = f"at most {len(positional)} by position" if positional else "its values by name only"
        raise ArgumentError(f"takes {how}, got {len(args)}: name them ({by_name[0] if by_name else '...'}=...)",
                            f"pairplay.{name}")
    for key in positional[:len(args)]:
        if key in kwargs:
            raise ArgumentError(f"`{key}` is given twice, by position and by name", at(name, key))
    given_ = set(positional[:len(args)]) | set(kwargs)
    missing = [p.name for p in params if p.default is P.empty and p.name not in given_
               and p.kind not in (P.VAR_POSITIONAL, P.VAR_KEYWORD)]
    if missing:
        raise ArgumentError(f"needs {', '.join(f'`{m}`' for m in missing)} (no default)", f"pairplay.{name}")


def checked_dataclass(cls):
    """`cls`, a dataclass of the public API, whose constructor checks its arguments first (`call_arguments`):
    `pairplay.StudySettings(bogus=1)` said Python's "__init__() got an unexpected keyword argument 'bogus'"."""
    import functools
    import inspect

    init = cls.__init__
    signature = inspect.signature(init)

    @functools.wraps(init)
    def checked(self, *args, **kwargs):
        call_arguments(cls.__name__, signature, args, kwargs)
        init(self, *args, **kwargs)
    cls.__init__ = checked
    return cls


# a verb's option -> the argument of the public functions that does the same (the fix a refusal offers)
PYTHON_NAMES = {"--force": "force=True"}


def python_words(function, name: str = ""):
    """`function` as the public API hands it out (pairplay/__init__.py): its arguments checked first
    (`call_arguments`), and a refusal whose way out names a verb's option (`--force replaces it`) names the
    argument instead (`force=True replaces it`), shown in the error's one line; the command line imports the
    function itself and keeps its option's words. `name`: its public name (`read_policy` is a file kind's `read`)."""
    import functools
    import inspect

    from pairplay.errors import UserError

    signature = inspect.signature(function)

    @functools.wraps(function)
    def called(*args, **kwargs):
        call_arguments(name or function.__name__, signature, args, kwargs)  # read_log(pth=...): Python's TypeError
        try:
            return function(*args, **kwargs)
        except UserError as err:
            if hasattr(err, "in_python"):  # its words name a verb's option in its text (services/recorder.py)
                err.in_python()
            if err.fix and err.option in PYTHON_NAMES:
                err.fix, err.option = err.fix.replace(err.option, PYTHON_NAMES[err.option]), ""
            raise
    return called
