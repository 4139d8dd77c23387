"""Re-publishing recorded events on the bus (`pairplay replay`).

Rule: the recorded bytes go out unchanged on their recorded key, in file
order; pacing follows the recorded log times divided by the speed (0: no
pacing). With `as_session`, each event is re-stamped into that session and
published on the matching key; nothing else changes.
"""

from __future__ import annotations

import threading
import time

import msgspec

from pairplay.replay.reader import RecordedEvent
from pairplay.schemas.events import encode_event
from pairplay.schemas.keys import event_key

from pairplay.services.bus import Bus


def republish(bus: Bus, events: list[RecordedEvent], speed: float, stop: threading.Event | None = None,
              as_session: str | None = None, clock=time.perf_counter, sleep=time.sleep) -> int:
    if not events:
        return 0
    start_wall, start_log = clock(), events[0].log_time_ns
    n = 0
    for r in events:
        if stop is not None and stop.is_set():
            break
        if speed > 0:
            due = start_wall + (r.log_time_ns - start_log) / 1e9 / speed
            wait = due - clock()
            if wait > 0:
                sleep(wait)
        if as_session:
            e = msgspec.structs.replace(r.event, session=as_session)
            bus.put(event_key(as_session, e.source, type(e).__name__), encode_event(e))
        else:
            bus.put(r.key, r.payload)
        n += 1
    return n
