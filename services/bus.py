"""The bus: Zenoh sessions configured from one place; nothing on a Zenoh thread ever blocks.

Rule: every pairplay process opens its Zenoh session through `open_bus(options)`.
Our defaults (`SAFE_DEFAULTS`) need no server and no network: listening on
`tcp/127.0.0.1:0` (the OS picks a free port; the real one is read back from
Zenoh's admin space, `Bus.locators()`), multicast scouting and gossip off
(nothing leaves loopback), scouting delay 100 ms. A Zenoh config file
(`--zenoh-config`: TLS, access control, ...) is laid over these defaults key
by key, so a key the file does not set keeps our value, never Zenoh's own
(Zenoh's would turn multicast on and listen on every interface); the options
given on the command line are laid over both. Several processes or hosts: one
process is the router (`pairplay session`), the others its clients (Zenoh
forwards between a router's clients, not between peers that only share a
third peer: measured). The router can be a process of its own (`pairplay router`,
services/router.py) that every service reaches as a client.

Surviving a restart of the router: Zenoh pub/sub keeps no history, so what is in
flight when a client's router goes is lost. A recovering bus (`--recover`,
`BusOptions.recovery`: the clients of a `pairplay router`) therefore publishes with Zenoh's advanced publishers (a
cache of the last `cache_samples` messages per key, sequence numbers, a heartbeat
with the last one every `HEARTBEAT_S`) and subscribes with advanced subscribers
that ask a publisher's cache for what they did not get (on a gap, or on a
heartbeat ahead of what came: a lost tail). The clients reconnect to the restarted
router by themselves (retrying every 0.25-1 s) and the messages of the outage
arrive then, in order per key, once each. What a cache no longer holds Zenoh
reports as a miss (`subscribe(on_miss=...)`): each service records the count,
and the recorder refills it from the publishers' own records (services/recorder.py).
Measured choices: periodic heartbeats, because sporadic ones (sent only when the
number changed) are lost with the outage and a lost tail then never came back;
not periodic queries, which held deliveries up by seconds in a live session. A
subscriber that joins late is sent what the caches hold (Zenoh's recovery of a
publisher it has not heard from): a restarted service then got thousands of old
messages again and a session stalled (measured), so recovery is not the default
of every client, only of those behind a router of their own.

No bus callback ever blocks (a callback that waits on a publish can wait on a
peer that waits on it: the whole process froze, LIBRARY-NOTES). A callback only
hands its sample to an `Inbox`: bounded per source and in bytes, it never
waits; what does not fit is shed and counted, and the service records the
count. Each service publishes from one place it owns, its `Outbox`: its thread,
or the service's own thread when that thread is idle (`Outbox.publish_here`:
two thread hand-offs less per service on a pick's way, issue 16), one at a time
and in order; never a bus callback or the main thread (signals). Its publishers
use congestion control BLOCK (Zenoh's default, DROP, silently lost 72-95% of
events between processes under load), which is safe there because no
consumer's callback can hold it up. SIGINT and SIGTERM set a stop flag;
every wait in a service checks it, and `Bus.close` gives Zenoh a bounded time
(a session closing under a blocked publish takes ~5.5 s: measured), so a
process exits within 2 s, its recording finished. That bound holds by construction:
the signal starts one `Deadline` (`SHUTDOWN_S` after it) shared by every step of
the shutdown; each wait takes what is left of it minus what the steps after it
reserve, so the waits add up to at most the budget however each one fares, and
what a step could not finish by then is counted and recorded, not waited for.
"""

from __future__ import annotations

import _thread
import argparse
import copy
import json
import logging
import queue
import signal
import sys
import threading
import time
import weakref
from collections import Counter, deque
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable

import json5
import msgspec
import zenoh
import zenoh.ext

from pairplay import signals, testpause
from pairplay.errors import UserError, folded
from pairplay.inputs import refusal
from pairplay.schemas.jsonfile import a_folder, empty, in_words
from pairplay.schemas.repeated import refuse_repeated
from pairplay.services.zenohcheck import MODES, exposed, scouting_beyond, type_errors
from pairplay.schemas.nesting import TOO_DEEP, json_loads

log = logging.getLogger("pairplay.bus")
LOOPBACK_ANY_PORT = "tcp/127.0.0.1:0"
# MODES: services/zenohcheck.py (the one list, also what a config file's "mode" may be)
CLOSE_TIMEOUT_S = 0.5  # Bus.close waits this long for Zenoh, then leaves it to the process exit
EXIT_BUDGET_S = 2.0  # a process is gone this long after SIGINT/SIGTERM (issue 12)
SHUTDOWN_S = 1.1  # its services stopped and its recording finished within this; the rest is the exit's
signalled = ""  # the signal that stopped this process, if one did (stop_on_signals)
CACHE_SAMPLES = 10_000  # per key, kept by a recovering publisher for subscribers that missed them (see rule)
MISSED = "lost on the bus, no longer in the publisher's cache when the link came back"  # Inbox.lost's why
HEARTBEAT_S = 0.25  # a recovering publisher tells its last sequence number this often (see rule)
# samples a drained subscription holds for its thread (Bus.subscribe): at 100,000 events/s, 10 ms of them,
# ten times what waits while the thread waits its turn for the GIL (1 ms in `pairplay run recorder`)
DRAIN_CAPACITY = 1024
BUCKETS_CACHED = 4096  # keys whose Inbox allowance is remembered (made-up keys cannot grow it past this)
# Bus.subscribe's `origin`: where the samples it takes were published (Zenoh's allowed_origin)
ORIGINS = {"any": zenoh.Locality.ANY, "remote": zenoh.Locality.REMOTE, "local": zenoh.Locality.SESSION_LOCAL}


def safe_defaults(scouting_delay_ms: int = 100) -> dict[str, Any]:
    """Our defaults for every key a config file leaves out (see rule)."""
    return {
        "listen": {"endpoints": [LOOPBACK_ANY_PORT]},
        "connect": {"endpoints": []},
        "scouting": {"multicast": {"enabled": False}, "gossip": {"enabled": False}, "delay": scouting_delay_ms},
        "adminspace": {"enabled": True},
    }


def overlay(base: dict, top: dict) -> dict:
    """`base` with `top` laid over it, key by key (nested objects merge; anything else replaces)."""
    out = copy.deepcopy(base)
    for k, v in top.items():
        out[k] = overlay(out[k], v) if isinstance(v, dict) and isinstance(out.get(k), dict) else copy.deepcopy(v)
    return out


class BusError(UserError):
    """The bus cannot be opened as configured: a malformed or unusable --listen/--connect
    endpoint, a port in use, a peer that refuses, a missing or invalid --zenoh-config."""


class BusOpenError(BusError, ConnectionError):
    """Zenoh refused to open the session (the message says which endpoint and why)."""


_log_ready = False


