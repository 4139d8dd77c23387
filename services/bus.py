"""The bus: Zenoh sessions configured from one place, BLOCK publishers, clean exit.

Rule: every pairplay process opens its Zenoh session through `open_bus(options)`.
The embedded default needs no server and no network: peer mode, listening on
`tcp/127.0.0.1:0` (the OS picks a free port, so two runs never clash; the real
port is read back from Zenoh's admin space, `Bus.locators()`), multicast
scouting and gossip off (nothing leaves loopback), scouting delay 100 ms.
Several processes or hosts: one process is the router (`pairplay session` is
one: it listens on loopback, or `--listen tcp/0.0.0.0:7447` for other hosts),
the others are its clients (`--connect tcp/<host>:<port>` makes a process a
client): Zenoh forwards between a router's clients, not between peers that
only share a third peer (measured: not forwarded). TLS, access
control and anything else Zenoh knows come from a Zenoh config file
(`--zenoh-config`), passed through untouched except for the options given on
the command line. Every publisher is declared with congestion control BLOCK:
Zenoh's default, DROP, silently lost 72-95% of events between processes under
load (LIBRARY-NOTES). SIGINT and SIGTERM set a stop flag; services then close
their session and the recorder finishes its file.
"""

from __future__ import annotations

import argparse
import json
import logging
import signal
import threading
from dataclasses import dataclass, field
from typing import Callable

import zenoh

from pairplay.errors import UserError

log = logging.getLogger("pairplay.bus")
LOOPBACK_ANY_PORT = "tcp/127.0.0.1:0"
MODES = ("peer", "client", "router")


class BusError(UserError):
    """The bus cannot be opened as configured: a malformed or unusable --listen/--connect
    endpoint, a port in use, a peer that refuses, a missing or invalid --zenoh-config."""


def _zenoh_reason(err: Exception) -> str:
    """Zenoh's message without the Rust source location it ends with."""
    text = " ".join(str(err).split())
    cut = text.find(" at /")
    return (text[:cut] if cut > 0 else text).rstrip(" .!") or type(err).__name__


@dataclass
class BusOptions:
    mode: str = "peer"
    listen: list[str] | None = None  # None: the mode's default (peer/router: loopback, any port)
    connect: list[str] = field(default_factory=list)
    zenoh_config: str | None = None  # a Zenoh JSON5 config file: TLS, access control, ...
    scouting_delay_ms: int = 100

    def where(self) -> str:
        """The options a failure to open the bus is about, as given on the command line."""
        parts = [f"--zenoh-config {self.zenoh_config}"] if self.zenoh_config else []
        parts += [f"--listen {e}" for e in self.listen or []] + [f"--connect {e}" for e in self.connect]
        return ", ".join(parts) or f"mode {self.mode}, listening on {LOOPBACK_ANY_PORT}"

    def to_zenoh(self) -> zenoh.Config:
        """The Zenoh config: the file (if any) with our options laid over it; BusError if it cannot be made."""
        if self.mode not in MODES:
            raise BusError(f"bus mode {self.mode!r} is not one of {MODES}", "--mode")
        if self.zenoh_config:
            try:
                config = zenoh.Config.from_file(self.zenoh_config)
            except zenoh.ZError as err:
                raise BusError(f"cannot use the Zenoh config: {_zenoh_reason(err)}",
                               f"--zenoh-config {self.zenoh_config}") from None
        else:
            config = None
        try:
            return self._zenoh_config(config)
        except zenoh.ZError as err:
            raise BusError(f"bad bus endpoint: {_zenoh_reason(err)}", self.where()) from None

    def _zenoh_config(self, config: zenoh.Config | None) -> zenoh.Config:
        if config is not None:
            config.insert_json5("mode", json.dumps(self.mode))
            if self.listen is not None:
                config.insert_json5("listen/endpoints", json.dumps(self.listen))
            if self.connect:
                config.insert_json5("connect/endpoints", json.dumps(self.connect))
            config.insert_json5("adminspace/enabled", "true")
            return config
        listen = self.listen if self.listen is not None else ([] if self.mode == "client" else [LOOPBACK_ANY_PORT])
        return zenoh.Config.from_json5(json.dumps({
            "mode": self.mode,
            "listen": {"endpoints": listen},
            "connect": {"endpoints": list(self.connect)},
            "scouting": {"multicast": {"enabled": False}, "gossip": {"enabled": False},
                         "delay": self.scouting_delay_ms},
            "adminspace": {"enabled": True},
        }))


def add_bus_arguments(parser: argparse.ArgumentParser) -> None:
    g = parser.add_argument_group("bus (Zenoh)")
    g.add_argument("--mode", choices=MODES, default=None,
                   help="Zenoh mode (default: client with --connect, else the verb's own: a session is a router, "
                        "anything else a peer)")
    g.add_argument("--listen", action="append", metavar="ENDPOINT",
                   help=f"endpoint to listen on, repeatable (default {LOOPBACK_ANY_PORT}: a free port)")
    g.add_argument("--connect", action="append", default=[], metavar="ENDPOINT",
                   help="endpoint to connect to, e.g. tcp/127.0.0.1:7447 (repeatable)")
    g.add_argument("--zenoh-config", metavar="FILE", help="Zenoh JSON5 config (TLS, access control), passed through")


