"""A versioned JSON file kind of ours (a policy file, a fitted-user file): one codec for all of them.

Rule: a file is one msgspec Struct encoded as JSON with one-space indents and a
final newline (keys in the Struct's order, floats in shortest round-trip form,
so the same value gives the same bytes); it is written only through
pairplay.outputs (atomic, no clobber without `force`); reading it either gives
the whole checked value or raises the kind's own error (an InputError
subclass) whose message starts with the file's name and says why, never a
half-read value. Every Struct of a file refuses a key it does not declare
(`forbid_unknown_fields`, at every level: a policy's misspelt `reward_bonsu`
was dropped and its default used). What the file says it is is read first:
a file without `format` is refused naming the field (the Struct's default
filled it in: `{}`-like files with the other fields were read as policies),
another kind's file for its format, and a file of a newer `version` (which
may add keys) for its version, not for a key it adds; an older file has fewer
keys, never more (fields are only added, with defaults). The Struct's
`__post_init__` checks `format` and `version` again, for values built in code.
A UTF-8 byte order mark (a Windows editor's) is accepted, as in every text
input of ours (`without_bom`): it was "malformed at byte 0", the BOM unnamed.
A file of nothing (or of blanks) is "<file>: the file is empty" (`empty`), in
every JSON, TOML or MCAP input alike. Why a JSON file cannot be used is said in
the file's words (`in_words`): the key as the file writes it and what is wrong
("q[0][1]: must be a number, got text"; "has no key `yaw_sgn` (did you mean
`yaw_sign`?)"), not msgspec's ("Expected `float`, got `str` - at `$.q[0][1]`"),
for every JSON input alike (policy and user-model files, the robot config, the
calibration). A file that is no JSON at all is said with where and what to do (`syntax_words`): a file
that ends inside its JSON is "cut short: it ends inside its JSON at line L (byte N, its end): a copy or a
save that did not finish? put back a whole copy" (msgspec said "Input data was truncated", no file's
place, no advice), a character that breaks it "not valid JSON at line L, column C (byte N): ...: correct
it there"; a TOML file's syntax alike (`toml_words`: tomllib's "(at end of document)" is said as the line
the file ends on).
A key an older pairplay's file holds and this one retired is said
to be retired, with what replaced it (a Struct's `RETIRED` table, `retired_key`),
never as a typo of another key. Every unknown or retired key of a file is said at once, in the
file's order (`unknown_keys`; the study and sweep files too), the first MAX_SAID by name and the
rest counted: msgspec stops at the first, and a file of two was fixed and rerun for each.
"""

from __future__ import annotations

import re
import types
import typing
from pathlib import Path
from typing import Generic, TypeVar

import msgspec
from pairplay.arguments import flag_argument, instance_argument, path_argument
from pairplay.inputs import check_input
from pairplay.nearest import nearest
from pairplay.numbers import counted, type_name
from .nesting import JsonDecoder, json_decode

T = TypeVar("T")
BOM = b"\xef\xbb\xbf"  # UTF-8's byte order mark: Notepad and other editors start a saved file with it
MCAP_MAGIC = b"\x89MCAP0\r\n"  # the first (and last) 8 bytes of every MCAP file (the MCAP specification);
# here, the lowest layer that reads files, so replay/ takes it from here too


def without_bom(data: bytes) -> bytes:
    """`data` without a leading UTF-8 byte order mark (what encoding="utf-8-sig" does for text): every
    JSON or TOML input a user may have saved from an editor is read through this or utf-8-sig."""
    return data[len(BOM):] if data.startswith(BOM) else data


def a_folder(path, what: str, give: str) -> str:
    """What a file input that is a folder is told, naming it: "<path>: a folder, not a <what>: give <give>".
    Every JSON or TOML input reads through this (a policy, the robot config, the calibration, a study file): it
    said the system's "cannot read: Is a directory", not what was expected there (a new user's trial:
    `protocol check STUDY_FOLDER`, `report --reference FOLDER`)."""
    return f"{path}: a folder, not a {what}: give {give}"


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


_LOCATED = re.compile(r"(.*?)(?: - at `\$(.*)`)?", re.S)
_BOUND = {">=": "at least", "<=": "at most", ">": "above", "<": "below"}


