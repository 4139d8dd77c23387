"""A service on the bus: a Driver fed from a Zenoh subscription, in its own thread.

Rule: a Node subscribes to its session's keys before anything else, declares
its liveliness token, then asks the recorder for the session's log so far. An
empty log is a fresh start (ServiceStarted, then the logic's first outputs);
a non-empty one is a restart: the Driver re-feeds it (node.py) and the service
publishes only what it still owes. Messages that arrived on the subscription
while the log was being read may repeat the log: they are skipped quietly.
One thread per Node handles its queue in arrival order; Zenoh's callback
threads only enqueue.
"""

from __future__ import annotations

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

from .bus import Bus
from .node import Driver, Logic

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
                 resume: bool = True):
        self.bus, self.logic, self.session = bus, logic, session
        self.driver = Driver(logic, session, clock)
        self.clock = clock
        self.resume = resume
        self.queue: queue.Queue = queue.Queue()
        self._overlap = 0
        self.resumed_events = 0
        self.thread: threading.Thread | None = None

    def publish(self, events: list[Event]) -> None:
        for e in events:
            self.bus.put(event_key(self.session, e.source, type(e).__name__), encode_event(e))

    def start(self, wait_for: tuple[str, ...] = (), wait_timeout_s: float = 30.0) -> None:
        """Subscribe, announce, catch up; with `wait_for`, first wait for those services' tokens."""
        self.bus.subscribe(session_keys(self.session), lambda key, payload: self.queue.put((key, payload)))
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
            key, payload = self.queue.get(timeout=timeout_s)
        except queue.Empty:
            return False
        overlap = self._overlap > 0
        if overlap:
            self._overlap -= 1
        self.publish(self.driver.receive(key, payload, overlap=overlap))
        return True

    def run(self, stop: threading.Event) -> None:
        while not stop.is_set() and not self.logic.done:
            self.step()

    def run_in_thread(self, stop: threading.Event) -> threading.Thread:
        self.thread = threading.Thread(target=self.run, args=(stop,), name=f"pairplay-{self.logic.name}", daemon=True)
        self.thread.start()
        return self.thread