def _init_zenoh_log() -> None:
    """Zenoh's own log only when asked for with RUST_LOG (e.g. RUST_LOG=zenoh::net::routing::interceptor::
    access_control=trace shows each access-control decision; RUST_LOG=error, Zenoh's errors), else none.
    Zenoh writes its log to stdout, and zenoh-python (1.10) offers no other stream (its bridge to Python's
    logging is not built in): by default its ERROR lines landed on a verb's stdout, which holds results
    only (an interrupted session printed "sending on a closed channel" there). What Zenoh refuses to our
    calls reaches the user as our own one line (BusOpenError, ...), not through its log."""
    global _log_ready
    if not _log_ready:
        _log_ready = True
        try:
            zenoh.try_init_log_from_env()  # nothing without RUST_LOG
        except Exception:  # already set up by the host program
            pass


class ConfigFileError(BusError, ValueError):
    """A --zenoh-config file that cannot be read (the message names the file and why)."""


def read_config_file(path: str) -> dict[str, Any]:
    if said := refusal(path):  # before opening: a pipe blocked (pairplay/inputs.py)
        raise ConfigFileError(f"cannot use the Zenoh config: {said}", f"--zenoh-config {path}")
    try:
        text = Path(path).read_text(encoding="utf-8-sig")  # a byte order mark is no JSON5 error
    except IsADirectoryError:
        raise ConfigFileError(f"cannot use the Zenoh config: {a_folder(path, 'Zenoh config', 'its JSON5 file')}",
                              f"--zenoh-config {path}") from None
    except OSError as err:
        raise ConfigFileError(f"cannot use the Zenoh config: {err.strerror or err}", f"--zenoh-config {path}") from None
    except UnicodeDecodeError as err:  # not text at all
        raise ConfigFileError(f"cannot use the Zenoh config: not JSON5: {err}", f"--zenoh-config {path}") from None
    if empty(text):  # (JSON5 said "Empty strings are not legal JSON5")
        raise ConfigFileError(f"cannot use the Zenoh config: {empty(text)}", f"--zenoh-config {path}")
    try:
        data = json5.loads(text)
    except ValueError as err:  # json5 says the line and column; what to do, as every JSON input (jsonfile.syntax_words)
        said = str(err).replace("<string>:", "line ", 1)
        said += (": cut short (a copy or a save that did not finish? put back a whole copy), or a quote or bracket "
                 "left open" if "Unexpected end of input" in said else ": correct it there")
        raise ConfigFileError(f"cannot use the Zenoh config: not JSON5: {said}", f"--zenoh-config {path}") from None
    except RecursionError:  # json5 recurses per level too (schemas/nesting.py)
        raise ConfigFileError(f"cannot use the Zenoh config: not JSON5: {TOO_DEEP}", f"--zenoh-config {path}") from None
    if not isinstance(data, dict):
        raise ConfigFileError("cannot use the Zenoh config: the top level must be an object", f"--zenoh-config {path}")
    try:  # json5 keeps the last of a key given twice: `{multicast: {enabled: false, enabled: true}}` turned it on
        refuse_repeated(text, json5.loads)
    except msgspec.ValidationError as err:
        raise ConfigFileError(f"cannot use the Zenoh config: {in_words(err)}", f"--zenoh-config {path}") from None
    return data


def _zenoh_reason(err: Exception) -> str:
    """Zenoh's message without the Rust source location it ends with."""
    text = folded(err)
    cut = text.find(" at /")
    return (text[:cut] if cut > 0 else text).rstrip(" .!") or type(err).__name__


@dataclass
class BusOptions:
    mode: str = "peer"
    listen: list[str] | None = None  # None: the file's, else (peer/router) loopback on a free port
    connect: list[str] = field(default_factory=list)
    zenoh_config: str | None = None  # a Zenoh JSON5 config file: TLS, access control, ...
    scouting_delay_ms: int = 100
    recovery: bool = False  # advanced pub/sub (see rule): clients of a router that may restart (--recover)
    cache_samples: int = CACHE_SAMPLES  # per key, with recovery

    @property
    def recovers(self) -> bool:
        """Whether this bus publishes and subscribes so that a router's restart loses nothing."""
        return self.recovery

    def where(self) -> str:
        """The options a failure to open the bus is about, as given on the command line."""
        parts = [f"--zenoh-config {self.zenoh_config}"] if self.zenoh_config else []
        parts += [f"--listen {e}" for e in self.listen or []] + [f"--connect {e}" for e in self.connect]
        return ", ".join(parts) or f"mode {self.mode}, listening on {LOOPBACK_ANY_PORT}"

    def to_dict(self) -> dict[str, Any]:
        """The whole config: our defaults, the file over them, the command line over both."""
        if self.mode not in MODES:
            raise BusError(f"bus mode {self.mode!r} is not one of {MODES}", "--mode")
        cfg = safe_defaults(self.scouting_delay_ms)
        if self.mode == "client":
            cfg["listen"]["endpoints"] = []  # a client listens nowhere unless told
        if self.recovers:  # back soon after a restarted router (Zenoh's own: 1 s, doubling up to 4 s)
            cfg["connect"]["retry"] = {"period_init_ms": 250, "period_max_ms": 1000, "period_increase_factor": 1.5}
        if self.zenoh_config:
            data = read_config_file(self.zenoh_config)
            wrong = type_errors(data)  # the keys we read or set (services/zenohcheck.py)
            if wrong:
                raise ConfigFileError(f"cannot use the Zenoh config: {wrong[0]}", f"--zenoh-config {self.zenoh_config}")
            cfg = overlay(cfg, data)
        cfg["mode"] = self.mode
        if self.listen is not None:
            cfg.setdefault("listen", {})["endpoints"] = list(self.listen)
        if self.connect:
            cfg.setdefault("connect", {})["endpoints"] = list(self.connect)
        cfg.setdefault("adminspace", {})["enabled"] = True  # locators() reads the real endpoints there
        if self.recovers:  # Zenoh's advanced publishers need timestamps on their samples
            cfg.setdefault("timestamping", {})["enabled"] = True
        return cfg

    def to_zenoh(self) -> zenoh.Config:
        """The Zenoh config (to_dict); BusError naming the options if Zenoh refuses it."""
        cfg = self.to_dict()
        try:
            return zenoh.Config.from_json5(json.dumps(cfg))
        except Exception as err:  # Zenoh's own check of the keys and values
            what = "cannot use the Zenoh config" if self.zenoh_config else "bad bus endpoint"
            raise ConfigFileError(f"{what}: {_zenoh_reason(err)}", self.where()) from None


def add_bus_arguments(parser: argparse.ArgumentParser) -> None:
    g = parser.add_argument_group("bus (Zenoh)")
    g.add_argument("--mode", choices=MODES, default=None,
                   help="Zenoh mode (default: client with --connect, else the verb's own: a session is a router, "
                        "anything else a peer)")
    g.add_argument("--listen", action="append", metavar="ENDPOINT",
                   help=f"endpoint to listen on, repeatable (default {LOOPBACK_ANY_PORT}: a free port)")
    g.add_argument("--connect", action="append", default=[], metavar="ENDPOINT",
                   help="endpoint to connect to, e.g. tcp/127.0.0.1:7447 (repeatable)")
    g.add_argument("--recover", action="store_true",
                   help="behind a `pairplay router` that may restart: Zenoh's advanced pub/sub (publisher caches, "
                        "recovery of what an outage held up); every process of the session needs it")
    g.add_argument("--zenoh-config", metavar="FILE",
                   help="Zenoh JSON5 config (TLS, access control); laid over pairplay's safe defaults key by key")