def _line_column(data: bytes, at: int) -> tuple[int, int]:
    """The line and column (from 1) of byte offset `at` of `data`."""
    before = data[:at]
    return before.count(b"\n") + 1, at - (before.rfind(b"\n") + 1) + 1


def syntax_words(exc: Exception, data: bytes | None) -> str:
    """msgspec's DecodeError for the JSON text `data` (a BOM taken off) with where and what to do (module
    rule); its own words if `data` is not given or the error is not one of its two syntax errors."""
    text = str(exc)
    malformed = re.fullmatch(r"JSON is malformed: (.*?)(?: \(byte (\d+)\))?", text, re.S)
    at_end = malformed is not None and malformed[2] is not None and data is not None and int(malformed[2]) >= len(data)
    if data is not None and (text == "Input data was truncated" or at_end):  # cut: its end is the place (`1.`)
        line = data.count(b"\n") + (0 if data.endswith(b"\n") else 1)
        return (f"cut short: it ends inside its JSON at line {line} (byte {len(data)}, its end): a copy or a save "
                "that did not finish? put back a whole copy")
    if malformed is None:
        return text
    if data is None or malformed[2] is None:
        return f"not valid JSON: {malformed[1]}"
    line, column = _line_column(data, int(malformed[2]))
    return f"not valid JSON at line {line}, column {column} (byte {malformed[2]}): {malformed[1]}: correct it there"


def toml_words(exc: Exception, text: str) -> str:
    """tomllib's TOMLDecodeError for `text` with where and what to do (module rule): its "(at end of
    document)" is the line the file ends on, a cut or an unclosed quote or bracket."""
    said = str(exc)
    if said.endswith("(at end of document)"):
        lines = text.count("\n") + (0 if text.endswith("\n") else 1)
        return (f"{said.removesuffix(' (at end of document)')} at its end (line {lines}): cut short (a copy or a "
                "save that did not finish? put back a whole copy), or a quote or bracket left open")
    return f"{said}: correct it there" if re.search(r"\(at line \d+, column \d+\)$", said) else said


def in_words(exc: Exception, struct: type | None = None, data: bytes | None = None) -> str:
    """Why msgspec could not read a JSON file, in the file's words (module rule): "KEY: what is wrong",
    KEY the path as the file writes it (`cards[0][2]`, `learner.alpha`; none at the top). `struct`, the
    Struct the file is read as, names the keys a table takes for an unknown one (and the one it resembles);
    `data`, the text decoded (a BOM taken off), places a syntax error (`syntax_words`).
    What it does not know is said as msgspec says it."""
    text = str(exc)
    if not isinstance(exc, msgspec.ValidationError):
        return syntax_words(exc, data)
    what, where = _LOCATED.fullmatch(text).groups()
    where = (where or "").lstrip(".")
    said = what
    if kinds := re.fullmatch(r"Expected `([\w |]+)`, got `(\w+)`", what):
        wanted = [k for k in kinds[1].split(" | ") if k != "null"]
        if {"int", "float"} <= set(wanted):
            wanted.remove("int")  # "a number" covers both
        said = f"must be {' or '.join(type_name(k) for k in wanted)}, got {type_name(kinds[2])}"
    elif bound := re.fullmatch(r"Expected `(?:int|float)` (>=|<=|>|<) (\S+)", what):
        said = f"must be {_BOUND[bound[1]]} {bound[2]}"
    elif length := re.fullmatch(r"Expected `(array|str|object)` of (?:length (>=|<=) (\d+)|(at least |at most )?"
                                r"length (\d+)(?:, got (\d+))?)", what):
        item = {"array": "item", "str": "character", "object": "key"}[length[1]]
        bound = _BOUND[length[2]] if length[2] else (length[4] or "exactly ").strip()
        said = f"must hold {bound} {counted(int(length[3] or length[5]), item)}" + (
            f", holds {length[6]}" if length[6] else "")
    elif unknown := re.fullmatch(r"Object contains unknown field `(.+)`", what):
        said = _unknown_said(struct, where, unknown[1])
        every = _every_unknown(struct, data)  # all of them at once: one at a time, a rerun each, was a trial
        if len(every) > 1:
            shown = [f"{w}: {_unknown_said(struct, w, k)}" if w else _unknown_said(struct, w, k)
                     for w, k in every[:MAX_SAID]]
            return "; ".join(shown) + (f"; and {len(every) - MAX_SAID} more" if len(every) > MAX_SAID else "")
    elif missing := re.fullmatch(r"Object missing required field `(.+)`", what):
        said = f"needs the key `{missing[1]}`"
    elif enum := re.fullmatch(r"Invalid enum value (.+)", what):
        said = f"{enum[1]} is not one of the values it takes"
    return f"{where}: {said}" if where else said


