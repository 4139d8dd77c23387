"""A service on the bus: a Driver fed from a Zenoh subscription, in its own thread.

Rule: a Node subscribes to its session's keys but its own publications (or, for
a logic that copes with any order between keys, just those of the events it
reads: `Node.subscribe`) before anything else, asks the recorder for the
session's log so far, and only then declares its liveliness token (`join_log`:
what a waiting game starts the session on; a game that waits for others
declares its own first). An empty log is a fresh start (ServiceStarted, then the logic's first outputs);
a non-empty one is a restart: the Driver re-feeds it (node.py) and the service
publishes only what it still owes. Messages that arrive on the subscription
and repeat the log (on their way while it was read; or, on a recovering bus,
the history the publishers' caches send a subscriber that joins late) are
skipped quietly: the log is the restarted service's cut point (services/guard.py).
Zenoh's callback threads only put samples into the Node's Inbox (never
waiting; a flood is shed there and the count recorded); one thread per Node
handles them in arrival order and publishes what it decides itself when its
Outbox's thread is idle, else leaves it to that thread (services/bus.py; issue
16: two thread hand-offs less per service). Every wait checks the stop flag.
"""

from __future__ import annotations

import gc
import logging
import threading
import time
from collections import deque
from typing import Any, Callable

import msgspec

from pairplay import __version__, environment, testpause
from pairplay.schemas.envelope import SEQ_MAX, Event
from pairplay.schemas.events import ServiceStarted, decode_event, encode_event, own_seq
from pairplay.schemas.keys import alive_key, event_key, query_key, session_keys, source_keys
from pairplay.schemas.trust import SOURCES, STARTERS

from pairplay.services.bus import MISSED, Bus, Inbox, Outbox
from pairplay.services.node import Driver, Logic
from pairplay.services.recorded import FLUSH_S, until_recorded
from pairplay.schemas.nesting import msgpack_decode
from pairplay.services.answers import one_answer

log = logging.getLogger("pairplay.runner")
# a game waits this long for the services it needs (Node.start), then one line, exit 2; a slow or
# loaded lab machine (services started by hand, or at nice 19 under load 30: over 30 s) sets more
WAIT_FOR_S = environment.wait_for_s()  # (pairplay/environment.py: `PAIRPLAY_WAIT_FOR_S=abc` was a traceback)
LOG_QUERY = "log"
SENT_QUERY = "sent"


def fetch_log(bus: Bus, session: str, timeout_s: float = 5.0, stop: threading.Event | None = None) -> list[Event]:
    """The session's events the recorder holds, in its order ([] if no recorder answers)."""
    testpause.pause("log-query")  # (a test holds a joining service here: tests/test_faults_restart.py)
    batches = []
    # one recorder's log: two sessions' that differ are none (one of them is not the recorder: services/answers.py)
    for payload in one_answer(bus.query_replies(query_key(session, "recorder", LOG_QUERY), timeout_s, stop=stop),
                              f"session {session}'s log"):
        try:
            index, items = msgpack_decode(payload, type=tuple[int, list[tuple[str, bytes]]])
        except msgspec.DecodeError as err:
            log.warning("unreadable log batch from the recorder: %s", err)
            continue
        batches.append((index, items))
    events = []
    for _, items in sorted(batches):
        for _, data in items:
            events.append(decode_event(data))
    return events


def join_log(bus: Bus, session: str, name: str, stop: threading.Event | None = None, *, read: bool = True,
             declared: bool = False) -> list[Event]:
    """What a service joining `session` as `name` resumes from: the recorder's log ([] unless it holds the
    session's start, or with `read` False); its liveliness token is declared once the log is read (unless
    `declared`: a game that waits for others declares its own first, and starts the session itself).

    Why in this order: the token is what a waiting game starts the session on. Declared before the log was
    read, the game could start the session in between, and a service's first start read the few events
    logged meanwhile as its own earlier life: "resumed_events 4" on a first start (test_session_crash
    [participant], 1 of 3 CI runs; then the robot bridge, which had its own copy of this start:
    test_faults_restart[robot-False] on a fresh clone under load, trial29 F1). The robot bridge and every
    Node join through here."""
    recorded = fetch_log(bus, session, stop=stop) if read else []
    if not declared:
        bus.alive(alive_key(session, name))
    if not any(type(e).__name__ == "SessionStarted" for e in recorded):
        return []  # the session has not started: nothing to catch up with
    return recorded


