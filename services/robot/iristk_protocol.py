"""The IrisTK broker's wire protocol, both directions, as IrisTK's own Java source has it.

Source (gabriel-skantze/IrisTK, read, not copied): core/src/iristk/system/Broker.java,
BrokerClient.java, core/src/iristk/util/NameFilter.java, ParsedInputStream.java,
Record.java, Event.java; docs/robot.md cites the lines.

Rule, reading (what the broker writes to a client, Broker.java 132, 190-191, 233):
exactly three kinds of line, each ending in "\\n":
  `SUBSCRIBE <filter>`   the union of the other clients' filters (NONE is "")
  `CONNECTED`            once, after CONNECT
  `EVENT <name> <n>`     followed by exactly n bytes: the sender's JSON plus one
                         "\\n" the broker adds and counts (n = length + 1)
<n> is what Java writes for an int: ASCII digits, no sign, no leading zero. Any
other byte sequence is reported (BadFrame, with the reason) and, where the
stream can still be followed, skipped; where it cannot (an EVENT header we
cannot read, a count over MAX_EVENT_BYTES: the byte count of what follows is
unknown) the frame is marked `fatal` and the connection is re-made, so no
payload is ever read as protocol lines. A `CLOSE` line (IrisTK's broker never
writes one; a client writes it to leave, Broker.java 264) is honoured as the end
of the connection.

Rule, writing (as BrokerClient.send, BrokerClient.java 124-129): `EVENT <name> <n>\\n`
followed by the JSON, n its UTF-8 byte count, nothing after it. Events carry
"class": "iristk.system.Event" (without it Record.fromJSON makes a plain Record
and BrokerClient drops it, BrokerClient.java 91-96, Record.java 656-666), never a
JSON null (minimal-json's asString() throws on it inside Record.parseJsonValue,
Record.java 718-719, and BrokerClient drops the event, line 103), and locations
as "class": "iristk.situated.Location" (the class that exists in IrisTK,
core/src/iristk/situated/Location.java; SystemAgentFlow casts an
action.attend location to it). `event_time` is free text to IrisTK (Event.java
86-94: a String, never parsed); we write "yyyy-MM-dd HH:mm:ss.SSS" like
IrisSystem.getTimestamp (java.sql.Timestamp).

NameFilter (NameFilter.java): a pattern may contain only `A-Za-z0-9_!.*;` and
space (line 77; anything else the broker refuses, Broker.java 272-277). Items are
separated by `;` (with optional spaces), an item is a space-separated list of
patterns, `!` marks an excluding one; a name passes an item if the *last*
pattern of the item that matches it is an including one (or, when nothing
matches, if every pattern is excluding); a name passes the filter if it passes
some item (lines 47-69, 119-150). `*` is `[^.]*`, `**` is `.*` (Java's `.`:
any character but a line terminator), everything else literal; whole-name match.
"""

from __future__ import annotations

import datetime as dt
import json
import re
from dataclasses import dataclass

from pairplay.schemas.robot_url import DEFAULT_PORTS
from pairplay.schemas.robot import check_name_filter
from pairplay.schemas.nesting import json_loads

EVENT_CLASS = "iristk.system.Event"
LOCATION_CLASS = "iristk.situated.Location"
DEFAULT_PORT = DEFAULT_PORTS["iristk"]
DEFAULT_TICKET = "furhat"
MAX_EVENT_BYTES = 1 << 20  # a count above this is a corrupt stream, not an event
MAX_LINE_BYTES = 1 << 16

_HEADER = re.compile(rb"EVENT ([^ \n\r]+) ([1-9][0-9]{0,8})")  # Broker.java 190: "EVENT " + name + " " + int


def event_time(time_ns: int) -> str:
    """Local time, "yyyy-MM-dd HH:mm:ss.SSS" (IrisTK accepts any string here)."""
    moment = dt.datetime.fromtimestamp(time_ns / 1e9)
    return moment.strftime("%Y-%m-%d %H:%M:%S.") + f"{moment.microsecond // 1000:03d}"


def without_nulls(value):
    """A copy of a JSON value with every None field dropped (the Java side rejects nulls)."""
    if isinstance(value, dict):
        return {k: without_nulls(v) for k, v in value.items() if v is not None}
    if isinstance(value, list):
        return [without_nulls(v) for v in value if v is not None]
    return value


def make_event(event_name: str, event_id: str, sender: str, time_ns: int, **fields) -> dict:
    event = {"class": EVENT_CLASS, "event_name": event_name, "event_id": event_id,
             "event_sender": sender, "event_time": event_time(time_ns)}
    event.update(fields)
    return without_nulls(event)


def event_frame(event: dict) -> bytes:
    """`EVENT <name> <n>\\n` + JSON, n its byte count (as BrokerClient.send writes it)."""
    body = json.dumps(event, separators=(",", ":"), ensure_ascii=False).encode()
    return f"EVENT {event['event_name']} {len(body)}\n".encode() + body


@dataclass(frozen=True)
class Line:
    text: str


@dataclass(frozen=True)
class EventFrame:
    name: str
    payload: bytes  # the JSON, the broker's trailing newline removed