MAX_SAID = 5  # unknown keys said by name on the one line; the rest counted ("and N more")


def _unknown_said(struct: type | None, where: str, key: str) -> str:
    """What is said of the key `key` that the table at `where` does not take: retired (with what replaced it),
    or unknown with the key it resembles (else the keys it takes)."""
    if (retired := retired_key(_struct_at(struct, where), key)) is not None:  # an older pairplay's file
        return retired
    keys = sorted(_keys_at(struct, where))
    near = nearest(key, keys)
    return f"no key `{key}` is known here" + (f" (did you mean `{near}`?)" if near
                                               else f"; the keys: {', '.join(keys)}" if keys else "")


def _every_unknown(struct: type | None, data: bytes | None) -> list[tuple[str, str]]:
    """(where, key) of every key of the JSON text `data` that the Struct read there does not take, in the
    file's order (msgspec stops at the first: a file with two retired keys was refused for one, then, rerun,
    for the next); [] if `data` is not JSON or no Struct is given."""
    if struct is None or data is None:
        return []
    try:
        value = json_decode(data)
    except msgspec.DecodeError:
        return []
    return unknown_keys(value, struct)


def unknown_keys(value: object, struct: type) -> list[tuple[str, str]]:
    """(where, key) of every key of `value` (a JSON or TOML file read as plain dicts and lists) that the Struct
    `struct` would refuse there, in the file's order; `where` is msgspec's path (`phase[0]`, `speech`, "" at the
    top). The files' checks name them all at once (msgspec stops at the first)."""
    found: list[tuple[str, str]] = []

    def walk(value: object, kind: object, where: str) -> None:
        kind = _struct_in(kind)
        origin, args = typing.get_origin(kind), typing.get_args(kind)
        if isinstance(kind, type) and issubclass(kind, msgspec.Struct) and isinstance(value, dict):
            fields = {f.encode_name: f.type for f in msgspec.structs.fields(kind)}
            for key, item in value.items():
                if key in fields:
                    walk(item, fields[key], f"{where}.{key}" if where else key)
                elif kind.__struct_config__.forbid_unknown_fields:
                    found.append((where, key))
        elif origin in (list, tuple) and args and isinstance(value, list):
            for n, item in enumerate(value):
                walk(item, args[0], f"{where}[{n}]")
        elif origin is dict and len(args) == 2 and isinstance(value, dict):
            for key, item in value.items():
                walk(item, args[1], f"{where}.{key}" if where else key)

    walk(value, struct, "")
    return found


def retired_key(struct: object, key: str) -> str | None:
    """What a file that still holds `key`, which `struct` (a Struct of a file kind) no longer takes, is told: that
    it was retired and what replaced it, from the Struct's `RETIRED` table (`ClassVar[dict[str, str]]`: key ->
    what does its work now; data, never code); None if `key` was never one of its keys. A retired key was refused
    as a typo, with a did-you-mean pointing at a key of another meaning (`iristk_subscriber_wait_s`: "did you mean
    `iristk_subscribe`?")."""
    table = getattr(struct, "RETIRED", None) if isinstance(struct, type) else None
    if not isinstance(table, dict) or key not in table:
        return None
    return f"the key `{key}` was retired (this pairplay no longer reads it): {table[key]}; remove it from the file"


def _keys_at(struct: type | None, where: str) -> set[str]:
    """The keys of the Struct that `where` (msgspec's path: `a.b[0].c`) leads to in `struct`; none if unknown."""
    kind = _struct_at(struct, where)
    if isinstance(kind, type) and issubclass(kind, msgspec.Struct):
        return {f.encode_name for f in msgspec.structs.fields(kind)}
    return set()