def sent_after(parameters: str, name: str) -> int:
    """The seq after which `name` is asked what it sent (`after=<source>:<seq>,...`; 0 if not asked). A number
    is read only as far as the bus's seqs go: a longer one (a query's parameters come from anyone on the bus)
    asks for nothing (SEQ_MAX), and 5000 digits are never given to int(), whose limit raised on Zenoh's thread."""
    after = 0
    for part in parameters.replace("after=", "").split(","):
        source, _, seq = part.partition(":")
        if source == name and seq.isascii() and seq.isdigit():
            after = min(int(seq), SEQ_MAX) if len(seq) <= 16 else SEQ_MAX
    return after


def answer_sent(outbox: Outbox, name: str, query) -> None:
    """Answer `.../_query/<name>/sent?after=<source>:<seq>,...` with what we published after
    that sequence number: msgpack (name, [(key, payload), ...]); from the outbox thread,
    after everything queued before it."""
    after = sent_after(str(query.parameters), name)

    def reply() -> None:
        items = [(k, p) for k, p in outbox.sent if own_seq(p) > after]
        Bus.answer(query, [msgspec.msgpack.encode((name, items))])
    outbox.call(reply)


def serve_sent(inbox: Inbox, outbox: Outbox, name: str, seconds: float) -> None:
    """For `seconds`, answer what the recorder asks of what we sent (`sent?after=`) from `inbox`, the session
    over (services/recorded.py); anything else that comes then is dropped, as it was when the service ended."""
    until = time.monotonic() + seconds
    while (left := until - time.monotonic()) > 0:
        item = inbox.get(left)
        if item is not None and item[0] is None:
            answer_sent(outbox, name, item[1])


def waiting_for(services, timeout_s: float = WAIT_FOR_S) -> str:
    """What a process's first line says it waits for (issue 12: a wait is announced and has a deadline)."""
    return f"waiting up to {timeout_s:g} s for: {', '.join(services)}" if services else ""


# a service whose session's game left the bus this long ago ends (GameWatch); a session whose needed service (its
# external recorder: services/recorderwatch.py) did fails (services/session.py): the settle time, 30 s unless
# PAIRPLAY_SETTLE_S says (pairplay/environment.py; tests of a recorder that never comes back shorten it)
GAME_GONE_S = environment.settle_s()


class GameWatch:
    """Whether the session's game left the bus for good: its liveliness token was seen, then gone
    for `gone_s` (the session's settle time: a crashed game restarted sooner is back in time).

    A service ends when the game ends the session (SessionEnded). One that missed it (its link
    was cut when it came, the session's process ended meanwhile) waited for ever: in the
    four-host test the robot bridge or the participant was still running 60 s after the
    session's end. The token is Zenoh's liveliness, dropped with a dead process's or a cut
    link's session, so this holds whatever the link did. The watcher runs on Zenoh's thread
    and only notes a time."""

    def __init__(self, bus: Bus, session: str, gone_s: float = GAME_GONE_S, clock=time.monotonic):
        from pairplay.schemas.keys import alive_key
        self.gone_s, self.clock = gone_s, clock
        self.seen = False
        self.gone_since: float | None = None
        bus.watch_alive(alive_key(session, "game"), self._on_token)

    def _on_token(self, _key: str, up: bool) -> None:
        if up:
            self.seen, self.gone_since = True, None
        elif self.seen and self.gone_since is None:
            self.gone_since = self.clock()

    def existed(self) -> None:
        """The game was on the bus before this service came (it restarted into a live session: the log or
        the bus said so). A game that ended during the service's start-up never shows it its token: before,
        such a service (a restarted recorder at load 8+) waited for ever; now its absence counts from here."""
        if not self.seen:
            self.seen, self.gone_since = True, self.clock()

    def gone(self) -> bool:
        return self.gone_since is not None and self.clock() - self.gone_since >= self.gone_s


class Stopped(Exception):
    """The stop flag was set while the service waited."""


