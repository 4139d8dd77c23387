"""Checking an event's JSON without building the event: every rule of `decode_event`, in C.

Rule: `check_event(payload)` accepts exactly the payloads `events.decode_event`
accepts, and returns a light twin of the event (`CHECKED_BY_TAG[tag]`: the same
tag, field names, types, ranges and defaults) instead of the event itself. The
twin differs in one thing only: a `Nanos` field (the envelope's `time_ns`,
RobotActed's `*_ns`, RecordingGap's times) is checked by msgspec as
`CheckedTime`, an integer 0..MAX_NS or the {"sec", "nsec"} object with the same
ranges, instead of by the Python `dec_hook` that builds a `Nanos`: that hook,
and Event.__post_init__, were two thirds of a recorder's decode (4.3 us of a
CardPicked against 1.1 us for the twin, measured 2026-11-30). Everything else
(nested structs such as SessionConfig, with their own checks) is the same type.

Why a separate set of types: a reader (the fold, a service) needs the event;
the recorder only needs to know that the bytes it writes are an event every
reader will decode, and the envelope (session, source, seq) to check its order
(services/guard.py). A twin is never looser than its event (tests/test_checked.py
compares both on hostile payloads); where it is stricter on some odd input,
`check_event` asks `decode_event` before refusing, so the event's own decoder
always has the last word and its error message is the one recorded.
"""

from __future__ import annotations

from typing import Annotated, Union

import msgspec

from .envelope import MAX_NS, NS_PER_S, TAG_FIELD, Nanos
from .events import EVENT_TYPES, decode_event
from .nesting import JsonDecoder

MAX_SEC, MAX_SEC_NSEC = divmod(MAX_NS, NS_PER_S)


class CheckedTimeObject(msgspec.Struct, frozen=True, forbid_unknown_fields=True):
    """The {"sec", "nsec"} form of a time (envelope.nanos_from_json): exactly these two keys,
    integers, nsec 0..10^9-1. `sec` stops one short of MAX_NS's second, the one range Meta
    cannot state exactly (sec == MAX_SEC is in range only up to MAX_SEC_NSEC): such a time (the
    year 2262) is left to `decode_event` (see rule) rather than paying a __post_init__ per event."""

    sec: Annotated[int, msgspec.Meta(ge=0, le=MAX_SEC - 1)]
    nsec: Annotated[int, msgspec.Meta(ge=0, le=NS_PER_S - 1)]


# a time as JSON: an integer of ns (recordings of pairplay <= 0.2) or the MCAP/Foxglove time object
CheckedTime = Union[Annotated[int, msgspec.Meta(ge=0, le=MAX_NS)], CheckedTimeObject]


def _twin(event_type: type) -> type:
    """The checked twin of one event class (see rule)."""
    config = event_type.__struct_config__
    fields = []
    for f in msgspec.structs.fields(event_type):
        if f.encode_name != f.name:
            raise TypeError(f"{event_type.__name__}.{f.name} is renamed: the twin does not support that")
        tp = CheckedTime if f.type is Nanos else f.type
        if f.default is not msgspec.NODEFAULT:
            fields.append((f.name, tp, f.default))
        elif f.default_factory is not msgspec.NODEFAULT:
            fields.append((f.name, tp, msgspec.field(default_factory=f.default_factory)))
        else:
            fields.append((f.name, tp))
    return msgspec.defstruct(event_type.__name__, fields, tag=config.tag, tag_field=TAG_FIELD, kw_only=True,
                             frozen=True, forbid_unknown_fields=config.forbid_unknown_fields,
                             module=__name__)


CHECKED_TYPES: tuple[type, ...] = tuple(_twin(t) for t in EVENT_TYPES)
CHECKED_BY_TAG: dict[str, type] = {t.__struct_config__.tag: t for t in CHECKED_TYPES}
_decoder = JsonDecoder(Union[CHECKED_TYPES])  # type: ignore[valid-type]


def check_event(payload: bytes):
    """The checked twin of the event in `payload` (attributes as the event's; a time is an int or a
    CheckedTimeObject). Raises msgspec.ValidationError / DecodeError exactly when
    `decode_event(payload)` does, with its message; returns the event itself in the (odd) case the
    twin refuses what the event's decoder takes."""
    try:
        return _decoder.decode(payload)
    except (msgspec.DecodeError, msgspec.ValidationError):
        return decode_event(payload)  # the event's decoder decides (and words the refusal)