def options_from_args(args: argparse.Namespace, default_mode: str = "peer") -> BusOptions:
    """Bus options of a command line. Without --mode, a process that connects somewhere
    is a client (Zenoh forwards between the clients of a router, not between peers
    that only share a third peer), and one that does not is `default_mode`."""
    mode = args.mode or ("client" if args.connect else default_mode)
    return BusOptions(mode=mode, listen=args.listen, connect=list(args.connect or []), zenoh_config=args.zenoh_config,
                      recovery=bool(getattr(args, "recover", False)))


def source_of(key: str) -> str:
    """The source chunk of `pairplay/<session>/<source>/<tag>` ('' if the key is not one)."""
    parts = key.split("/", 3)
    return parts[2] if len(parts) == 4 else ""


class Deadline:
    """One time limit shared by every step of a shutdown (see module rule).

    `left(reserve, cap)`: the seconds a step may still wait, keeping `reserve`
    seconds for the steps after it, at most `cap`; never negative."""

    def __init__(self, seconds: float, clock: Callable[[], float] = time.monotonic):
        self.clock = clock
        self.at = clock() + seconds

    def left(self, reserve: float = 0.0, cap: float | None = None) -> float:
        x = max(0.0, self.at - reserve - self.clock())
        return x if cap is None else min(cap, x)

    def passed(self, reserve: float = 0.0) -> bool:
        return self.left(reserve) <= 0.0


def deadline_of(stop: threading.Event, seconds: float = SHUTDOWN_S) -> Deadline:
    """The shutdown deadline of a stop flag: started by the signal (`stop_on_signals`), else now."""
    deadline = getattr(stop, "deadline", None)
    if deadline is None:
        deadline = stop.deadline = Deadline(seconds)
    return deadline


def shutdown_wait(stop: threading.Event | None, cap: float, reserve: float = 0.0) -> float:
    """Seconds a wait on a shutdown path may take (a join, a flush, a close, a linger): `cap`
    while running; once `stop` is set, what the shutdown's deadline leaves after `reserve`
    seconds kept for the steps after it, at most `cap`. Every such wait of every verb takes
    its time from here, so however each fares they add up to the deadline (module rule)."""
    if stop is None or not stop.is_set():
        return cap
    return deadline_of(stop).left(reserve, cap)


def signal_taken(stop: threading.Event) -> str:
    """The signal's name if `stop_on_signals` took one for `stop` (or `pass_stop` passed one on), else "": set in
    the handler itself, unlike `stop.is_set()`, which a thread the handler starts sets, late on a loaded machine
    (`stop_on_signals`). Whether a KeyboardInterrupt is a second signal's, and what a verb says of the game or file
    the first stopped, is decided from this."""
    return getattr(stop, "why", "")


def pass_stop(source: threading.Event, target: threading.Event) -> None:
    """Stop `target` as `source` was stopped: the same reason (`why`) and the same deadline (a
    verb's signal stopping a session it runs with its own stop flag)."""
    target.why = getattr(source, "why", "") or getattr(target, "why", "")
    target.deadline = deadline_of(source)
    target.set()


SHED_KEPT = 20_000  # Inbox.shed_items holds at most this many between two takes
_NOTHING_SHED: Counter = Counter()  # Inbox.take_shed's answer when nothing was shed (shared: never changed)


class Inbox:
    """Zenoh's callback threads -> one service thread; `put` never waits (see module rule).

    Arrival order is kept. What does not fit is shed and counted by source:
    a message over `max_payload` bytes; a message from a source outside
    `sources` once `per_unknown` of those wait (they share one allowance, so
    made-up names cannot fill the inbox); a known source's message once
    `per_source` of its own wait; anything once `max_bytes` wait in all.
    Items are (key, payload, received_ns); `control` items (a query to answer)
    are never shed.
    """

    def __init__(self, sources: frozenset[str] | None = None, *, per_source: int = 20_000,
                 per_unknown: int = 1_000, max_bytes: int = 64 << 20, max_payload: int | None = None,
                 clock: Callable[[], int] = time.time_ns):
        from pairplay.schemas.trust import MAX_PAYLOAD, SOURCES
        self.sources = SOURCES if sources is None else sources
        self.per_source, self.per_unknown, self.max_bytes = per_source, per_unknown, max_bytes
        self.max_payload = MAX_PAYLOAD if max_payload is None else max_payload
        self.clock = clock
        self._items: deque = deque()
        self._count: Counter = Counter()  # waiting, by source ('' for every unknown one)
        self._bytes = 0
        self._lock = threading.Lock()
        self._cond = threading.Condition(self._lock)
        self._waiting = 0  # consumers waiting in get_many: put wakes one only then
        self._buckets: dict[str, str] = {}  # key -> its allowance (_bucket_of)
        self.shed: Counter = Counter()  # (source, why) -> messages shed, since the last take_shed
        self.shed_total = 0
        # a list to keep what a full inbox sheds of a known source, (key, payload), for its owner to say what it was
        # (`take_shed_items`; the recorder: a hole they leave in its file is its own shedding, not the bus's); None:
        # only counted
        self.shed_items: list | None = None

    def put(self, key: str, payload: bytes) -> bool:
        """Queue one sample; False if it was shed. Never waits beyond a short lock.
        (Runs once per message on Zenoh's thread: the lock is taken directly and the
        consumer woken only if it waits, measured per message in the recorder's profile.)"""
        bucket = self._bucket_of(key)
        cap = self.per_source if bucket else self.per_unknown
        size = len(payload)
        with self._lock:
            if size > self.max_payload or self._count[bucket] >= cap or self._bytes + size > self.max_bytes:
                self._shed_one(key, payload, bucket, cap)
                return False
            self._items.append((key, payload, self.clock()))
            self._count[bucket] += 1
            self._bytes += size
            if self._waiting:
                self._cond.notify()
        return True

    def _bucket_of(self, key: str) -> str:
        """The allowance a key's messages count against: its source if known, else '' (cached
        per key; the cache is bounded, so made-up keys cannot grow it)."""
        bucket = self._buckets.get(key)
        if bucket is None:
            source = source_of(key)
            bucket = source if source in self.sources else ""
            if len(self._buckets) < BUCKETS_CACHED:
                self._buckets[key] = bucket
        return bucket

    def _shed_one(self, key: str, payload: bytes, bucket: str, cap: int) -> None:
        size = len(payload)
        # (no number in the why: a refusal's count names its kind with digits as "N", trial28 F20)
        why = ("larger than the bus's payload limit" if size > self.max_payload else
               "inbox full for this source" if self._count[bucket] >= cap else "inbox full")
        self.shed[(source_of(key), why)] += 1
        self.shed_total += 1
        # (a made-up source's leaves no hole; at most SHED_KEPT between two takes: a consumer held up in a flood
        # must not grow what the inbox bounds; past it a hole's cause is not known, and said as the bus's)
        if self.shed_items is not None and bucket and size <= self.max_payload and len(self.shed_items) < SHED_KEPT:
            self.shed_items.append((key, payload))

    def control(self, item: Any) -> None:
        """Queue an item for the service thread that is never shed (a query to answer)."""
        with self._cond:
            self._items.append((None, item, self.clock()))
            if self._waiting:
                self._cond.notify()

    def get(self, timeout_s: float = 0.1):
        """The oldest item, or None after `timeout_s`."""
        got = self.get_many(timeout_s, 1)
        return got[0] if got else None

    def get_many(self, timeout_s: float = 0.1, most: int = 1000) -> list:
        """Up to `most` of the oldest items at once (one lock and one wake-up for a batch),
        waiting up to `timeout_s` for the first; [] if none came."""
        with self._cond:
            if not self._items:
                if timeout_s <= 0:
                    return []
                self._waiting += 1
                try:
                    self._cond.wait(timeout_s)
                finally:
                    self._waiting -= 1
                if not self._items:
                    return []
            items = self._items
            n = min(most, len(items))
            out = [items.popleft() for _ in range(n)]
            count, buckets = self._count, self._buckets
            for key, payload, _ in out:
                if key is not None:
                    bucket = buckets.get(key)
                    if bucket is None:
                        source = source_of(key)
                        bucket = source if source in self.sources else ""
                    count[bucket] -= 1
                    self._bytes -= len(payload)
            return out

    def __len__(self) -> int:
        return len(self._items)

    def discard(self, why: str, keep: Callable[[str], bool] | None = None, into: list | None = None) -> int:
        """Shed everything still waiting (counted under `why`, like any shed message; control
        items are dropped); how many messages. For a shutdown that cannot wait for them.
        `keep(key)`: the messages it is true of stay, in order (what a shutdown must still take).
        `into`: each message shed is appended to it, (key, payload), for the caller to say what it was
        (the recorder: a hole they leave in its file is theirs, not the bus's)."""
        with self._cond:
            n = 0
            kept = deque()
            for item in self._items:
                key = item[0]
                if key is not None and keep is not None and keep(key):
                    kept.append(item)
                elif key is not None:
                    self.shed[(source_of(key), why)] += 1
                    n += 1
                    if into is not None:
                        into.append((key, item[1]))
            self.shed_total += n
            self._items = kept
            self._count.clear()
            self._bytes = 0
            for key, payload, _ in kept:  # (kept: a few; the inbox's counts hold them again)
                self._count[self._bucket_of(key)] += 1
                self._bytes += len(payload)
        return n

    def lost(self, source: str, why: str, n: int) -> None:
        """Count `n` messages that never reached this inbox (lost on the bus: `Bus.subscribe`'s
        `on_miss`) with what it shed, so the service records them the same way. Never waits."""
        with self._cond:
            self.shed[(source, why)] += n
            self.shed_total += n

    def oldest_ns(self) -> int | None:
        with self._cond:
            return self._items[0][2] if self._items else None

    def take_shed(self) -> Counter:
        """What was shed since the last call, by (source, why); empty, do not change it."""
        if not self.shed:  # the usual case, once per step of a service: no lock and no new Counter (a shed
            return _NOTHING_SHED  # counted meanwhile, after this read under the GIL, is the next call's)
        with self._cond:
            out, self.shed = self.shed, Counter()
        return out

    def take_shed_items(self) -> list:
        """What was kept of the messages shed since the last call (`shed_items`), oldest first."""
        if not self.shed_items:
            return []
        with self._cond:
            out, self.shed_items = self.shed_items, []
        return out


