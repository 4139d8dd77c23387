"""A service on the bus: a Driver fed from a Zenoh subscription, in its own thread.

Rule: a Node subscribes to its session's keys (or, for a logic that copes with
any order between keys, just those of the events it reads) before anything else, declares
its liveliness token, then asks the recorder for the session's log so far. An
empty log is a fresh start (ServiceStarted, then the logic's first outputs);
a non-empty one is a restart: the Driver re-feeds it (node.py) and the service
publishes only what it still owes. Messages that arrived on the subscription
while the log was being read may repeat the log: they are skipped quietly.
One thread per Node handles its queue in arrival order; Zenoh's callback
threads only enqueue.
"""

from __future__ import annotations

import gc
import logging
import queue
import threading
import time
from typing import Callable

import msgspec

from pairplay import __version__
from pairplay.schemas.envelope import Event
from pairplay.schemas.events import ServiceStarted, decode_event, encode_event
from pairplay.schemas.keys import alive_key, event_key, query_key, session_keys

from pairplay.services.bus import Bus
from pairplay.services.node import Driver, Logic

log = logging.getLogger("pairplay.runner")
LOG_QUERY = "log"


def fetch_log(bus: Bus, session: str, timeout_s: float = 5.0) -> list[Event]:
    """The session's events the recorder holds, in its order ([] if no recorder answers)."""
    batches = []
    for payload in bus.query(query_key(session, "recorder", LOG_QUERY), timeout_s):
        try:
            index, items = msgspec.msgpack.decode(payload, type=tuple[int, list[tuple[str, bytes]]])
        except msgspec.DecodeError as err:
            log.warning("unreadable log batch from the recorder: %s", err)
            continue
        batches.append((index, items))
    events = []
    for _, items in sorted(batches):
        for _, data in items:
            events.append(decode_event(data))
    return events


class Node:
    def __init__(self, bus: Bus, logic: Logic, session: str, *, clock: Callable[[], int] = time.time_ns,
                 resume: bool = True, inline: bool = True):
        self.bus, self.logic, self.session = bus, logic, session
        self.driver = Driver(logic, session, clock)
        self.clock = clock
        self.resume = resume
        self.queue: queue.Queue = queue.Queue()
        self._overlap = 0
        self.resumed_events = 0
        self.thread: threading.Thread | None = None
        # inline: handle each message in Zenoh's callback (under a lock), saving a thread
        # hand-off per message (pick -> suggestion latency); before the catch-up is done,
        # messages wait in the queue either way.
        self.inline = inline
        self._lock = threading.RLock()  # Zenoh may deliver our own publications back on this thread
        self._live = False
        self._wake = threading.Event()

    def _on_message(self, key: str, payload: bytes) -> None:
        if not self.inline:
            self.queue.put((key, payload))
            return
        with self._lock:  # queued or handled under the lock: none can slip between the catch-up and going live
            if not self._live:
                self.queue.put((key, payload))
                return
            self.publish(self.driver.receive(key, payload))
            if self.logic.done:
                self._wake.set()

    def stamp(self, events: list[Event]) -> list[Event]:
        """Number and time this service's own new events (an input a web page gave, say);
        the caller publishes them (`publish`), outside any bus callback."""
        with self._lock:
            return self.driver._stamp(events)

    def refuse(self, reason: str, key: str, source: str = "", seq: int = 0, payload: bytes = b"") -> list[Event]:
        """A MessageRejected for an input that did not come over the bus (a WebSocket message)."""
        with self._lock:
            return self.driver.reject(reason, key, source, seq, payload)

    def publish(self, events: list[Event]) -> None:
        for e in events:
            self.bus.put(event_key(self.session, e.source, type(e).__name__), encode_event(e))

    def start(self, wait_for: tuple[str, ...] = (), wait_timeout_s: float = 30.0) -> None:
        """Subscribe, announce, catch up; with `wait_for`, first wait for those services' tokens."""
        if getattr(self.logic, "by_tag", False):
            # only the tags the logic reads: Zenoh then does not even send the others here
            for tag in sorted(self.logic.consumes):
                self.bus.subscribe(f"{session_keys(self.session)[:-2]}*/{tag}", self._on_message)
        else:
            self.bus.subscribe(session_keys(self.session), self._on_message)
        self.bus.alive(alive_key(self.session, self.logic.name))
        if wait_for:
            self.wait_for(wait_for, wait_timeout_s)
        recorded = fetch_log(self.bus, self.session) if self.resume else []
        if not any(type(e).__name__ == "SessionStarted" for e in recorded):
            recorded = []  # the session has not started: nothing to catch up with
        self._overlap = self.queue.qsize()
        announce = ServiceStarted(service=self.logic.name, version=__version__, resumed_events=len(recorded))
        if recorded:
            log.info("%s resumes from %d recorded events", self.logic.name, len(recorded))
            self.resumed_events = len(recorded)
            self.publish(self.driver.resume(recorded, announce=announce))
            for m in self.driver.mismatches:
                log.error("%s: the log and the recomputation disagree: %s", self.logic.name, m)
        else:
            self.publish(self.driver._stamp([announce]) + self.driver.start())
        if self.inline:
            with self._lock:
                while self.step(0):
                    pass
                self._live = True
        # Everything built so far (modules, the log folded at start) lives for the
        # whole session: keep it out of the collector's scans, which otherwise
        # show up as the slowest suggestions (pick -> suggestion p99).
        gc.freeze()

    def wait_for(self, services: tuple[str, ...], timeout_s: float) -> None:
        deadline = time.monotonic() + timeout_s
        wanted = {alive_key(self.session, s) for s in services}
        while True:
            alive = self.bus.alive_now(alive_key(self.session, "*"), timeout_s=0.5)
            if wanted <= alive:
                return
            if time.monotonic() > deadline:
                missing = sorted(k.rsplit("/", 1)[1] for k in wanted - alive)
                raise TimeoutError(f"{self.logic.name}: no {', '.join(missing)} on the bus after {timeout_s:.0f} s")
            time.sleep(0.05)

    def step(self, timeout_s: float = 0.1) -> bool:
        """Handle one message (False if none came)."""
        try:
            key, payload = self.queue.get(timeout=timeout_s) if timeout_s > 0 else self.queue.get_nowait()
        except queue.Empty:
            return False
        overlap = self._overlap > 0
        if overlap:
            self._overlap -= 1
        self.publish(self.driver.receive(key, payload, overlap=overlap))
        return True

    def run(self, stop: threading.Event) -> None:
        while not stop.is_set() and not self.logic.done:
            if self.inline and self._live:
                self._wake.wait(0.1)
            else:
                self.step()

    def run_in_thread(self, stop: threading.Event) -> threading.Thread:
        self.thread = threading.Thread(target=self.run, args=(stop,), name=f"pairplay-{self.logic.name}", daemon=True)
        self.thread.start()
        return self.thread
