"""The lab server's log lines: one line for a burst from a client, not one a connection; uvicorn's own lines in ours.

Rule: a line the lab server says for each connection or request of a client (a head not sent whole in time, a
request that is not HTTP, a body refused) goes through `bursts.said`: the first of its kind from a client is
said at once; the next ones from that client are counted, and said in one line ("closed 199 more connections
from 127.0.0.1 that sent no whole request head within 10 s") once the client has sent none for QUIET_S, or
every EVERY_S while they go on. What is counted when the server stops is said then (`flush`, from
server.WebServer.stop): nothing is lost, its count is said. Before (trial32 H) 300 idle connections printed 201
lines on `protocol serve`'s terminal. What a request leaves in a recording (bodylimit.py: a MessageRejected
each) is not this module's: that stays one a request.

uvicorn's own loggers: the web server is started with `log_config=None` (server.py), so uvicorn installs no
handler of its own (its default printed "WARNING:  Invalid HTTP request received.", its format and its words,
beside ours), and `quiet_uvicorn` puts `UvicornLines` on its loggers: each record is said again by
"pairplay.lab" in our words, through the command's handler (its -q/-v), or dropped when the lab's protocol
says it itself with its client (deadlines.DeadlineH11: an invalid request, an upgrade it does not serve).
"""

from __future__ import annotations

import asyncio
import logging
import threading
import time
from dataclasses import dataclass
from typing import Callable

log = logging.getLogger("pairplay.lab")
QUIET_S = 2.0  # a client that sent nothing of the kind for this long: its burst is over, its count said
EVERY_S = 30.0  # a burst that goes on: its count said this often
UVICORN_LOGGERS = ("uvicorn", "uvicorn.error", "uvicorn.asgi", "uvicorn.access")
# uvicorn's lines that DeadlineH11 says itself, with the client (uvicorn's words name none)
SAID_BY_US = frozenset({"Invalid HTTP request received.", "Unsupported upgrade request."})
# the other lines of uvicorn's that a lab server can meet, in our words
WORDS = {
    "Exception in ASGI application": "a request failed inside the lab server, answered 500 (a fault of pairplay's)",
    "ASGI callable returned without sending handshake.": "a WebSocket was closed before its handshake",
    "ASGI callable returned without completing handshake.": "a WebSocket was closed before its handshake",
}


@dataclass
class _Burst:
    more: Callable[[int], str]  # the line for n more of the kind
    since: float  # when the burst began, or its count was last said
    last: float  # the last one's time
    count: int = 0  # not said yet


class Bursts:
    """Lines of a kind from a client, coalesced (module rule). `said` is called in an event loop's thread;
    `flush` from any thread."""

    def __init__(self, logger: logging.Logger, quiet_s: float = QUIET_S, every_s: float = EVERY_S):
        self.log, self.quiet_s, self.every_s = logger, quiet_s, every_s
        self._lock = threading.Lock()  # `flush` comes from the thread that stops the server
        self._open: dict[tuple, _Burst] = {}

    def said(self, loop: asyncio.AbstractEventLoop, key: tuple, first: str, more: Callable[[int], str]) -> None:
        """`first` now when no burst of `key` (a kind and a client) is open; else counted, said by `more(n)`."""
        now = time.monotonic()
        with self._lock:
            burst = self._open.get(key)
            if burst is not None:
                burst.count += 1
                burst.last = now
                return
            self._open[key] = _Burst(more, now, now)
        self.log.warning("%s", first)
        loop.call_later(self.quiet_s, self._due, loop, key)

    def _due(self, loop: asyncio.AbstractEventLoop, key: tuple) -> None:
        """The burst's count said when the client has gone quiet or EVERY_S have passed; over when quiet."""
        now = time.monotonic()
        with self._lock:
            burst = self._open.get(key)
            if burst is None:  # flushed (the server stopped)
                return
            quiet = now - burst.last >= self.quiet_s
            text = ""
            if burst.count and (quiet or now - burst.since >= self.every_s):
                text, burst.count, burst.since = burst.more(burst.count), 0, now
            if quiet:
                del self._open[key]
        if text:
            self.log.warning("%s", text)
        if not quiet:
            loop.call_later(min(burst.last + self.quiet_s, burst.since + self.every_s) - now, self._due, loop, key)

    def flush(self) -> None:
        """Say every count not said yet, and close every burst (the server stops: its timers will not run)."""
        with self._lock:
            left = [b.more(b.count) for b in self._open.values() if b.count]
            self._open.clear()
        for text in left:
            self.log.warning("%s", text)


bursts = Bursts(log)  # one for the process, as the connection cap's count (deadlines.DeadlineH11) is


class UvicornLines(logging.Filter):
    """Hands a uvicorn record to "pairplay.lab" in our words (module rule); uvicorn's own handlers see none."""

    def filter(self, record: logging.LogRecord) -> bool:
        message = record.getMessage().strip()
        if message not in SAID_BY_US:
            words = WORDS.get(message, f"the web server (uvicorn) says: {message}")
            log.log(record.levelno, "%s", words, exc_info=record.exc_info)  # a fault's traceback is kept
        return False


_lines = UvicornLines()


def quiet_uvicorn() -> None:
    """Route uvicorn's loggers through `UvicornLines` (once: a filter is added to a logger once)."""
    for name in UVICORN_LOGGERS:
        logging.getLogger(name).addFilter(_lines)
