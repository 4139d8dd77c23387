"""The envelope every bus event carries, and the base class of all events.

Rule: an event is a frozen msgspec Struct, past tense, with an explicit string
tag in the field "type" (the class name; tags never change). Its first four
fields are the envelope: the session id, the source (the service or device that
published it), the source's sequence number (1, 2, 3, ... per source and
session, strictly increasing) and the publisher's wall time in ns. The envelope
fields default to empty so that code can build an event first and stamp it when
it publishes (`stamped`). Schema evolution: new fields get defaults and go at
the end of their class; never rename or retag.

Unknown fields are ignored on decode (no `forbid_unknown_fields`), so an old
reader can read a newer recording.

Times in ns (`time_ns` and RobotActed's `*_ns`) are `Nanos`: a Python int that
the JSON encoding writes as the MCAP/Foxglove time object {"sec": S, "nsec": N}
(N < 10**9), because JSON numbers above 2**53 are rounded by JavaScript readers
(by up to 128 ns for today's epoch times). The decoder reads both that object
and a plain integer (recordings of pairplay <= 0.2), so old files stay readable.
Encode and decode events only with `events.encode_event` / `decode_event`
(they carry the hooks); the JSON Schema of a Nanos field accepts both forms.
"""

from __future__ import annotations

from typing import Annotated

import msgspec

TAG_FIELD = "type"
NS_PER_S = 1_000_000_000
MAX_NS = 2**63 - 1  # fits MCAP's unsigned 64-bit times (and every int64 reader)
# Ranges, checked on decode (schemas/trust.py): a sequence number stays exact in a
# JavaScript reader (2^53); a time lies in 0..MAX_NS (a time_ns of -1 passed every check
# once, then killed the recorder inside the MCAP writer).
SEQ_MAX = 2**53
Seq = Annotated[int, msgspec.Meta(ge=0, le=SEQ_MAX)]


class Nanos(int):
    """A time or duration in ns; JSON: {"sec": S, "nsec": N} (the MCAP/Foxglove time), or an int from old files."""

    __slots__ = ()

    def __repr__(self) -> str:
        return int.__repr__(self)


def nanos_to_json(value: "Nanos") -> dict[str, int]:
    sec, nsec = divmod(int(value), NS_PER_S)
    return {"sec": sec, "nsec": nsec}


def nanos_from_json(obj) -> Nanos:
    """A Nanos from its JSON: the {sec, nsec} object or a plain integer; TypeError/ValueError otherwise."""
    if type(obj) is dict and len(obj) == 2:  # the common case first (every event holds a few; rebuild speed)
        sec, nsec = obj.get("sec"), obj.get("nsec")
        if type(sec) is int and type(nsec) is int and 0 <= nsec < NS_PER_S and 0 <= sec * NS_PER_S + nsec <= MAX_NS:
            return Nanos(sec * NS_PER_S + nsec)
    if isinstance(obj, int) and not isinstance(obj, bool):
        if not 0 <= obj <= MAX_NS:
            raise ValueError(f"a time of {obj} ns is outside 0..{MAX_NS}")
        return Nanos(obj)
    if isinstance(obj, dict) and set(obj) == {"sec", "nsec"} and all(
            isinstance(obj[k], int) and not isinstance(obj[k], bool) for k in obj) and 0 <= obj["nsec"] < NS_PER_S:
        value = obj["sec"] * NS_PER_S + obj["nsec"]
        if not 0 <= value <= MAX_NS:
            raise ValueError(f"a time of {obj['sec']} s is outside 0..{MAX_NS} ns")
        return Nanos(value)
    raise ValueError(f"a time is {{sec, nsec}} (nsec 0..{NS_PER_S - 1}) or an integer of ns, not {obj!r}")


def enc_hook(obj):
    if isinstance(obj, Nanos):
        return nanos_to_json(obj)
    raise NotImplementedError(f"cannot encode {type(obj).__name__}")


def dec_hook(tp, obj):
    if tp is Nanos:
        if type(obj) is dict and len(obj) == 2:  # nanos_from_json's common case, inlined (rebuild speed)
            sec, nsec = obj.get("sec"), obj.get("nsec")
            if type(sec) is int and type(nsec) is int and 0 <= nsec < NS_PER_S and 0 <= sec * NS_PER_S + nsec <= MAX_NS:
                return Nanos(sec * NS_PER_S + nsec)
        return nanos_from_json(obj)
    raise NotImplementedError(f"cannot decode {tp}")


NANOS_SCHEMA = {"anyOf": [
    {"title": "time", "type": "object", "properties": {"sec": {"type": "integer"},
                                                        "nsec": {"type": "integer", "minimum": 0,
                                                                 "maximum": NS_PER_S - 1}},
     "required": ["sec", "nsec"], "additionalProperties": False},
    {"type": "integer", "description": "ns (recordings of pairplay <= 0.2)"}]}


def schema_hook(tp):
    if tp is Nanos:
        return dict(NANOS_SCHEMA)
    raise NotImplementedError(f"no JSON Schema for {tp}")


class Event(msgspec.Struct, frozen=True, kw_only=True, tag_field=TAG_FIELD):
    """Base of every event: the envelope. Subclasses add `tag="TheirName"`."""

    session: str = ""
    source: str = ""
    seq: Seq = 0
    time_ns: Nanos = 0

    def __post_init__(self) -> None:
        # a time given as a plain int (a clock's value) is still a time: JSON {sec, nsec}
        if type(self.time_ns) is int and self.time_ns:
            msgspec.structs.force_setattr(self, "time_ns", Nanos(self.time_ns))


def stamped(event: Event, *, session: str, source: str, seq: int, time_ns: int) -> Event:
    """A copy of `event` with its envelope filled in (events are frozen)."""
    return msgspec.structs.replace(event, session=session, source=source, seq=seq, time_ns=Nanos(time_ns))


def tag_of(event_type: type[Event]) -> str:
    """The string tag of an event class."""
    return event_type.__struct_config__.tag
