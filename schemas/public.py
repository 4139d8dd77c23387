"""A Struct of the public API (pairplay/__init__.py) whose constructor says a caller's mistake in the project's words.

Rule: `pairplay.SessionConfig(bogus=1)` is refused as every public function refuses a mistake
(pairplay/arguments.py `call_arguments`: an ArgumentError, one line, the unknown argument and the one
it resembles), not with msgspec's "Unexpected keyword argument 'bogus'". A Struct takes no `__init__` or
`__new__` of its own, so the check is its metaclass's `__call__`; msgspec lets a metaclass derive from its
StructMeta from 0.20 on (`msgspec.StructMeta`), the lowest pyproject declares (on 0.19 the Struct kept
msgspec's words). Decoding never calls the constructor: a file's keys are checked by the decoder
(schemas/jsonfile.py).
"""

from __future__ import annotations

import inspect

import msgspec

from pairplay.arguments import call_arguments

_SIGNATURES: dict[type, inspect.Signature] = {}


class PublicStructMeta(msgspec.StructMeta):
    """The metaclass of a public Struct: its arguments checked before msgspec builds it."""

    def __call__(cls, *args, **kwargs):
        signature = _SIGNATURES.get(cls)
        if signature is None:  # once per class
            signature = _SIGNATURES[cls] = inspect.signature(cls)
        call_arguments(cls.__name__, signature, args, kwargs)
        return super().__call__(*args, **kwargs)
