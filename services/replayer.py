"""Re-publishing recorded events on the bus (`pairplay replay`).

Rule: the recorded bytes go out unchanged on their recorded key, in file
order but for the session's end: its last SessionEnded goes out after the events filed
after it (`end_last`: the robot's late RobotActed, the learner's last reward), at their
time. A recorder closes on the SessionEnded once no source of the session is on the bus
(a replay's never are), a live view once nothing more came for its grace: in file order
a recorder shed the robot's last 5 RobotActed, and a view missed one and saved the rest
as whole (trial33 L). Pacing follows the recorded log times divided by the speed (0: no
pacing). With `as_session`, each event is re-stamped into that session and
published on the matching key, its SessionStarted's config naming that session too (a copy
recorded under it named the original in its config: its verify recomputed the game's first
events as beyond the recording, FAIL, trial33 L); nothing else changes. Every wait (pacing, a
full outbox) ends when `stop` is set: a signal never waits for the next
recorded event (a paced replay slept through the gap, 30 s and more).
"""

from __future__ import annotations

import threading
import time

import msgspec

from pairplay.replay.reader import RecordedEvent
from pairplay.schemas.events import SessionStarted, encode_event
from pairplay.schemas.keys import event_key

from pairplay.services.bus import Outbox


def end_last(events: list[RecordedEvent]) -> list[RecordedEvent]:
    """`events` with their last SessionEnded moved after every other event (see the module rule); an earlier
    one (a forged end the recording kept) stays where it is."""
    ends = [i for i, r in enumerate(events) if type(r.event).__name__ == "SessionEnded"]
    if not ends or ends[-1] == len(events) - 1:
        return events
    i = ends[-1]
    return events[:i] + events[i + 1:] + [events[i]]


def republish(bus, events: list[RecordedEvent], speed: float, stop: threading.Event | None = None,
              as_session: str | None = None, clock=time.perf_counter, sleep=None) -> int:
    """Publish `events` (see module rule) through `bus.put`, or an Outbox's `send_within`; how
    many were handed over. `sleep(s)` defaults to `stop.wait` (interrupted by the stop)."""
    if not events:
        return 0
    stop = stop if stop is not None else threading.Event()
    sleep = sleep or stop.wait
    put = (lambda key, payload: bus.send_within(key, payload, stop)) if isinstance(bus, Outbox) else \
        (lambda key, payload: bus.put(key, payload) or True)
    start_wall, start_log = clock(), events[0].log_time_ns
    n = 0
    for r in end_last(events):
        if stop.is_set():
            break
        if speed > 0:
            due = start_wall + (r.log_time_ns - start_log) / 1e9 / speed
            wait = due - clock()
            if wait > 0:
                sleep(wait)
                if stop.is_set():
                    break
        if as_session:
            e = msgspec.structs.replace(r.event, session=as_session)
            if isinstance(e, SessionStarted):  # its config names the session too (verify runs the config's)
                e = msgspec.structs.replace(e, config=msgspec.structs.replace(e.config, session=as_session))
            sent = put(event_key(as_session, e.source, type(e).__name__), encode_event(e))
        else:
            sent = put(r.key, r.payload)
        n += bool(sent)
    return n