class Outbox:
    """The one place a service publishes from: its own thread, or its owner's (see module rule).

    `send` and `call` never wait. Publishing is in order with BLOCK publishers, by
    whichever holds `_putting`: the Outbox's thread, or the owner thread through
    `publish_here` (a service thread after a step). `send(..., wake=False)` only
    queues, for the owner that calls `publish_here` next: it publishes what waits
    itself when nobody else is publishing, so an event leaves without two thread
    hand-offs (issue 16: ~50 us each cold, and the Outbox thread waking in the
    middle of a step took the GIL from it); when the thread is busy it leaves
    everything to it. The owner may thus wait in a put (a congested peer; Zenoh
    closes the link after ~5 s), never in a bus callback: callers must be a
    thread no signal handler or bus callback runs on (services/runner.py runs its
    Node in a thread of its own for that). An event with another queued right
    behind it is put without express (`Bus.put_batched`) and the last of the run
    with it, so what one step decided leaves in one Zenoh batch, sent at once by
    its last event (a first pick's three events: 98 us of puts cold, 29 us
    batched). `call(fn)` runs `fn` in turn (a
    query's answer). `keep`: remember what was sent (a restarted recorder asks)."""

    def __init__(self, bus: "Bus", name: str, keep: bool = False):
        self.bus, self.name = bus, name
        self._items: deque = deque()  # (key, payload) or (None, fn), in order
        self._pending = 0  # queued or being published
        self._lock = threading.Lock()
        self._wake = threading.Condition(self._lock)  # the thread: something was sent
        self._idle = threading.Condition(self._lock)  # flush: nothing pending
        self._putting = threading.Lock()  # held by whoever publishes now: one at a time keeps the order
        self._stopping = False
        self.sent: list[tuple[str, bytes]] | None = [] if keep else None
        self._publishing: tuple[list, int] = ([], 0)  # the run being published and how far (`_drain`; one
        # attribute, so `in_hand` reads both at once)
        self.failed = 0
        self._thread = threading.Thread(target=self._run, name=f"pairplay-{name}-outbox", daemon=True)
        self._thread.start()
        adopt = getattr(bus, "adopt", None)
        if adopt is not None:  # its bus (a game's scope) stops the thread when it closes, if nobody did
            adopt(self)

    def send(self, key: str, payload: bytes, wake: bool = True) -> None:
        """Queue `payload` for `key`; `wake=False`: the caller calls `publish_here` next."""
        with self._lock:
            self._pending += 1
            self._items.append((key, payload))
            if wake:
                self._wake.notify()

    def send_all(self, items: list[tuple[str, bytes]], wake: bool = True) -> None:
        """`send` of each (key, payload) in order, under one taking of the lock (a step's events)."""
        with self._lock:
            self._pending += len(items)
            self._items.extend(items)
            if wake:
                self._wake.notify()

    def send_within(self, key: str, payload: bytes, stop: threading.Event, most: int = 1_000) -> bool:
        """`send`, once fewer than `most` wait (a producer faster than the bus: `pairplay replay` at
        full speed); the wait checks `stop`, so a signal never waits on a blocked publish. False
        if stopped first (not sent)."""
        while self._pending >= most:
            if stop.wait(0.001):
                return False
        self.send(key, payload)
        return True

    def call(self, fn: Callable[[], None]) -> None:
        with self._lock:
            self._pending += 1
            self._items.append((None, fn))
            self._wake.notify()

    def publish_here(self) -> None:
        """Publish what waits from the calling thread, unless the Outbox's thread is publishing
        (then it takes everything, in order). May wait in a put: see the class rule."""
        if self._putting.acquire(blocking=False):
            try:
                self._drain()
            finally:
                self._putting.release()
        # what came in meanwhile (or while the thread held _putting) is the thread's: its
        # wait checks for waiting items, so nothing is stranded. Read first without the lock (a
        # step's usual case, nothing left): an item sent after the read woke the thread itself
        if self._items:
            with self._lock:
                if self._items:
                    self._wake.notify()

    def _run(self) -> None:
        while True:
            with self._lock:
                while not self._items and not self._stopping:
                    self._wake.wait()
                if self._stopping and not self._items:
                    return
            with self._putting:
                self._drain()

    def _drain(self) -> None:
        """Publish until nothing waits (the caller holds `_putting`): what waits is taken as a run, under
        one taking of the lock, and counted done once the run is out (a step's events: issue 16)."""
        while True:
            with self._lock:
                if not self._items:
                    return
                run = list(self._items)
                self._items.clear()
                self._publishing = (run, 0)
            done = 0
            try:
                last = len(run) - 1
                for i, (key, item) in enumerate(run):
                    # another event right behind: it rides in Zenoh's batch, and the last of the run (express)
                    # sends it (Bus.put_batched); one that came in after the run was taken is the next run's
                    self._publish(key, item, i < last and run[i + 1][0] is not None)
                    done += 1
                    self._publishing = (run, done)
            finally:
                with self._lock:
                    if done < len(run):  # left by an exception _publish does not count (a thread's exit): kept
                        self._items.extendleft(reversed(run[done:]))
                    self._pending -= done
                    if not self._pending:
                        self._idle.notify_all()

    def _publish(self, key: str | None, item, more: bool) -> None:
        """One item of a run: an event put (batched when `more`), or a call; a failure counted, never raised."""
        try:
            if key is None:
                item()
            else:
                if self.sent is not None:  # before the put: one that waits in it is in hand (`in_hand`)
                    self.sent.append((key, item))
                if more:
                    self.bus.put_batched(key, item)
                else:
                    self.bus.put(key, item)
        except Exception as err:  # a closed session, a refused key: counted, the thread goes on
            self.failed += 1
            # the bus closed under a stopping process (a signal at start-up): counted, INFO (README's logging
            # rule: a WARNING is for data a running session lost or refused)
            closing = getattr(self.bus, "_closed", False)
            what = key if key is not None else f"(a call, {getattr(item, '__name__', item)!s:.80})"  # not "None"
            log.log(logging.INFO if closing else logging.WARNING, "%s could not publish %s: %s", self.name, what, err)

    def pending(self) -> int:
        return self._pending

    def in_hand(self) -> list[tuple[str, bytes]]:
        """Every event this Outbox was given, in order: what it published or is publishing (`sent`, kept
        only with `keep`), then what still waits. The events of an in-process service its session's
        recorder writes at the close whatever the bus brought (services/session.py `own_tail`)."""
        # read against the way an event moves (waiting -> the run being published -> sent): one that moves
        # between two reads is seen twice (the caller drops a repeat), never missed
        with self._lock:
            waiting = [(key, item) for key, item in self._items if key is not None]
        run, at = self._publishing
        running = [(key, item) for key, item in run[at:] if key is not None]
        return list(self.sent or ()) + running + waiting

    def flush(self, timeout_s: float) -> bool:
        """Wait (bounded) until everything sent so far is published; False on timeout."""
        deadline = time.monotonic() + timeout_s
        with self._lock:
            if self._items:
                self._wake.notify()  # queued with wake=False by an owner that stopped before publishing
            while self._pending:
                left = deadline - time.monotonic()
                if left <= 0:
                    return False
                self._idle.wait(left)
        return True

    def close(self, timeout_s: float = 1.0) -> bool:
        """Publish what is queued (bounded by `timeout_s`), then stop the thread."""
        done = self.flush(timeout_s)
        self.stop()
        return done

    def stop(self) -> None:
        """End the thread once what is queued is handed on (published, or counted failed once the bus
        is closed); never waits."""
        with self._lock:
            self._stopping = True
            self._wake.notify()