def start_unless_stopped(start: Callable[[], Any], stop: threading.Event, name: str) -> Any:
    """Run a service's start in a thread of its own and wait for it, or for `stop`: a start may
    take seconds on a loaded machine (the game's first deal loads compiled kernels, a service asks
    for the log, waits for others), and a signal must not wait for it. Raises Stopped if `stop`
    is set first (the start is left to finish or not in its daemon thread), or the start's error;
    else what the start returned."""
    failed: list[BaseException] = []
    result: list = []

    def run() -> None:
        try:
            result.append(start())
        except BaseException as err:  # re-raised in the caller's thread
            failed.append(err)
    thread = threading.Thread(target=run, name=f"pairplay-{name}-start", daemon=True)
    thread.start()
    while thread.is_alive():
        if stop.is_set():
            raise Stopped(name)
        thread.join(0.02)
    if failed:
        raise failed[0]
    return result[0]


class Node:
    def __init__(self, bus: Bus, logic: Logic, session: str, *, clock: Callable[[], int] = time.time_ns,
                 resume: bool = True, stop: threading.Event | None = None):
        self.bus, self.logic, self.session = bus, logic, session
        self.driver = Driver(logic, session, clock)
        if not getattr(logic, "by_tag", False):  # the whole session, each publisher's in its order (`subscribe`),
            # unless the bus recovers an outage per key (services/guard.py `whole`)
            self.driver.guard.whole = not bus.options.recovers
            if logic.name in STARTERS:  # the game: its own publications never come back to it (`subscribe`), so
                self.driver.guard.names_forgeries = True  # a message on its keys is another process's (forgery.py)
        else:  # only the tags it reads (`subscribe`): see services/guard.py `by_tag`
            self.driver.guard.by_tag = True
        self.clock = clock
        self.resume = resume
        self.stop = stop if stop is not None else threading.Event()
        self.inbox = Inbox()
        self.outbox = Outbox(bus, logic.name, keep=True)  # a restarted recorder may ask what we sent
        self.resumed_events = 0
        self.thread: threading.Thread | None = None
        self._lock = threading.RLock()  # the Node's thread, or the session ending it from outside
        self.game_gone_s = GAME_GONE_S  # see GameWatch
        self.game_watch: GameWatch | None = None
        self._keys: dict[tuple[str, str], str] = {}  # (source, tag) -> key (publish); sources are ours, tags a fixed set
        # `hold()` true: inputs wait aside, in order, and queries are still answered (a restarted recorder's
        # refill asks what we sent): a game whose external recorder left the bus (services/recorderwatch.py)
        self.hold: Callable[[], bool] | None = None
        self._held: deque = deque()
        # its recorder is another process: once its session has ended, it stays on the bus until the recorder
        # holds every event it published, answering the refill (services/recorded.py); `lacking`: what it did not
        self.confirm_recorded = False
        self.lacking = ""
        self._sent_query = None  # its queryable (`start`), released when its thread ends: nobody answers it then
    def _on_message(self, key: str, payload: bytes) -> None:
        self.inbox.put(key, payload)  # Zenoh's thread: hand over, never wait

    def _on_miss(self, publisher: str, n: int) -> None:
        self.inbox.lost(f"publisher {publisher}", MISSED, n)  # recorded as a count, like a shed message

    def stamp(self, events: list[Event]) -> list[Event]:
        """Number and time this service's own new events (an input a web page gave, say);
        the caller publishes them (`publish`), outside any bus callback."""
        with self._lock:
            return self.driver._stamp(events)

    def refuse(self, reason: str, key: str, source: str = "", seq: int = 0, payload: bytes = b"") -> list[Event]:
        """A MessageRejected for an input that did not come over the bus (a WebSocket message)."""
        with self._lock:
            return self.driver.reject(reason, key, source, seq, payload)

    def publish(self, events: list[Event], wake: bool = True) -> None:
        """Queue `events` on the Outbox; `wake=False`: the caller publishes them itself next
        (`outbox.publish_here`, outside the lock: see step)."""
        if not events:
            return
        items = []
        for e in events:
            tag = type(e).__name__
            key = self._keys.get((e.source, tag))
            if key is None:  # built and checked once per source and tag (the check is most of its cost)
                key = self._keys[(e.source, tag)] = event_key(self.session, e.source, tag)
            items.append((key, encode_event(e)))
        self.outbox.send_all(items, wake)

    def subscribe(self) -> None:
        """The Node's subscriptions (module rule). A logic that copes with any order between keys
        (`by_tag`): only the tags it reads; Zenoh then does not even send the others here. Any
        other: the whole session but its own echo, each publisher's messages in its order: what
        other processes publish on one subscription (Zenoh keeps a publisher's order on a link),
        what this process's other services publish on one subscription per source. A session's
        own publications reach its own subscribers without the network, and the game's came back
        to it while it was still putting the rest of a step's events: the callbacks of its own
        echoes took the GIL between its puts and held up the one the learner waits for (issue
        16: pick -> suggestion 2.16-2.25x the paced raw round trip with the echo, 2.10-2.14x
        without, 6 interleaved runs each; docs/bus.md "Fifth pass")."""
        if getattr(self.logic, "by_tag", False):
            for tag in sorted(self.logic.consumes):
                self.bus.subscribe(f"{session_keys(self.session)[:-2]}*/{tag}", self._on_message, self._on_miss)
            return
        self.bus.subscribe(session_keys(self.session), self._on_message, self._on_miss, origin="remote")
        for source in sorted(SOURCES - {self.logic.name}):
            self.bus.subscribe(source_keys(self.session, source), self._on_message, self._on_miss, origin="local")

    def start(self, wait_for: tuple[str, ...] = (), wait_timeout_s: float = WAIT_FOR_S) -> None:
        """Subscribe, announce, catch up; with `wait_for`, first wait for those services' tokens.
        Raises Stopped if the stop flag is set meanwhile."""
        self.subscribe()
        self._sent_query = self.bus.queryable(query_key(self.session, self.logic.name, SENT_QUERY), self.inbox.control)
        if self.logic.name != "game":
            self.game_watch = GameWatch(self.bus, self.session, self.game_gone_s)
        if wait_for:
            self.bus.alive(alive_key(self.session, self.logic.name))
            self.wait_for(wait_for, wait_timeout_s)
        recorded = join_log(self.bus, self.session, self.logic.name, self.stop, read=self.resume,
                            declared=bool(wait_for))  # the token once the log is read (join_log)
        if self.stop.is_set():
            raise Stopped(self.logic.name)
        if recorded and self.game_watch is not None:
            self.game_watch.existed()
        announce = ServiceStarted(service=self.logic.name, version=__version__, resumed_events=len(recorded),
                                  marks=sorted(getattr(self.logic, "PLACED", ())))
        if recorded:
            log.info("%s resumes from %d recorded events", self.logic.name, len(recorded))
            self.resumed_events = len(recorded)
            with self._lock:
                if self.stop.is_set():
                    raise Stopped(self.logic.name)
                self.publish(self.driver.resume(recorded, announce=announce))
            for m in self.driver.mismatches:
                log.error("%s: the log and the recomputation disagree: %s", self.logic.name, m)
        else:
            # The logic's start (the game's first deal: 1-3 s on a loaded VM) runs before anything is
            # numbered; numbering and publishing happen at once under the lock, and not once stopped. A
            # session stopped meanwhile ends the game only if it started (session.end_game, same lock):
            # before, the announcement was numbered first, the stop saw a started game and recorded its
            # SessionEnded, and its SessionStarted came after the recording had closed (or never).
            started = self.logic.start()
            with self._lock:
                if self.stop.is_set():
                    raise Stopped(self.logic.name)
                self.publish(self.driver._stamp([announce]) + self.driver._stamp(started))
        # Everything built so far (modules, the log folded at start) lives for the
        # whole session: keep it out of the collector's scans, which otherwise
        # show up as the slowest suggestions (pick -> suggestion p99).
        gc.freeze()

    def wait_for(self, services: tuple[str, ...], timeout_s: float) -> None:
        deadline = time.monotonic() + timeout_s
        wanted = {alive_key(self.session, s) for s in services}
        while True:
            if self.stop.is_set():
                raise Stopped(self.logic.name)
            alive = self.bus.alive_now(alive_key(self.session, "*"), timeout_s=0.5, stop=self.stop)
            if wanted <= alive:
                return
            if time.monotonic() > deadline:
                missing = sorted(k.rsplit("/", 1)[1] for k in wanted - alive)
                raise TimeoutError(f"{self.logic.name}: no {', '.join(missing)} on the bus after {timeout_s:.0f} s")
            self.stop.wait(0.05)

    def step(self, timeout_s: float = 0.1) -> bool:
        """Handle one message (False if none came). Off the main thread, what it decides is
        published from this thread (`Outbox.publish_here`: no hand-off to the Outbox's thread,
        issue 16), after the lock is released: a put that waits on a congested peer then holds
        up only this thread, never the session's end (`end_game` takes the lock) or a signal
        (handled on the main thread; run() on the main thread leaves publishing to the Outbox)."""
        here = threading.get_ident() != threading.main_thread().ident
        holding = self.hold is not None and self.hold()
        item = self._held.popleft() if self._held and not holding else self.inbox.get(timeout_s)
        try:
            shed = self.inbox.take_shed()
            if shed or self.driver.refusals.held:  # (Refusals.pending, read inline: once per step)
                with self._lock:  # numbered and queued in one go: the queue's order is the numbers' order
                    self.publish(self.driver.tick(shed), wake=not here)
            if item is None:
                return False
            key, payload, _ = item
            if key is None:  # a restarted recorder asks what we sent
                answer_sent(self.outbox, self.logic.name, payload)
                return True
            if holding:  # taken once the hold ends, before anything that came after it
                self._held.append(item)
                return True
            with self._lock:
                self.publish(self.driver.receive(key, payload), wake=not here)
            return True
        finally:
            if here:
                self.outbox.publish_here()

    def run(self, stop: threading.Event | None = None) -> None:
        stop = stop or self.stop
        while not stop.is_set() and not self.logic.done:
            try:
                self.step()
            except Exception:  # a bug must not kill the service's only thread (the Driver records logic errors)
                log.exception("%s: unexpected error; going on", self.logic.name)
            if self.game_watch is not None and self.game_watch.gone():
                log.warning("%s: the session's game left the bus %.0f s ago without this service seeing the "
                            "session's end (a cut link?); stopping", self.logic.name, self.game_watch.gone_s)
                break
        with self._lock:  # `pairplay run` may end the game from its main thread meanwhile
            self.publish(self.driver.tick(self.inbox.take_shed(), force=True))
        if self.confirm_recorded and self.logic.done and not stop.is_set():
            self.outbox.flush(FLUSH_S)  # (what it published last: the recorder is asked about it next)
            self.lacking = until_recorded(self.bus, self.session, {self.logic.name: self.driver.seq},
                                          lambda s: serve_sent(self.inbox, self.outbox, self.logic.name, s), stop)
            if self.lacking:
                log.warning("%s: %s", self.logic.name, self.lacking)
        if self.logic.done and self._sent_query is not None:
            # nobody takes the inbox from here on: a refill's question to us would wait its whole timeout, and hold up
            # the recorder's thread with it (3-7 s), while it is asked what it holds by those still on the bus
            self.bus.release(self._sent_query)
            self._sent_query = None
            while self.inbox.get(0) is not None:  # (a question queued meanwhile: dropped, so Zenoh finishes it)
                pass
        if self.driver.guard.skipped:
            log.info("%s skipped %d deliveries its log already held", self.logic.name, self.driver.guard.skipped)

    def run_in_thread(self, stop: threading.Event | None = None) -> threading.Thread:
        thread = threading.Thread(target=self.run, args=(stop,), name=f"pairplay-{self.logic.name}", daemon=True)
        thread.start()  # kept only once started: a thread that could not start is never joined (it raised)
        self.thread = thread
        return thread

    def close(self, timeout_s: float = 1.0) -> bool:
        """Publish what is still queued (bounded), then end the Outbox's thread; True if everything went out."""
        return self.outbox.close(timeout_s)

    def finish(self, join_s: float, flush_s: float) -> bool:
        """After its stop: wait (at most `join_s`) for the Node's thread, then `close` (at most `flush_s`).
        Every owner of a Node ends it so; a Node not closed kept its Outbox's thread for the process's
        life (a pilot's scripted board and the combiner: one more thread per game)."""
        thread = self.thread
        if thread is not None:
            thread.join(join_s)
        return self.close(flush_s)
