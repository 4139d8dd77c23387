"""A versioned JSON file kind of ours (a policy file, a fitted-user file): one codec for all of them.

Rule: a file is one msgspec Struct encoded as JSON with one-space indents and a
final newline (keys in the Struct's order, floats in shortest round-trip form,
so the same value gives the same bytes); it is written only through
pairplay.outputs (atomic, no clobber without `force`); reading it either gives
the whole checked value or raises the kind's own error (an InputError
subclass) whose message starts with the file's name and says why, never a
half-read value. The Struct's `__post_init__` checks `format` and `version`;
a file without `format` is refused naming the field (the Struct's default
filled it in: `{}`-like files with the other fields were read as policies).
A UTF-8 byte order mark (a Windows editor's) is accepted, as in every text
input of ours (`without_bom`): it was "malformed at byte 0", the BOM unnamed.
A file of nothing (or of blanks) is "<file>: the file is empty" (`empty`), in
every JSON, TOML or MCAP input alike.
"""

from __future__ import annotations

from pathlib import Path
from typing import Generic, TypeVar

import msgspec
from pairplay.numbers import counted

T = TypeVar("T")
BOM = b"\xef\xbb\xbf"  # UTF-8's byte order mark: Notepad and other editors start a saved file with it
MCAP_MAGIC = b"\x89MCAP0\r\n"  # the first (and last) 8 bytes of every MCAP file (the MCAP specification);
# here, the lowest layer that reads files, so replay/ takes it from here too


def without_bom(data: bytes) -> bytes:
    """`data` without a leading UTF-8 byte order mark (what encoding="utf-8-sig" does for text): every
    JSON or TOML input a user may have saved from an editor is read through this or utf-8-sig."""
    return data[len(BOM):] if data.startswith(BOM) else data


def empty(data: bytes | str) -> str:
    """"the file is empty" (with how many bytes of blank it holds, if any) if `data`, a file's content, holds
    nothing but a byte order mark and whitespace, else "". Every JSON, TOML or MCAP input says so in these
    words, naming the file: msgspec said "Input data was truncated", a study file "Object missing required
    field `study`", JSON5 "Empty strings are not legal JSON5", and an empty sweep file ran the default
    study with exit 0 (a new user's trial)."""
    raw = data.encode("utf-8") if isinstance(data, str) else data
    if without_bom(raw).strip():
        return ""
    return "the file is empty" + (f" ({counted(len(raw), 'byte')} of blank)" if raw else "")


class _Format(msgspec.Struct):
    format: str  # required: a kind's Struct has a default for it, so a file without it was accepted


_format_decoder = msgspec.json.Decoder(_Format)


class JsonFileKind(Generic[T]):
    """encode/decode/write/read of one file kind: `struct` (a msgspec Struct type), the `error` it
    raises (InputError subclass), `what` names it in messages ("policy file")."""

    def __init__(self, struct: type[T], error: type[Exception], what: str, from_recording: str = ""):
        self.error, self.what = error, what
        self.from_recording = from_recording  # what makes one of a recording, said when given a recording
        self._encoder = msgspec.json.Encoder()
        self._decoder = msgspec.json.Decoder(struct)

    def encode(self, value: T) -> bytes:
        return msgspec.json.format(self._encoder.encode(value), indent=1) + b"\n"

    def decode(self, data: bytes, source: str | None = None) -> T:
        """Parse and check; the kind's error, starting with `source` (default: `what`), otherwise."""
        source = source or self.what
        if data[:len(MCAP_MAGIC)] == MCAP_MAGIC:  # was "JSON is malformed": the user gave the wrong file
            raise self.error(f"{source}: an MCAP recording, not a {self.what}"
                             + (f" ({self.from_recording})" if self.from_recording else ""))
        if empty(data):
            raise self.error(f"{source}: {empty(data)}")
        data = without_bom(data)
        try:
            _format_decoder.decode(data)
        except msgspec.ValidationError as exc:
            if "missing required field `format`" in str(exc):
                raise self.error(f'{source}: no "format" field: not a {self.what}') from None
        except msgspec.DecodeError:
            pass  # malformed: said below, as before
        try:
            return self._decoder.decode(data)
        except self.error as exc:
            raise self.error(f"{source}: {exc}") from None
        except (msgspec.ValidationError, msgspec.DecodeError, ValueError) as exc:
            raise self.error(f"{source}: corrupt or not a {self.what}: {exc}") from None

    def write(self, path, value: T, force: bool = False) -> None:
        """Write atomically (a crash never leaves half a file); an existing file is replaced only
        with `force` (OutputError otherwise; pairplay.outputs)."""
        from pairplay.outputs import write_bytes

        write_bytes(path, self.encode(value), force)

    def read(self, path) -> T:
        """The checked value of the file at `path`; the kind's error if it cannot be read or used."""
        try:
            data = Path(path).read_bytes()
        except OSError as exc:
            raise self.error(f"{path}: cannot read: {exc.strerror}") from None
        return self.decode(data, str(path))