class BusClosed(RuntimeError):
    """A declaration or a publish on a bus, or a bus's scope, that is closed already."""


class Bus:
    """One Zenoh session with cached BLOCK publishers.

    Everything declared through a Bus (subscribers, each with the callback thread zenoh-python
    gives it; queryables; liveliness tokens and watchers; publishers) and every Outbox made on
    it are released by its `close`. `scope()` is a Bus on the same session whose close releases
    only its own, the session left open: a process that runs game after game on one bus (`protocol
    pilot`, `protocol serve`) runs each on a scope of its own, or each game's ~40 declarations and
    their threads lived until the process ended (a new user's 12-game pilot: 53 -> 511 threads,
    1.8 -> 5.5 GB of address space; under `ulimit -v 3000000` game 5 could not start a thread).
    Once closed, a bus refuses new declarations and publishes (BusClosed): a service's start
    left running after a stop cannot declare on the open session what nobody would release."""

    def __init__(self, options: BusOptions | None = None, session: zenoh.Session | None = None,
                 express: bool = True, stop: threading.Event | None = None):
        self.options = options or BusOptions()
        self.stop = stop  # the process's stop flag: once set, closing takes what its deadline leaves
        # express: each event leaves at once instead of waiting to be batched with others
        # (an event is a decision someone waits for)
        self.express = express
        self.session = session if session is not None else _open(self.options)
        self._publishers: dict[str, zenoh.Publisher] = {}
        self._batched: dict[str, zenoh.Publisher] = {}  # put_batched: the same keys without express
        self._probes: dict[str, zenoh.Publisher] = {}  # matching() of a recovering bus
        self._lock = threading.Lock()
        self._declared: list = []
        self._closed = False
        self._parent: Bus | None = None  # a scope's bus (scope): its close leaves the session open
        self._scopes: list[Bus] = []  # open scopes: closed with this bus
        self._outboxes: weakref.WeakSet[Outbox] = weakref.WeakSet()  # their threads end with this bus (adopt)
        self.missed: Counter = Counter()  # publisher -> messages Zenoh reported lost for good (recovering bus)

    def scope(self) -> "Bus":
        """A Bus on this one's Zenoh session whose close releases only what was declared through
        it (class rule); closed with this bus, if not before."""
        child = Bus(self.options, session=self.session, express=self.express, stop=self.stop)
        child._parent = self
        with self._lock:
            if self._closed:
                raise BusClosed("the bus is closed")
            self._scopes.append(child)
        return child

    def adopt(self, outbox: "Outbox") -> None:
        """An Outbox made on this bus: its thread is stopped when the bus closes (if its owner did not)."""
        with self._lock:
            closed = self._closed
            if not closed:
                self._outboxes.add(outbox)
        if closed:
            outbox.stop()

    def _keep(self, declared):
        """Remember a declaration for `close`; on a closed bus, undeclare it at once and raise BusClosed."""
        with self._lock:
            if not self._closed:
                self._declared.append(declared)
                return declared
        _undeclare(declared)
        raise BusClosed("the bus is closed")

    def publisher(self, key: str, express: bool | None = None) -> zenoh.Publisher:
        """The BLOCK publisher of `key`, declared once; `express=False` (Bus.put_batched): a second one
        on the key without express (a plain bus only)."""
        batched = express is False and self.express
        cache = self._batched if batched else self._publishers
        pub = cache.get(key)
        if pub is None:
            with self._lock:
                if self._closed:
                    raise BusClosed(f"the bus is closed: nothing is published on {key}")
                pub = cache.get(key)
                if pub is None:
                    if self.options.recovers:
                        pub = zenoh.ext.declare_advanced_publisher(
                            self.session, key, congestion_control=zenoh.CongestionControl.BLOCK, express=self.express,
                            cache=zenoh.ext.CacheConfig(self.options.cache_samples),
                            sample_miss_detection=zenoh.ext.MissDetectionConfig(heartbeat=HEARTBEAT_S, sporadic_heartbeat=None))
                    else:
                        pub = self.session.declare_publisher(key, congestion_control=zenoh.CongestionControl.BLOCK,
                                                             express=self.express and not batched)
                    cache[key] = pub
        return pub

    def matching(self, key: str) -> bool:
        """Whether a subscriber anywhere matches `key` now (Zenoh's matching status; a recovering
        bus's advanced publishers have none, so a plain probe publisher on the key answers)."""
        if not self.options.recovers:
            return self.publisher(key).matching_status.matching
        probe = self._probes.get(key)
        if probe is None:
            with self._lock:
                if self._closed:
                    raise BusClosed("the bus is closed")
                probe = self._probes.get(key) or self.session.declare_publisher(key)
                self._probes[key] = probe
        return probe.matching_status.matching

    def put(self, key: str, payload: bytes) -> None:
        """Publish (may wait under congestion: call it from an Outbox or a test thread, never a callback)."""
        self.publisher(key).put(payload)

    def put_batched(self, key: str, payload: bytes) -> None:
        """Publish with more to follow at once: without express, so the sample waits in Zenoh's
        current batch for the next one, and the next express put (`put`) sends them together (one
        network write, one wake of the link's task: issue 16, ~30 us a put with a peer, cold).

        Zenoh's rule (io/zenoh-transport/src/common/pipeline.rs, StageIn::push_network_message):
        an express message moves the current batch out at once; any other stays in it for
        adaptive batching, at most `transport.link.tx.batching.time_limit` (1 ms by default)
        past the batch's first write. The caller must end a run of these with `put` (the
        Outbox's rule), or a sample may wait that long. Order is kept (one batch, one
        priority). A recovering bus's publishers keep their caches per publisher, so there
        this is `put` (one publisher per key keeps a late joiner's replay in order)."""
        self.publisher(key, express=self.options.recovers).put(payload)

    def subscribe(self, key_expr: str, callback: Callable[[str, bytes], None],
                  on_miss: Callable[[str, int], None] | None = None, *, drain: bool = False,
                  origin: str = "any"):
        """Call `callback(key, payload)` for every sample. The callback runs on a Zenoh
        thread: it must not raise and must not wait (hand the sample to an Inbox).
        A recovering bus (see rule) calls `on_miss(publisher, n)` when Zenoh reports `n`
        messages of a publisher (its Zenoh id) lost for good; the same rules apply to it.
        Misses are also counted in `self.missed`.

        `drain=True` (a subscriber that takes a whole session's stream: the recorder): the
        samples wait in a Zenoh FIFO channel of `DRAIN_CAPACITY` and one thread of ours takes
        everything waiting each time it holds the GIL (`_drain_samples`), where zenoh-python's
        own callback thread gives the GIL up and takes it again around every sample: beside a
        writing thread working through a backlog, each of those takes waited for it (issue 16:
        a 100,000-event burst was taken 0.50-0.87x as fast as a raw subscriber, 1.45-1.88x
        drained, same run, load < 1). The channel is bounded like Zenoh's default one (a
        consumer that stops taking holds up Zenoh's thread, never memory); ours never stops.

        `origin`: "any", or only what other processes publish ("remote") or only what this
        process does ("local"): Zenoh's `allowed_origin` (a session's own publications
        reach its own subscribers without the network; services/runner.py keeps a service's
        own echo away so)."""
        allowed_origin = ORIGINS[origin]

        def on_sample(sample: zenoh.Sample) -> None:
            try:
                callback(str(sample.key_expr), sample.payload.to_bytes())
            except Exception:  # Zenoh only logs callback errors; say where it came from
                log.exception("subscriber callback on %s failed", sample.key_expr)
        handler = zenoh.handlers.FifoChannel(DRAIN_CAPACITY) if drain else on_sample
        if not self.options.recovers:
            sub = self._keep(self.session.declare_subscriber(key_expr, handler, allowed_origin=allowed_origin))
            if drain:
                self._drain_samples(sub.handler, on_sample, key_expr)
            return sub

        def on_lost(miss) -> None:
            try:
                publisher = str(miss.source)
                with self._lock:
                    self.missed[publisher] += miss.nb
                log.warning("%d messages on %s from %s lost on the bus", miss.nb, key_expr, publisher)
                if on_miss is not None:
                    on_miss(publisher, miss.nb)
            except Exception:
                log.exception("miss listener on %s failed", key_expr)
        sub = self._keep(zenoh.ext.declare_advanced_subscriber(
            self.session, key_expr, handler, allowed_origin=allowed_origin,
            recovery=zenoh.ext.RecoveryConfig(periodic_queries=None, heartbeat=True)))
        self._keep(sub.sample_miss_listener(on_lost))
        if drain:
            self._drain_samples(sub.handler, on_sample, key_expr)
        return sub

    @staticmethod
    def _drain_samples(channel, on_sample: Callable[[zenoh.Sample], None], key_expr: str) -> threading.Thread:
        """A thread that waits for a sample (the GIL released), then hands on every sample already
        waiting without giving the GIL up in between (`try_recv`); it ends when the subscriber is
        undeclared or its session closed (the channel then raises: closed). `on_sample` never raises."""
        def run() -> None:
            try:
                while True:
                    on_sample(channel.recv())
                    sample = channel.try_recv()
                    while sample is not None:
                        on_sample(sample)
                        sample = channel.try_recv()
            except zenoh.ZError:  # the channel is closed: undeclared, or the session closed
                return
        thread = threading.Thread(target=run, name=f"pairplay-take-{key_expr}", daemon=True)
        thread.start()
        return thread

    def on_router_link(self, callback: Callable[[bool, str], None]):
        """Call `callback(up, router_zid)` when this session's link to a router opens or closes
        (a restarted router: closed, then opened again). Runs on a Zenoh thread: must not wait."""
        def on_event(event) -> None:
            try:
                if str(event.transport.whatami).lower().endswith("router"):
                    callback(event.kind == zenoh.SampleKind.PUT, str(event.transport.zid))
            except Exception:
                log.exception("router link listener failed")
        return self._keep(self.session.info.declare_transport_events_listener(on_event))

    def queryable(self, key_expr: str, on_query: Callable[["Asked"], None]):
        """Hand each query on `key_expr` to `on_query` (as an `Asked`), which must not wait: it passes the
        query on (an Inbox's `control`), and the service answers it later with `answer`."""
        def handler(query: zenoh.Query) -> None:
            try:
                on_query(Asked(query, key_expr))
            except Exception:
                log.exception("queryable %s failed", key_expr)
        return self._keep(self.session.declare_queryable(key_expr, handler))

    @staticmethod
    def answer(query: "Asked | zenoh.Query", payloads: list[bytes]) -> None:
        """Reply `payloads` to `query`, on its queryable's own key (`Asked`): access control lets a host reply
        only on the keys of the sources it may answer for, and a question to every source (`_query/*/sent`)
        answered on its own wildcard key matched none (docs/examples/zenoh-tls-server.json5)."""
        key = query.answer_key if isinstance(query, Asked) else query.key_expr
        try:
            for payload in payloads:
                query.reply(key, payload)
        finally:
            query.drop()

    def query(self, selector: str, timeout_s: float = 2.0, stop: threading.Event | None = None,
              meanwhile: Callable[[], None] | None = None) -> list[bytes]:
        """Payloads of every ok reply to a query (`query_replies` without who sent them)."""
        return [payload for _, payload in self.query_replies(selector, timeout_s, stop, meanwhile)]

    def query_replies(self, selector: str, timeout_s: float = 2.0, stop: threading.Event | None = None,
                      meanwhile: Callable[[], None] | None = None, with_key: bool = False) -> list[tuple]:
        """(the ZenohId of the session that replied, payload) of every ok reply to a query (errors are logged,
        not raised); returns early, with what came, once `stop` is set. `meanwhile()`, if given, is called while
        no reply waits (it must return within milliseconds): a service that asks the recorder whether it holds
        its events answers the recorder's refill so (services/recorded.py). Who replied is what tells two
        answers for one source apart (services/answers.py). `with_key`: (replier, payload, the key the reply was
        sent on): the key a host may reply on is what access control limits (docs/examples), so it, not the
        payload's own words, says which source an answer may speak for."""
        out = []
        # no consolidation: a queryable may answer with many replies on one key
        replies = _get(self.session.get, selector, timeout=timeout_s,
                       consolidation=zenoh.QueryConsolidation(zenoh.ConsolidationMode.NONE))
        for reply in _replies(replies, timeout_s + 1.0, stop, meanwhile):
            if reply.ok is not None:
                replier = reply.replier_id
                who, payload = str(replier.zid) if replier is not None else "", reply.ok.payload.to_bytes()
                out.append((who, payload, str(reply.ok.key_expr)) if with_key else (who, payload))
            else:
                log.warning("query %s: error reply %s", selector, reply.err.payload.to_bytes()[:200])
        return out

    def release(self, declared) -> None:
        """Undeclare one declaration now (a queryable nobody will answer any more: a query to it would wait
        its whole timeout), not at the bus's close."""
        with self._lock:
            self._declared = [d for d in self._declared if d is not declared]
        _undeclare(declared)

    def alive(self, key: str):
        """Declare a liveliness token: others see this service while it runs."""
        return self._keep(self.session.liveliness().declare_token(key))

    def watch_alive(self, key_expr: str, callback: Callable[[str, bool], None]):
        """Call `callback(key, up)` when a liveliness token on `key_expr` appears (up) or goes (a
        service left the bus, or crashed: Zenoh drops a dead session's tokens with its link);
        tokens there already come first as appearing. Runs on a Zenoh thread: must not wait."""
        def on_token(sample: zenoh.Sample) -> None:
            try:
                callback(str(sample.key_expr), sample.kind == zenoh.SampleKind.PUT)
            except Exception:
                log.exception("liveliness watcher on %s failed", key_expr)
        return self._keep(self.session.liveliness().declare_subscriber(key_expr, on_token, history=True))

    def alive_now(self, key_expr: str, timeout_s: float = 1.0, stop: threading.Event | None = None) -> set[str]:
        """The liveliness tokens on `key_expr` now; returns early, with what came, once `stop` is set
        (a shutdown does not wait out the query)."""
        replies = _get(self.session.liveliness().get, key_expr, timeout=timeout_s)
        out: set[str] = set()
        for reply in _replies(replies, timeout_s + 0.5, stop):
            if reply.ok is not None:
                out.add(str(reply.ok.key_expr))
        return out

    def listening(self) -> str:
        """The endpoints it listens on as every verb says them: `(no listener)` for a client, which listens on none
        (a joined empty list printed `bus ` with nothing after it: `pairplay robot --connect`, trial34 J)."""
        return " ".join(self.locators()) or "(no listener)"

    def locators(self) -> list[str]:
        """The endpoints this session really listens on (ports chosen by the OS)."""
        zid = str(self.session.zid())
        for reply in _replies(_get(self.session.get, f"@/{zid}/*", timeout=2.0), 3.0, None):
            if reply.ok is None:
                continue
            try:
                info = json_loads(reply.ok.payload.to_bytes())
            except ValueError:
                continue
            if isinstance(info, dict) and "locators" in info:
                return [str(x) for x in info["locators"]]
        return []

    def close(self, timeout_s: float | None = None) -> bool:
        """Close the session; if Zenoh takes longer than `timeout_s` (default: CLOSE_TIMEOUT_S, or
        what the shutdown's deadline leaves once `stop` is set; a publish blocked on a peer that
        went away), leave the rest to the process exit. True if closed."""
        if timeout_s is None:
            timeout_s = shutdown_wait(self.stop, CLOSE_TIMEOUT_S)
        if not self._shut():
            return True
        if self._parent is not None:
            self._parent._forget(self)

        def close_all() -> None:
            self._undeclare_all()
            if self._parent is not None:
                return  # a scope: the session is its parent's
            try:
                self.session.close()
            except Exception as err:
                log.warning("closing the Zenoh session: %s", err)
        closer = threading.Thread(target=close_all, name="pairplay-bus-close", daemon=True)
        try:
            closer.start()
        except RuntimeError:  # out of threads (`ulimit -v`): closed here, unbounded, rather than left open (zenoh's
            close_all()       # subscriber threads are not daemons: an open session held the process's exit for ever)
            return True
        closer.join(timeout_s)
        if closer.is_alive():
            # INFO: nothing is lost (README's logging rule): the exit ends it; a default-level line after
            # an interrupted session's one summary line was noise
            log.info("the Zenoh session did not close within %.1f s; leaving it to the exit", timeout_s)
            return False
        return True

    def _shut(self) -> bool:
        """Refuse declarations and publishes from now on, this bus's and its scopes', and stop their
        Outboxes' threads (never waits); False if it was closed already."""
        with self._lock:
            if self._closed:
                return False
            self._closed = True
            scopes, outboxes = list(self._scopes), list(self._outboxes)
        for scope in scopes:
            scope._shut()
        for outbox in outboxes:
            outbox.stop()
        return True

    def _forget(self, scope: "Bus") -> None:
        with self._lock:
            if scope in self._scopes:
                self._scopes.remove(scope)

    def _undeclare_all(self) -> None:
        """Undeclare what was declared through this bus and its scopes (after `_shut`: nothing new comes)."""
        with self._lock:
            scopes, self._scopes = self._scopes, []
            declared, self._declared = self._declared, []
            publishers = list(self._publishers.values()) + list(self._batched.values()) + list(self._probes.values())
            self._publishers, self._batched, self._probes = {}, {}, {}
        for scope in scopes:
            scope._undeclare_all()
        for d in reversed(declared):
            _undeclare(d)
        for p in publishers:
            _undeclare(p)

    def __enter__(self) -> "Bus":
        return self

    def __exit__(self, *exc) -> None:
        self.close()


