"""The IrisTK broker's wire protocol (thesis appendix D), both directions.

Rule: the connection carries text lines ending in "\\n" and event frames
`EVENT <name> <n>\\n` followed by exactly n bytes of JSON. The broker's n counts a
newline written after the JSON, so we write JSON + "\\n" and count it; when we
read, we take exactly n bytes and strip one trailing newline. An empty line is
skipped, so a peer whose n leaves the newline out is read correctly too.
Anything else is reported as a bad frame with the reason and the connection goes
on: the framing is line based, so one bad line costs that line only.

Events for the Java side always carry "class": "iristk.system.Event" (it drops
events without one), never a JSON null (omit the field instead), and
`event_time` as "yyyy-MM-dd HH:mm:ss.SSS" (local time, as IrisTK writes it).

NameFilter (iristk.util.NameFilter, as this project reads it): event names are
dot-separated; `*` matches within one segment, `**` any run of characters
including dots; alternatives are separated by `;` (whitespace is taken as a
separator too, to be lenient with a broker that lists them so); a term
starting with `!` excludes. A name passes if it matches no excluding term and some including term, or
there are only excluding terms; an empty filter passes nothing (the broker's
SUBSCRIBE with no subscribers).
"""

from __future__ import annotations

import datetime as dt
import json
import re
from dataclasses import dataclass

EVENT_CLASS = "iristk.system.Event"
LOCATION_CLASS = "iristk.util.Location"
DEFAULT_PORT = 1932
DEFAULT_TICKET = "furhat"
MAX_EVENT_BYTES = 1 << 20  # a count above this is a corrupt header, not an event
MAX_LINE_BYTES = 1 << 16


def event_time(time_ns: int) -> str:
    """IrisTK's timestamp: local time, "yyyy-MM-dd HH:mm:ss.SSS"."""
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
    """`EVENT <name> <n>\\n` + JSON + "\\n", n counting that newline."""
    body = json.dumps(event, separators=(",", ":"), ensure_ascii=False).encode() + b"\n"
    return f"EVENT {event['event_name']} {len(body)}\n".encode() + body


@dataclass(frozen=True)
class Line:
    text: str


@dataclass(frozen=True)
class EventFrame:
    name: str
    payload: bytes  # the JSON, trailing newline removed


@dataclass(frozen=True)
class BadFrame:
    reason: str
    excerpt: bytes


Frame = Line | EventFrame | BadFrame


class FrameReader:
    """Incremental parser: feed bytes as they arrive, get complete frames back."""

    def __init__(self) -> None:
        self._buffer = bytearray()
        self._pending: tuple[str, int] | None = None  # an EVENT header waiting for its bytes

    def feed(self, data: bytes) -> list[Frame]:
        self._buffer += data
        frames: list[Frame] = []
        while True:
            if self._pending is not None:
                name, n = self._pending
                if len(self._buffer) < n:
                    break
                payload = bytes(self._buffer[:n])
                del self._buffer[:n]
                self._pending = None
                frames.append(EventFrame(name, payload.removesuffix(b"\n").removesuffix(b"\r")))
                continue
            end = self._buffer.find(b"\n")
            if end < 0:
                if len(self._buffer) > MAX_LINE_BYTES:
                    frames.append(BadFrame("line longer than 64 KiB without a newline", bytes(self._buffer[:80])))
                    self._buffer.clear()
                break
            raw = bytes(self._buffer[:end]).removesuffix(b"\r")
            del self._buffer[:end + 1]
            frame = self._line(raw) if raw else None
            if frame is not None:
                frames.append(frame)
        return frames

    def _line(self, raw: bytes) -> Frame | None:
        """A line as a frame; None for an EVENT header (its payload is read next)."""
        try:
            text = raw.decode("utf-8")
        except UnicodeDecodeError:
            return BadFrame("line is not UTF-8", raw[:80])
        if not text.startswith("EVENT ") and text != "EVENT":
            return Line(text)
        parts = text.split(" ")
        if len(parts) != 3 or not parts[1] or not parts[2].isdigit():
            return BadFrame("EVENT header is not 'EVENT <name> <nbytes>'", raw[:80])
        n = int(parts[2])
        if n > MAX_EVENT_BYTES:
            return BadFrame(f"EVENT byte count {n} exceeds {MAX_EVENT_BYTES}", raw[:80])
        self._pending = (parts[1], n)
        return None


def decode_event(frame: EventFrame) -> dict:
    """The event object of a frame; ValueError with the reason if it is not one."""
    try:
        event = json.loads(frame.payload)
    except (UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise ValueError(f"EVENT {frame.name}: payload is not JSON ({exc})") from None
    if not isinstance(event, dict):
        raise ValueError(f"EVENT {frame.name}: payload is not a JSON object")
    return event


class NameFilter:
    """IrisTK event-name filter: `*`, `**`, `!` and `;` (see the module rule)."""

    def __init__(self, spec: str) -> None:
        self.spec = spec
        terms = [t for t in re.split(r"[;\s]+", spec) if t]
        self._include = [_compile(t) for t in terms if not t.startswith("!")]
        self._exclude = [_compile(t[1:]) for t in terms if t.startswith("!")]

    def matches(self, name: str) -> bool:
        if not self._include and not self._exclude:
            return False
        if any(p.fullmatch(name) for p in self._exclude):
            return False
        return not self._include or any(p.fullmatch(name) for p in self._include)

    def __repr__(self) -> str:
        return f"NameFilter({self.spec!r})"


def _compile(term: str) -> re.Pattern[str]:
    pieces = re.split(r"(\*\*|\*)", term)
    regex = "".join(".*" if p == "**" else "[^.]*" if p == "*" else re.escape(p) for p in pieces)
    return re.compile(regex)
