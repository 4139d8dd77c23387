"""Where the view's events come from: the live bus or a recording.

Rule: both sources yield `(event, None)` for an event to fold,
`(None, None)` at each poll that finds the live source caught up (nothing
waiting: a coalescing view may draw now), and `(None, note)` for something the view should say instead (a malformed bus
message, a gap in a source's sequence numbers, a corrupt or truncated
recording); nothing raises on bad content and nothing is published: the view
never changes a session.

Live: samples wait in Zenoh's own ring buffer (RingChannel) until the view's
thread takes them, so no Python runs on Zenoh's receive path and a slow view
never holds the session's BLOCK publishers back. If the view falls more than
`capacity` samples behind, the oldest are overwritten; the view notices the gap
in the senders' sequence numbers and says so (a view, unlike the recorder, may
lose frames; the recording is the truth). A SessionEnded ends the live view once nothing more
came for its grace and no source of the session but its recorder is on the bus (their
liveliness tokens), as the recorder closes: a live robot's last RobotActed comes up to
seconds after the end (the virtual robot's, 1.3 s after its previous one), and the view
saved the rest as whole without it (trial33 L). It ends it only while its
source publishes nothing after it but its shell's events: one the game goes on after was not
its end (forged on the bus: docs/bus.md "Forged starts and ends"), said as a note. A view that joins a running session
first asks the recorder for the log so far (the query restarting services
use; a read, it changes nothing), so it still shows the whole session.

Recording: read with replay's truncation-tolerant reader. `speed` 0 replays as
fast as the view can draw; otherwise the envelope times are followed, `speed`
times real time.
"""

from __future__ import annotations

import threading
import time
from pathlib import Path
from typing import Iterator

import msgspec
import zenoh

from pairplay.replay.forgery import AFTER_END
from pairplay.replay.reader import EventLog, events_of
from pairplay.schemas.events import decode_event
from pairplay.schemas.keys import alive_key, parse_event_key, session_keys

from pairplay.services.runner import fetch_log
from pairplay.numbers import counted

Item = tuple[object | None, str | None]


class Info(str):
    """A note that is news, not a loss (the catch-up from the recorder): logged at INFO, not WARNING."""


class SequenceGaps:
    """Notice missing events per (session, source) from the envelope's seq numbers, which start at 1: a
    source first seen above 1 lost its first events (a view attached to a replay already under way, with no
    recorder to catch up from, drew 2547 of 2552 events and said nothing). `missed` counts them all."""

    def __init__(self) -> None:
        self.last: dict[tuple[str, str], int] = {}
        self.missed = 0

    def check(self, event) -> str | None:
        key = (event.session, event.source)
        last = self.last.get(key)
        self.last[key] = max(event.seq, last or 0)
        if last is None and event.seq > 1:
            self.missed += event.seq - 1
            return (f"{event.seq - 1} event(s) from {event.source} missing before seq {event.seq}: published "
                    "before the view joined, and no recorder's log held them")
        if last is not None and event.seq > last + 1:
            self.missed += event.seq - last - 1
            return f"{event.seq - last - 1} event(s) from {event.source} missing before seq {event.seq}"
        return None


def recording_items(path: str | Path, *, speed: float = 0.0, session: str | None = None,
                    sleep=None, clock=time.monotonic, stop: threading.Event | None = None,
                    log: EventLog | None = None, events: list | None = None) -> Iterator[Item]:
    """Events of one session of a recording, paced by `speed` (0: as fast as possible). The pacing
    waits on `stop` (`sleep` defaults to `stop.wait`): a signal never waits for the next event.
    `log`: the recording read already (cli/view.py reads it to check it first): drawn as read, not read
    again (a file a `recover` or a recorder changes beside the view could differ, or fail, the second time);
    `events`: its events, if it was read keeping them alone (reader.events_of), else those of `log.events`. Read here,
    its events alone are kept (reader.events_of), not its records and their bytes."""
    stop = stop if stop is not None else threading.Event()
    sleep = sleep or stop.wait
    if log is None:
        log, events = events_of(path)
    elif events is None:
        events = [r.event for r in log.events]
    chosen = session
    t0_event = t0_wall = None
    for bad in log.bad:
        yield None, f"recording message on {bad.key or '?'} does not decode: {bad.reason}"
    for event in events:
        if chosen is None and event.session:
            chosen = event.session
        if event.session != chosen:
            continue
        if speed > 0 and event.time_ns:
            if t0_event is None:
                t0_event, t0_wall = event.time_ns, clock()
            wait = t0_wall + (event.time_ns - t0_event) / 1e9 / speed - clock()
            if wait > 0:
                sleep(wait)
        if stop.is_set():
            return
        yield event, None
    if log.missing:  # damaged, cut, recovered from a file that lost parts, undecodable: what it lost (reader.EventLog)
        yield None, f"recording not whole ({log.missing}); its intact parts are shown"
    elif log.loss_free:  # damaged where no event was: drawn whole, the damage noted in the view (and said in
        # view's saved line: cli/view.py; reader.EventLog.loss_free)
        yield None, Info(f"recording read whole: {log.loss_free}")