def _undeclare(declared) -> None:
    try:
        declared.undeclare()
    except Exception:  # already gone with its session
        pass


def _open(options: BusOptions) -> zenoh.Session:
    """zenoh.open, its refusals (a port in use, a TLS handshake refused, nothing listening in client
    mode) as a BusOpenError naming the options (one line for the user)."""
    _init_zenoh_log()
    config = options.to_zenoh()
    cfg = options.to_dict()
    exposed_to = exposed(cfg)
    if exposed_to:  # every verb's bus, in one line (services/zenohcheck.py)
        log.warning("the bus listens beyond loopback without TLS (%s): anyone on that network can read and write "
                    "the session; use tls/ endpoints (docs/bus.md, \"Security\")", " ".join(exposed_to))
    if scouted := scouting_beyond(cfg):  # UDP on every interface: multicast scouting opened it without a word
        log.warning("the bus scouts beyond loopback (%s): anyone on that network can find the session and "
                    "connect to it; turn scouting off, or use tls/ endpoints (docs/bus.md, \"Security\")",
                    "; ".join(scouted))
    try:
        return zenoh.open(config)
    except Exception as err:
        raise BusOpenError(f"cannot open the bus: {_zenoh_reason(err)}", options.where()) from None


class Asked:
    """A query as a service gets it (Bus.queryable): Zenoh's Query, and the key it is answered on
    (`answer_key`: the queryable's, concrete, of the one source it answers for)."""
    __slots__ = ("query", "answer_key")

    def __init__(self, query: zenoh.Query, answer_key: str):
        self.query, self.answer_key = query, answer_key

    def __getattr__(self, name: str):
        return getattr(self.query, name)