@dataclass(frozen=True)
class BadFrame:
    reason: str
    excerpt: bytes
    fatal: bool = False  # the stream cannot be followed past this: re-make the connection


Frame = Line | EventFrame | BadFrame


class FrameReader:
    """Incremental parser: feed bytes as they arrive, get complete frames back.

    Never raises on any input; after a fatal BadFrame it returns nothing more
    (the caller re-makes the connection).
    """

    def __init__(self) -> None:
        self._buffer = bytearray()
        self._pending: tuple[bytes, int] | None = None  # an EVENT header waiting for its bytes
        self.broken = False

    def feed(self, data: bytes) -> list[Frame]:
        if self.broken:
            return []
        self._buffer += data
        frames: list[Frame] = []
        while not self.broken:
            if self._pending is not None:
                name, n = self._pending
                if len(self._buffer) < n:
                    break
                payload = bytes(self._buffer[:n])
                del self._buffer[:n]
                self._pending = None
                frames.append(self._event(name, payload))
                continue
            end = self._buffer.find(b"\n")
            if end < 0:
                if len(self._buffer) > MAX_LINE_BYTES:
                    frames.append(self._fatal(f"line longer than {MAX_LINE_BYTES} bytes without a newline",
                                              bytes(self._buffer[:80])))
                break
            raw = bytes(self._buffer[:end])
            del self._buffer[:end + 1]
            frame = self._line(raw)
            if frame is not None:
                frames.append(frame)
        return frames

    def _fatal(self, reason: str, excerpt: bytes) -> BadFrame:
        self.broken = True
        self._buffer.clear()
        return BadFrame(reason, excerpt, fatal=True)

    @staticmethod
    def _event(name: bytes, payload: bytes) -> Frame:
        try:
            text = name.decode("utf-8")
        except UnicodeDecodeError:
            return BadFrame("EVENT name is not UTF-8 (its bytes were skipped)", name[:80])
        if not payload.endswith(b"\n"):
            return BadFrame(f"EVENT {text}: payload does not end with the newline the broker adds",
                            payload[:80])
        return EventFrame(text, payload[:-1])

    def _line(self, raw: bytes) -> Frame | None:
        """A line as a frame; None for an EVENT header (its payload is read next)."""
        if raw.startswith(b"EVENT"):
            match = _HEADER.fullmatch(raw)
            if match is None:
                return self._fatal("EVENT header is not 'EVENT <name> <n>' with n in ASCII digits"
                                   " (what the broker writes); its byte count is unknown", raw[:80])
            n = int(match.group(2))
            if n > MAX_EVENT_BYTES:
                return self._fatal(f"EVENT byte count {n} exceeds {MAX_EVENT_BYTES}", raw[:80])
            self._pending = (match.group(1), n)
            return None
        if not raw:
            return BadFrame("empty line (the broker never writes one)", b"")
        try:
            text = raw.decode("utf-8")
        except UnicodeDecodeError:
            return BadFrame("line is not UTF-8", raw[:80])
        return Line(text)


def decode_event(frame: EventFrame) -> dict:
    """The event object of a frame; ValueError with the reason if it is not one."""
    try:
        event = json_loads(frame.payload)
    except (UnicodeDecodeError, json.JSONDecodeError, RecursionError) as exc:
        raise ValueError(f"EVENT {frame.name}: payload is not JSON ({exc})") from None
    if not isinstance(event, dict):
        raise ValueError(f"EVENT {frame.name}: payload is not a JSON object")
    return event


def subscribe_filter(line: str) -> str | None:
    """The filter of a broker `SUBSCRIBE` line (BrokerClient.java 108-114); None if not one."""
    if line.rstrip(" ") == "SUBSCRIBE":
        return ""
    if line.startswith("SUBSCRIBE "):
        return line[len("SUBSCRIBE "):].strip(" ")
    return None


class NameFilter:
    """IrisTK's NameFilter (see the module rule); ValueError for a pattern IrisTK refuses."""

    def __init__(self, spec: str) -> None:
        check_name_filter(spec)
        self.spec = spec
        self._items: list[tuple[list[tuple[re.Pattern[str], bool]], bool]] = []
        for item in re.split(r" *; *", spec.strip(" ")):
            parts = item.strip(" ").split()
            if not parts:
                continue
            patterns = [(_compile(p[1:] if p.startswith("!") else p), not p.startswith("!")) for p in parts]
            self._items.append((patterns, all(not include for _, include in patterns)))

    def matches(self, name: str) -> bool:
        for patterns, all_exclude in self._items:
            accepts = all_exclude
            for pattern, include in patterns:
                if pattern.fullmatch(name):
                    accepts = include  # the last matching pattern decides
            if accepts:
                return True
        return False

    def __repr__(self) -> str:
        return f"NameFilter({self.spec!r})"


def _compile(term: str) -> re.Pattern[str]:
    pieces = re.split(r"(\*\*|\*)", term)
    # Java's "." stops at line terminators; "[^.]" does not (NameFilter.java 133-137).
    regex = "".join("[^\n\r\u0085\u2028\u2029]*" if p == "**" else "[^.]*" if p == "*" else re.escape(p)
                    for p in pieces)
    return re.compile(regex, re.DOTALL)