class LiveSource:
    """Subscribe to one session on the bus; the view's thread pulls from Zenoh's ring buffer."""

    def __init__(self, bus, session: str, *, capacity: int = 100_000, catch_up: bool = True,
                 stop: threading.Event | None = None):
        self.session, self.bus = session, bus
        self.gaps = SequenceGaps()
        self.ended = False
        self.ended_by = None  # the SessionEnded taken as the end: undone if its source goes on (issue "forge")
        # A RingChannel keeps the newest `capacity` samples inside Zenoh (no Python, no GIL on
        # the receive path) and never pushes back on the publishers; what it overwrites shows
        # up as a gap in the senders' sequence numbers.
        # Kept by the bus (Bus._keep): undeclared by its close before the channel goes, also when this
        # source's own close never runs (its catch-up below interrupted)
        self.subscriber = bus._keep(bus.session.declare_subscriber(session_keys(session),
                                                                   zenoh.handlers.RingChannel(capacity)))
        # Subscribed first, then the recorder's log so far: a view that joins late starts
        # from the whole session; live samples already in the log are skipped by their seq.
        self.backlog: list = []
        self.backlog_error = ""
        if catch_up:
            try:
                self.backlog = fetch_log(bus, session, timeout_s=5.0, stop=stop)
            except (msgspec.DecodeError, msgspec.ValidationError) as err:
                self.backlog_error = f"the recorder's log of {session} does not decode ({err}); showing live events only"

    def items(self, stop: threading.Event, *, poll_s: float = 0.002, grace_s: float = 0.5) -> Iterator[Item]:
        """Decoded events until `stop` is set, or the session has ended and nothing more
        arrived for `grace_s` (other services may still publish their last events)."""
        idle_since = None
        if self.backlog_error:
            yield None, self.backlog_error
        if self.backlog:
            yield None, Info(f"caught up from the recorder: {counted(len(self.backlog), 'event')} published before the view joined")
        for event in self.backlog:
            yield from self._accept(event)
        self.backlog = []
        try:
            while not stop.is_set():
                sample = self.subscriber.try_recv()
                if sample is None:
                    now = time.monotonic()
                    idle_since = idle_since or now
                    yield None, None  # caught up: a coalescing view may draw what it holds
                    if self.ended and now - idle_since >= grace_s:
                        if not self._sources_on_bus(stop):
                            return
                        idle_since = now  # (its late reports are the session's: see rule)
                    time.sleep(poll_s)
                    continue
                idle_since = None
                yield from self._decode(str(sample.key_expr), sample.payload.to_bytes())
        finally:
            self.close()

    def _sources_on_bus(self, stop: threading.Event) -> bool:
        """Whether a source of the session other than its recorder (which waits for them too) is on the bus."""
        alive = self.bus.alive_now(alive_key(self.session, "*"), timeout_s=0.3, stop=stop)
        return any(k != alive_key(self.session, "recorder") for k in alive)

    def close(self) -> None:
        try:
            self.subscriber.undeclare()
        except Exception:  # already gone with its session
            pass

    def _decode(self, key: str, payload: bytes) -> Iterator[Item]:
        try:
            parsed = parse_event_key(key)
            event = decode_event(payload)
        except (ValueError, msgspec.DecodeError, msgspec.ValidationError) as err:
            yield None, f"malformed message on {key}: {err} ({payload[:80]!r})"
            return
        if (event.session, event.source, type(event).__name__) != (parsed.session, parsed.source, parsed.tag):
            yield None, f"message on {key} says it is {type(event).__name__} from {event.source} in {event.session}"
            return
        yield from self._accept(event)

    def _accept(self, event) -> Iterator[Item]:
        if event.seq <= self.gaps.last.get((event.session, event.source), 0):
            return  # already shown (from the recorder's log), or a duplicate
        gap = self.gaps.check(event)
        if gap:
            yield None, gap
        tag = type(event).__name__
        end = self.ended_by
        if end is not None and event.source == end.source and tag not in AFTER_END:
            # the source goes on after "its" end: that end was not its (replay/forgery.py); follow on
            self.ended, self.ended_by = False, None
            yield None, (f"the SessionEnded seq {end.seq} claiming source {end.source!r} was not its end: its "
                         f"{tag} seq {event.seq} came after it (forged on the bus?); still following the session")
        if tag == "SessionEnded":
            self.ended, self.ended_by = True, event
        yield event, None
