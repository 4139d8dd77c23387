"""A Struct of the public API (pairplay/__init__.py) whose constructor says a caller's mistake in the project's words.

Rule: `pairplay.SessionConfig(bogus=1)` is refused as every public function refuses a mistake
(pairplay/arguments.py `call_arguments`: an ArgumentError, one line, the unknown argument and the one
it resembles), not with msgspec's "Unexpected keyword argument 'bogus'". A Struct takes no `__init__` or
`__new__` of its own, so the check is its metaclass's `__call__`; msgspec lets a metaclass derive from its
StructMeta from 0.20 on (`msgspec.StructMeta`), the lowest pyproject declares (on 0.19 the Struct kept
msgspec's words). Decoding never calls the constructor: a file's keys are checked by the decoder
(schemas/jsonfile.py).

Each field alone is checked where the Struct is made, by its `__post_init__` (`check_kinds`, then its own
ranges): msgspec's constructor checks no type, so `SessionConfig(rounds="20")` was taken and refused only when
run_session ran. `__post_init__` runs on decode too: a file or a message holding a field out of its range is
then a msgspec.ValidationError, malformed input refused as every malformed input is (a reader's bad record, the
recorder's MessageRejected), never a traceback; its kinds the decoder has checked already. A FieldError raised
for a caller's call is said in the public API's words by the metaclass (`pairplay.SessionConfig(rounds)`).
"""

from __future__ import annotations

import inspect

import msgspec

from pairplay.arguments import at, call_arguments, given
from pairplay.errors import ArgumentError, OptionError, UserError

_SIGNATURES: dict[type, inspect.Signature] = {}
_KINDS: dict[type, type] = {}  # a public Struct -> its twin without checks (`check_kinds`)


class FieldError(ValueError):
    """A field of a public Struct that cannot be, alone (`key`: the field; `what`: why, naming it), raised by its
    `__post_init__` (module rule). A ValueError, so that msgspec makes it a ValidationError on decode."""

    def __init__(self, key: str, what: str):
        super().__init__(what)
        self.key, self.what = key, what


class FieldKindError(FieldError, TypeError):
    """A field not of its kind (`check_kinds`)."""


def public_error(err: FieldError, struct: str) -> UserError:
    """`err` as the public API says it (pairplay/arguments.py rule): ArgumentError for a kind, OptionError for a
    range, where `pairplay.<struct>(<field>)`. (The verbs bound every option before they make the Struct: a
    refusal here is a Python caller's.)"""
    return (ArgumentError if isinstance(err, TypeError) else OptionError)(err.what, at(struct, err.key))


def check_kinds(value: msgspec.Struct) -> None:
    """FieldKindError for the first field of `value` not of its declared kind, checked as the decoder checks a
    file's (msgspec.convert of its builtins into a twin Struct without `__post_init__`: an integer is never a
    bool, text never a number; one that cannot be encoded at all, a numpy array, is not of its kind either)."""
    from .jsonfile import in_words

    cls = type(value)
    twin = _KINDS.get(cls)
    if twin is None:  # once per class: the same fields and types, no checks of its own
        twin = _KINDS[cls] = msgspec.defstruct(
            f"{cls.__name__}Kinds", [(f.name, f.type) if f.required else (f.name, f.type, msgspec.UNSET)
                                     for f in msgspec.structs.fields(cls)], kw_only=True)
    for f in msgspec.structs.fields(cls):
        field = getattr(value, f.name)
        if field is msgspec.UNSET:
            continue  # (a field left out: what its default says)
        try:
            msgspec.to_builtins(field)
        except TypeError:  # (what to_builtins cannot encode, no field could ever be)
            raise FieldKindError(f.name, f"{f.name} cannot be {given(field)}: give a plain Python value "
                                 "(int(...), float(...), list(...))") from None
    try:
        msgspec.convert(msgspec.to_builtins(value), twin)
    except msgspec.ValidationError as exc:
        said = in_words(exc, cls)
        path, _, what = said.partition(": ")
        key = path.split("[", 1)[0].split(".", 1)[0]
        if path == key and ", got " in what:  # the field itself: what was given, as StudySettings says it
            said = f"{key} {what.rsplit(', got ', 1)[0]}, got {given(getattr(value, key))}"
        raise FieldKindError(key, said) from None


class PublicStructMeta(msgspec.StructMeta):
    """The metaclass of a public Struct: its arguments checked before msgspec builds it."""

    def __call__(cls, *args, **kwargs):
        signature = _SIGNATURES.get(cls)
        if signature is None:  # once per class
            signature = _SIGNATURES[cls] = inspect.signature(cls)
        call_arguments(cls.__name__, signature, args, kwargs)
        try:
            return super().__call__(*args, **kwargs)
        except FieldError as err:  # its __post_init__'s (module rule)
            raise public_error(err, cls.__name__) from None