def open_bus(options: BusOptions | None = None, stop: threading.Event | None = None) -> Bus:
    return Bus(options, stop=stop)


_DONE = object()  # the last item of a get's replies (_get): Zenoh dropped its callback, every reply came


def _get(start: Callable[..., Any], *args: Any, **kwargs: Any) -> queue.SimpleQueue:
    """Start a Zenoh get (`start`: a session's or its liveliness's `get`) whose replies Zenoh's thread
    puts in a queue of ours, `_DONE` last. A queue, not Zenoh's FifoChannel: a reader that stops early
    (a shutdown's `stop`, `locators` once it has its answer) dropped the channel while the query went on,
    and each reply after that was Zenoh's ERROR "sending on a closed channel" (its log, on stdout: an
    interrupted session's stdout held it). Nothing can close this queue; what comes after the reader
    went is dropped with it. The callback only puts, which never waits; it runs on zenoh-python's thread
    for the get (indirect, as every callback of ours: a direct one makes Zenoh's network thread wait for
    the GIL, docs/bus.md "Tried and not kept"), which holds Zenoh's end until the query is over."""
    replies: queue.SimpleQueue = queue.SimpleQueue()
    start(*args, handler=zenoh.handlers.Callback(replies.put, lambda: replies.put(_DONE)), **kwargs)
    return replies


