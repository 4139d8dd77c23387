"""The key space of the bus: `pairplay/<session>/<source>/<event tag>`.

Rule: every event is published on exactly one key built from its envelope and
tag, so a subscriber to `pairplay/<session>/**` sees the whole session and the
recorder keeps one MCAP channel per key. Session ids and source names are single
key chunks: no `/`, no zenoh wildcards or verbatim markers (`* $ # ?`), no `@`.
Requests that need an answer (the recorder's log, for a restarting service) use
queryables on `pairplay/<session>/_query/<service>/<name>`, and running services
hold liveliness tokens on `pairplay/<session>/_alive/<service>`: both outside
the event space.
"""

from __future__ import annotations

from typing import NamedTuple

ROOT = "pairplay"
QUERY_CHUNK = "_query"
ALIVE_CHUNK = "_alive"
_FORBIDDEN = set("/*$#?@ ")


class EventKey(NamedTuple):
    session: str
    source: str
    tag: str


def check_chunk(what: str, value: str) -> str:
    """Return `value` if it is a legal single key chunk, else raise ValueError."""
    if not value or _FORBIDDEN & set(value) or any(c.isspace() for c in value):  # a tab, a newline: spaces too
        raise ValueError(f"{what} {value!r} must be non-empty and free of / * $ # ? @ and spaces")
    return value


def event_key(session: str, source: str, tag: str) -> str:
    return f"{ROOT}/{check_chunk('session', session)}/{check_chunk('source', source)}/{tag}"


def session_keys(session: str) -> str:
    """Wildcard of everything published in one session."""
    return f"{ROOT}/{check_chunk('session', session)}/**"


def source_keys(session: str, source: str) -> str:
    """Wildcard of everything one source publishes in one session."""
    return f"{ROOT}/{check_chunk('session', session)}/{check_chunk('source', source)}/**"


def query_key(session: str, service: str, name: str) -> str:
    return f"{ROOT}/{check_chunk('session', session)}/{QUERY_CHUNK}/{service}/{name}"


def alive_key(session: str, service: str) -> str:
    """Liveliness token of a running service (`*` for all of a session's)."""
    return f"{ROOT}/{check_chunk('session', session)}/{ALIVE_CHUNK}/{service}"


def parse_event_key(key: str) -> EventKey:
    """Split an event key; ValueError if it is not `pairplay/<session>/<source>/<tag>`."""
    parts = str(key).split("/")
    if len(parts) != 4 or parts[0] != ROOT or parts[2] in (QUERY_CHUNK, ALIVE_CHUNK):
        raise ValueError(f"key {key!r} is not {ROOT}/<session>/<source>/<event>")
    return EventKey(parts[1], parts[2], parts[3])