def options_from_args(args: argparse.Namespace, default_mode: str = "peer") -> BusOptions:
    """Bus options of a command line. Without --mode, a process that connects somewhere
    is a client (Zenoh forwards between the clients of a router, not between peers
    that only share a third peer), and one that does not is `default_mode`."""
    mode = args.mode or ("client" if args.connect else default_mode)
    return BusOptions(mode=mode, listen=args.listen, connect=list(args.connect or []), zenoh_config=args.zenoh_config)


class Bus:
    """One Zenoh session with cached BLOCK publishers."""

    def __init__(self, options: BusOptions | None = None, session: zenoh.Session | None = None,
                 express: bool = True):
        self.options = options or BusOptions()
        # express: each event leaves at once instead of waiting to be batched with others
        # (an event is a decision someone waits for; throughput stays BLOCK-safe either way)
        self.express = express
        self.session = session if session is not None else _open(self.options)
        self._publishers: dict[str, zenoh.Publisher] = {}
        self._lock = threading.Lock()
        self._declared: list = []
        self._closed = False

    def publisher(self, key: str) -> zenoh.Publisher:
        pub = self._publishers.get(key)
        if pub is None:
            with self._lock:
                pub = self._publishers.get(key)
                if pub is None:
                    pub = self.session.declare_publisher(key, congestion_control=zenoh.CongestionControl.BLOCK,
                                                         express=self.express)
                    self._publishers[key] = pub
        return pub

    def put(self, key: str, payload: bytes) -> None:
        self.publisher(key).put(payload)

    def subscribe(self, key_expr: str, callback: Callable[[str, bytes], None]):
        """Call `callback(key, payload)` for every sample (callbacks must not raise)."""
        def on_sample(sample: zenoh.Sample) -> None:
            try:
                callback(str(sample.key_expr), sample.payload.to_bytes())
            except Exception:  # Zenoh only logs callback errors; say where it came from
                log.exception("subscriber callback on %s failed", sample.key_expr)
        sub = self.session.declare_subscriber(key_expr, on_sample)
        self._declared.append(sub)
        return sub

    def queryable(self, key_expr: str, answer: Callable[[str], list[bytes]]):
        """Answer each query on `key_expr` with the payloads `answer(selector_params)` returns."""
        def on_query(query: zenoh.Query) -> None:
            try:
                for payload in answer(str(query.parameters)):
                    query.reply(query.key_expr, payload)
            except Exception as err:
                log.exception("queryable %s failed", key_expr)
                query.reply_err(f"{type(err).__name__}: {err}")
        q = self.session.declare_queryable(key_expr, on_query)
        self._declared.append(q)
        return q

    def query(self, selector: str, timeout_s: float = 2.0) -> list[bytes]:
        """Payloads of every ok reply to a query (errors are logged, not raised)."""
        out = []
        # no consolidation: a queryable may answer with many replies on one key
        for reply in self.session.get(selector, timeout=timeout_s,
                                      consolidation=zenoh.QueryConsolidation(zenoh.ConsolidationMode.NONE)):
            if reply.ok is not None:
                out.append(reply.ok.payload.to_bytes())
            else:
                log.warning("query %s: error reply %s", selector, reply.err.payload.to_bytes()[:200])
        return out

    def alive(self, key: str):
        """Declare a liveliness token: others see this service while it runs."""
        token = self.session.liveliness().declare_token(key)
        self._declared.append(token)
        return token

    def alive_now(self, key_expr: str, timeout_s: float = 1.0) -> set[str]:
        return {str(r.ok.key_expr) for r in self.session.liveliness().get(key_expr, timeout=timeout_s)
                if r.ok is not None}

    def locators(self) -> list[str]:
        """The endpoints this session really listens on (ports chosen by the OS)."""
        zid = str(self.session.zid())
        for reply in self.session.get(f"@/{zid}/*", timeout=2.0):
            if reply.ok is None:
                continue
            try:
                info = json.loads(reply.ok.payload.to_bytes())
            except ValueError:
                continue
            if isinstance(info, dict) and "locators" in info:
                return [str(x) for x in info["locators"]]
        return []

    def close(self) -> None:
        if self._closed:
            return
        self._closed = True
        for d in reversed(self._declared):
            try:
                d.undeclare()
            except Exception:  # already gone with its session
                pass
        for p in self._publishers.values():
            try:
                p.undeclare()
            except Exception:
                pass
        self.session.close()

    def __enter__(self) -> "Bus":
        return self

    def __exit__(self, *exc) -> None:
        self.close()


def _open(options: BusOptions) -> zenoh.Session:
    """zenoh.open, its refusals as a BusError naming the options (one line for the user)."""
    config = options.to_zenoh()
    try:
        return zenoh.open(config)
    except zenoh.ZError as err:
        raise BusError(f"cannot open the bus: {_zenoh_reason(err)}", options.where()) from None


def open_bus(options: BusOptions | None = None) -> Bus:
    return Bus(options)


def stop_on_signals(stop: threading.Event) -> None:
    """SIGINT/SIGTERM set `stop` and name the signal in `stop.why` (a second SIGINT still interrupts).
    Main thread only."""
    def handler(signum, frame):
        if stop.is_set() and signum == signal.SIGINT:
            raise KeyboardInterrupt
        log.info("signal %s: stopping", signal.Signals(signum).name)
        if not stop.is_set():
            stop.why = signal.Signals(signum).name  # what ended the session, for its SessionEnded
        stop.set()
    signal.signal(signal.SIGINT, handler)
    signal.signal(signal.SIGTERM, handler)