def _replies(replies: queue.SimpleQueue, wait_s: float, stop: threading.Event | None,
             meanwhile: Callable[[], None] | None = None):
    """The replies of a get (`_get`) as they come, for at most `wait_s` seconds, until every reply
    came or `stop` is set (a shutdown does not wait out a query); `meanwhile()` called while none waits."""
    deadline = time.monotonic() + wait_s
    while not (stop is not None and stop.is_set()):
        left = deadline - time.monotonic()
        if left <= 0:
            return
        try:
            if meanwhile is not None:
                reply = replies.get_nowait()
            else:
                reply = replies.get(timeout=min(left, 0.002 if stop is not None else left))
        except queue.Empty:
            if meanwhile is not None:
                meanwhile()
            continue
        if reply is _DONE:
            return
        yield reply


def stop_on_signals(stop: threading.Event, then: Callable[[], object] | None = None,
                    now: Callable[[], object] | None = None) -> None:
    """SIGINT/SIGTERM set `stop`, name the signal in `stop.why` and start the shutdown's
    `stop.deadline` (a second SIGINT or SIGTERM interrupts: KeyboardInterrupt); then
    call `then()` (it must only set flags). `stop` is set and `then` called by a thread started from the handler: a handler
    runs on the main thread between two of its bytecodes, possibly while that thread holds the
    lock of the Event it waits on. Main thread only.

    What the verb reads to say what a signal did is decided in the handler itself, never by that thread: `stop.why`
    (`signal_taken`), and `now()`, called in the handler before the thread starts, which may only assign attributes
    (no lock, no Event). The thread may run late on a loaded machine, after a second signal's KeyboardInterrupt has
    reached the verb: `protocol pilot` read `stop.is_set()` and the stopped game that `then` set, found neither, and
    said "nothing more was written" of the game it cut (once at load 5.4; tests/test_protocol_cut_game.py and
    tests/test_cut_signals.py hold the thread at `signal-stopping` to land the second signal there)."""
    def handler(signum, frame):
        # a signal taken already (its name in `why`), not a stop set by the work's own end: the first Ctrl-C
        # as a session finished its file was read as a second one and the file left cut (a new user's trial)
        taken = bool(getattr(stop, "why", ""))
        if taken:  # a second signal: a wait that a second one cuts ends on SIGTERM too (signals.wait_cut)
            signals.again = signals.again or signum
        if taken:  # a second SIGINT or SIGTERM cuts the shutdown (a second SIGTERM was heard only in wait_cut)
            if signals.in_finalizer(frame):  # raised there it would be swallowed (pairplay/signals.py)
                signals.deliver_again(signum)
                return
            raise KeyboardInterrupt
        global signalled
        signalled = signal.Signals(signum).name  # the exit skips the interpreter's teardown (cli/main.py)
        signals.stopping = signals.stopping or signum  # a wait that is not on `stop` ends too (folderlock)
        if taken:
            return
        stop.why = signal.Signals(signum).name  # what ended the session, for its SessionEnded
        deadline_of(stop)  # the shutdown's time starts now, not when a thread notices
        if now is not None:  # (plain attributes: what was running as the signal came, decided here; see the rule)
            now()
        # Setting an Event takes its lock, which the main thread holds for a moment inside `stop.wait()`
        # (or any Event's wait): from the handler, running on that thread, the set waited for ever (a
        # router froze on SIGTERM, 1 of ~10 runs of test_cli_signals). So a thread of its own sets the
        # flags; `stop.why` and the deadline above are plain attributes, there at once.
        _thread.start_new_thread(_stop_now, (stop, then, signum))
    signals.handle(handler)  # not over an ignored signal: it stays ignored (pairplay/signals.py)
    # A signal that came before this handler replaced the command's own (cli/interrupts.py; read through
    # sys.modules: services do not import cli) stops at once: its KeyboardInterrupt may have been lost.
    pending = getattr(sys.modules.get("pairplay.cli.interrupts"), "received", 0)
    if pending and not getattr(stop, "why", ""):
        handler(pending, None)


def _stop_now(stop: threading.Event, then: Callable[[], object] | None, signum: int) -> None:
    """stop_on_signals' work that takes locks, off the signal handler's thread."""
    testpause.pause("signal-stopping")  # (a test holds this thread here: a loaded machine runs it late)
    log.info("signal %s: stopping", signal.Signals(signum).name)
    stop.set()
    if then is not None:
        then()
