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
"""

from __future__ import annotations

from typing import Annotated

import msgspec

TAG_FIELD = "type"
# Ranges, checked on decode (schemas/trust.py): a sequence number stays exact in a
# JavaScript reader (2^53), a time fits MCAP's unsigned 64-bit log time (a time_ns
# of -1 passed every check once, then killed the recorder inside the MCAP writer).
Seq = Annotated[int, msgspec.Meta(ge=0, le=2**53)]
TimeNs = Annotated[int, msgspec.Meta(ge=0, le=2**63 - 1)]


class Event(msgspec.Struct, frozen=True, kw_only=True, tag_field=TAG_FIELD):
    """Base of every event: the envelope. Subclasses add `tag="TheirName"`."""

    session: str = ""
    source: str = ""
    seq: Seq = 0
    time_ns: TimeNs = 0


def stamped(event: Event, *, session: str, source: str, seq: int, time_ns: int) -> Event:
    """A copy of `event` with its envelope filled in (events are frozen)."""
    return msgspec.structs.replace(event, session=session, source=source, seq=seq, time_ns=time_ns)


def tag_of(event_type: type[Event]) -> str:
    """The string tag of an event class."""
    return event_type.__struct_config__.tag
