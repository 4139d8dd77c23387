"""Decoding outside data never raises RecursionError.

Rule: every decoder of bytes that come from outside the process (bus messages, robot frames,
WebSocket and HTTP bodies, recordings, journals, policy, settings and study files) is one of
this module's, which turn a RecursionError into the decoding library's own error:
msgspec.DecodeError, json.JSONDecodeError, tomllib.TOMLDecodeError. Every caller already
refuses and records those.

Why: msgspec, the standard json module and tomllib recurse once per level of nesting, so
a value nested ~1,000 deep (`{"a":` x 1,500: 9 KB, under the bus's payload limit) raised
RecursionError, which nothing caught: one such message on the bus killed the recorder, the
robot bridge's thread and the session, and `pairplay recover` then died on the same message
in the journal (a hostile user's trial, trial28 F18). No pairplay value is nested more than
a few levels, so whatever is that deep is not one of ours.
"""

from __future__ import annotations

import json
import tomllib
from typing import Any

import msgspec

TOO_DEEP = "nested too deeply (a value inside ~1,000 others): not a pairplay message or file"


class JsonDecoder:
    """msgspec.json.Decoder (same arguments) whose `decode` raises msgspec.DecodeError on nesting too deep
    (module rule)."""

    __slots__ = ("_decode", "type")

    @property
    def raw(self):
        """msgspec's own `decode`, for a hot loop that catches RecursionError itself (a Python frame per
        message is a tenth of a recording's read)."""
        return self._decode

    def __init__(self, *args: Any, **kwargs: Any):
        decoder = msgspec.json.Decoder(*args, **kwargs)
        self._decode, self.type = decoder.decode, decoder.type

    def decode(self, data: bytes | bytearray | memoryview | str) -> Any:
        try:
            return self._decode(data)
        except RecursionError:
            raise msgspec.DecodeError(TOO_DEEP) from None


class MsgpackDecoder(JsonDecoder):
    """msgspec.msgpack.Decoder (same arguments), as JsonDecoder (module rule)."""

    def __init__(self, *args: Any, **kwargs: Any):
        decoder = msgspec.msgpack.Decoder(*args, **kwargs)
        self._decode, self.type = decoder.decode, decoder.type


def json_decode(data: bytes | bytearray | memoryview | str, **kwargs: Any) -> Any:
    """msgspec.json.decode(data, **kwargs); msgspec.DecodeError on nesting too deep (module rule)."""
    try:
        return msgspec.json.decode(data, **kwargs)
    except RecursionError:
        raise msgspec.DecodeError(TOO_DEEP) from None


def msgpack_decode(data: bytes | bytearray | memoryview, **kwargs: Any) -> Any:
    """msgspec.msgpack.decode(data, **kwargs); msgspec.DecodeError on nesting too deep (module rule)."""
    try:
        return msgspec.msgpack.decode(data, **kwargs)
    except RecursionError:
        raise msgspec.DecodeError(TOO_DEEP) from None


def json_loads(text: str | bytes | bytearray, **kwargs: Any) -> Any:
    """json.loads(text, **kwargs); json.JSONDecodeError on nesting too deep (module rule)."""
    try:
        return json.loads(text, **kwargs)
    except RecursionError:
        raise json.JSONDecodeError(TOO_DEEP, text if isinstance(text, str) else "", 0) from None


def toml_loads(text: str, **kwargs: Any) -> dict[str, Any]:
    """tomllib.loads(text, **kwargs); tomllib.TOMLDecodeError on nesting too deep (module rule)."""
    try:
        return tomllib.loads(text, **kwargs)
    except RecursionError:
        raise tomllib.TOMLDecodeError(TOO_DEEP) from None
