"""The recorder: every event of a session into one MCAP file, loss bounded in time.

Rule: the recorder subscribes to `pairplay/<session>/**` and writes each
message's exact bytes to the channel of its key (replay/writer.py), after the
checks every service makes (it decodes, its key agrees with its envelope, right
session, sequence number above the last one on that key). What fails a
check is not written on a typed channel: the recorder publishes a
MessageRejected with the reason and an excerpt of the payload, and records that.
The file flushes at least every 0.1 s (the most a SIGKILL can lose; `pairplay
recover` completes such a file). The session config, seed and software version
go into MCAP metadata ("pairplay.session") when SessionStarted passes, the
recorder's own into "pairplay.recorder". It answers restarting services with
the log so far (`pairplay/<session>/_query/recorder/log`, msgpack batches).
"""

from __future__ import annotations

import logging
import queue
import threading
import time
from pathlib import Path
from typing import Callable

import msgspec

from pairplay import __version__
from pairplay.replay.writer import FLUSH_INTERVAL_NS, EventLogWriter
from pairplay.schemas.events import MessageRejected, SessionStarted, decode_event, encode_event
from pairplay.schemas.envelope import stamped
from pairplay.schemas.keys import alive_key, event_key, parse_event_key, query_key, session_keys

from pairplay.services.bus import Bus
from pairplay.services.runner import LOG_QUERY

log = logging.getLogger("pairplay.recorder")
BATCH = 2000
_MARK = object()


def free_path(path: Path) -> Path:
    """`path`, or `<stem>.<n>.mcap` if it exists: a recording is never overwritten
    (a recorder restarted after a crash must not destroy what the crash left)."""
    n = 1
    candidate = path
    while candidate.exists():
        candidate = path.with_name(f"{path.stem}.{n}{path.suffix}")
        n += 1
    return candidate


class Recorder:
    name = "recorder"

    def __init__(self, bus: Bus | None, session: str, path: str | Path, *, clock: Callable[[], int] = time.time_ns,
                 flush_interval_ns: int = FLUSH_INTERVAL_NS):
        self.bus, self.session, self.path, self.clock = bus, session, free_path(Path(path)), clock
        self.path.parent.mkdir(parents=True, exist_ok=True)
        self.writer = EventLogWriter(self.path, flush_interval_ns=flush_interval_ns)
        self.writer.add_metadata("pairplay.recorder", {"session": session, "software_version": __version__,
                                                       "started_ns": str(clock())})
        self.queue: queue.Queue = queue.Queue()
        self.last_seq: dict[str, int] = {}  # per key
        self.top_seq: dict[str, int] = {}  # per source: the highest sequence number recorded
        self.kept: list[tuple[str, bytes]] = []
        self.seq = 0
        self.rejected = 0
        self.ended = False
        self._lock = threading.Lock()

    # -- bus side (Zenoh threads) -----------------------------------------
    def start(self) -> None:
        self.bus.subscribe(session_keys(self.session), self.enqueue)
        self.bus.queryable(query_key(self.session, self.name, LOG_QUERY), self._answer_log)
        self.bus.alive(alive_key(self.session, self.name))

    def enqueue(self, key: str, payload: bytes) -> None:
        self.queue.put((key, payload, self.clock()))

    def _answer_log(self, _params: str) -> list[bytes]:
        """Everything recorded so far, including what was queued when the query came."""
        reached = threading.Event()
        self.queue.put((_MARK, reached, 0))
        reached.wait(5.0)
        with self._lock:
            items = list(self.kept)
        return [msgspec.msgpack.encode((i // BATCH, items[i:i + BATCH])) for i in range(0, len(items), BATCH)] or []

    # -- writer side (one thread) -----------------------------------------
    def step(self, timeout_s: float = 0.05) -> bool:
        due = self.writer.due_in_ns(self.clock())
        wait = timeout_s if due is None else min(timeout_s, due / 1e9)
        try:
            key, payload, received_ns = self.queue.get(timeout=max(wait, 0.0005))
        except queue.Empty:
            self.writer.maybe_flush(self.clock())
            return False
        if key is _MARK:
            payload.set()
            return True
        self.record(key, payload, received_ns)
        self.writer.maybe_flush(self.clock())
        return True

    def record(self, key: str, payload: bytes, received_ns: int) -> bool:
        """Check and write one message; False (and a published rejection) if it fails a check."""
        try:
            event = decode_event(payload)
            k = parse_event_key(key)
        except (msgspec.DecodeError, msgspec.ValidationError, ValueError) as err:
            return self._reject(f"malformed: {err}", key, payload)
        tag = type(event).__name__
        if (k.session, k.source, k.tag) != (event.session, event.source, tag):
            return self._reject(f"key {key} does not match the payload's session {event.session!r}, source "
                                f"{event.source!r}, event {tag}", key, payload, event)
        if event.session != self.session:
            return self._reject(f"wrong session {event.session!r}", key, payload, event)
        last = self.last_seq.get(key, 0)  # per key, as the services check (node.py)
        if event.seq <= last:
            return self._reject(f"sequence number {event.seq} from {event.source} is not above the last one "
                                f"on {key} ({last}): duplicate or out of order", key, payload, event)
        self.last_seq[key] = event.seq
        self.top_seq[event.source] = max(self.top_seq.get(event.source, 0), event.seq)
        # the recorder's own times: log time = when it took the message (its clock, monotonic in the file),
        # publish time = the same; the envelope's time_ns is the publisher's claim and stays in the payload
        self.writer.write(key, payload, log_time_ns=received_ns, sequence=event.seq)
        with self._lock:
            self.kept.append((key, payload))
        if isinstance(event, SessionStarted):
            c = event.config
            self.writer.add_metadata("pairplay.session", {
                "config": msgspec.json.encode(c).decode(), "session": c.session, "participant": c.participant,
                "persona": c.persona, "seed": str(c.seed), "game_index": str(c.game_index),
                "algorithm": c.algorithm, "software_version": c.software_version or __version__,
                "streams": str(c.streams)})
        elif tag == "SessionEnded":
            self.ended = True
        return True

    def _reject(self, reason: str, key: str, payload: bytes, event=None) -> bool:
        self.rejected += 1
        log.warning("recorder rejected %s: %s", key, reason)
        if self.bus is not None:
            self.seq += 1
            r = stamped(MessageRejected(reason=reason, key=str(key), offending_source=getattr(event, "source", ""),
                                        offending_seq=getattr(event, "seq", 0),
                                        excerpt=payload[:200].decode("utf-8", "replace")),
                        session=self.session, source=self.name, seq=self.seq, time_ns=self.clock())
            self.bus.put(event_key(self.session, self.name, "MessageRejected"), encode_event(r))
        return False

    def drain(self) -> None:
        """Write everything already queued."""
        while True:
            try:
                key, payload, received_ns = self.queue.get_nowait()
            except queue.Empty:
                return
            if key is _MARK:
                payload.set()
            else:
                self.record(key, payload, received_ns)

    def run(self, stop: threading.Event) -> None:
        while not stop.is_set():
            self.step()

    def close(self) -> None:
        self.drain()
        self.writer.close()