def _struct_at(struct: type | None, where: str) -> object:
    """The type that `where` (msgspec's path: `a.b[0].c`) leads to in `struct` (None if it leads nowhere known)."""
    kind: object = struct
    for token in re.findall(r"\[\d+\]|[^.\[\]]+", where):
        kind = _struct_in(kind)
        if token.startswith("["):
            args = [a for a in typing.get_args(kind) if a is not type(None)]
            kind = args[0] if args else None
        elif kind is not None and isinstance(kind, type) and issubclass(kind, msgspec.Struct):
            kind = next((f.type for f in msgspec.structs.fields(kind) if f.encode_name == token), None)
        else:
            return None
    return _struct_in(kind)


def _struct_in(kind: object) -> object:
    """`kind` with an Optional (a union with None) taken off."""
    union = typing.get_origin(kind) in (typing.Union, types.UnionType)
    args = [a for a in typing.get_args(kind) if a is not type(None)] if union else []
    return args[0] if len(args) == 1 else kind


class _Format(msgspec.Struct):
    """What a file says it is, read before the rest (its other keys ignored here): see JsonFileKind.decode."""

    format: str  # required: a kind's Struct has a default for it, so a file without it was accepted
    version: object = None  # any JSON here: a version that is no integer is worded by the whole decode


_format_decoder = JsonDecoder(_Format)


class JsonFileKind(Generic[T]):
    """encode/decode/write/read of one file kind: `struct` (a msgspec Struct type), the `error` it
    raises (InputError subclass), `what` names it in messages ("policy file")."""

    def __init__(self, struct: type[T], error: type[Exception], what: str, from_recording: str = ""):
        self.error, self.what = error, what
        self.from_recording = from_recording  # what makes one of a recording, said when given a recording
        self._encoder = msgspec.json.Encoder()
        self._decoder = JsonDecoder(struct)
        self._struct = struct
        # the format and version this pairplay writes: the Struct's defaults (its `format` and `version`)
        defaults = {f.name: f.default for f in msgspec.structs.fields(struct)}
        self.format, self.version = defaults["format"], defaults["version"]
        self.noun = what.removesuffix(" file").replace("-", "_")  # its functions: read_policy, write_user_model

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
            said = _format_decoder.decode(data)
        except msgspec.ValidationError as exc:
            if "missing required field `format`" in str(exc):
                raise self.error(f'{source}: no "format" field: not a {self.what}') from None
        except msgspec.DecodeError:
            pass  # malformed: said below, as before
        else:
            # what the file is, before its keys: the Struct refuses a key it does not declare, and a file of
            # another kind, or of a newer version (which may add keys), is refused for that, not for a key
            if said.format != self.format:
                raise self.error(f"{source}: not a pairplay {self.what} (format {said.format!r})")
            if type(said.version) is int and said.version > self.version:
                raise self.error(f"{source}: {self.what} version {said.version} is newer than this pairplay "
                                 f"(reads up to {self.version}); upgrade pairplay")
        try:
            return self._decoder.decode(data)
        except self.error as exc:
            raise self.error(f"{source}: {exc}") from None
        except (msgspec.ValidationError, msgspec.DecodeError, ValueError) as exc:
            said = in_words(exc, self._struct, data)
            if said.startswith("cut short") and self.from_recording:  # or made again, from its recording
                said += f", or make it again ({self.from_recording})"
            raise self.error(f"{source}: corrupt or not a {self.what}: {said}") from None

    def write(self, path, value: T, force: bool = False) -> None:
        """Write atomically (a crash never leaves half a file); an existing file is replaced only
        with `force` (OutputError otherwise; pairplay.outputs)."""
        from pairplay.outputs import write_bytes

        function = f"write_{self.noun}"
        path = path_argument(path, function)  # (write_policy(policy, path) wrote nothing and said pathlib's TypeError)
        instance_argument(value, self._struct, function, "value", f"a {self._struct.__name__}")
        write_bytes(path, self.encode(value), flag_argument(force, function, "force"))

    def read(self, path) -> T:
        """The checked value of the file at `path`; the kind's error if it cannot be read or used."""
        path = path_argument(path, f"read_{self.noun}")
        check_input(path, self.error)  # before opening: a pipe blocked its reader (pairplay/inputs.py)
        try:
            data = path.read_bytes()
        except IsADirectoryError:
            raise self.error(a_folder(path, self.what, "the path of one file")) from None
        except OSError as exc:
            raise self.error(f"{path}: cannot read: {exc.strerror}") from None
        return self.decode(data, str(path))
