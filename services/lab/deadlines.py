"""The lab server's HTTP connections: a deadline for a request's head, and a cap on how many are open.

Rule: a connection that has not sent a whole request head (request line and
headers) within READ_S of connecting, or of its last response, is answered 408
and closed; a request's body has its own deadline (bodylimit.BodyLimit, the
same READ_S). At most MAX_CONNECTIONS connections (HTTP and WebSocket) are open:
one more is closed as soon as it is accepted, before it is read. Before (trial29
F11) uvicorn held a half-sent request for ever: 900 connections each holding
headers and 100 bytes of a 60,000-byte body were all open 20 s later, and from
beyond loopback a host could hold sockets up to the process's fd limit, which
the study's bus and recording share.

Sizes, for a lab: a few pages (console, board, mirror, questionnaire, a
read-only tab or two), each browser using at most 6 connections to one host,
stay under 60 connections; 200 leaves room and stays far below the usual fd
limit of 1024. READ_S: a console request or a questionnaire's answer is a few
hundred bytes (64 KiB at most), sent in milliseconds on a lab network; 10 s is
a slow Wi-Fi's many times over. uvicorn's own `limit_concurrency` is not the
cap: it answers 503 only once a request head has come, so connections that
send nothing are never counted out. This is uvicorn's h11 protocol with those
two rules added (its `http` option takes a protocol class).

Its lines: the cap is said once when reached and once when left; a head
timed out, a request that is not HTTP (answered 400) and an upgrade to a
protocol it does not serve are said for each client in bursts (serverlog.py:
the first at once, the rest counted), with the client: uvicorn's own words for
the last two name none and are dropped (serverlog.UvicornLines).
"""

from __future__ import annotations

import logging

import h11
from uvicorn.protocols.http.h11_impl import H11Protocol

from pairplay.numbers import counted
from pairplay.services.lab.serverlog import bursts

log = logging.getLogger("pairplay.lab")
READ_S = 10.0  # seconds for a request's head, and (bodylimit.py) for its body
MAX_CONNECTIONS = 200
# a request head never came, so there is no request for h11 to answer: the bytes are written as they are
TIMED_OUT = b"HTTP/1.1 408 Request Timeout\r\ncontent-length: 0\r\nconnection: close\r\n\r\n"


class DeadlineH11(H11Protocol):
    """uvicorn's h11 protocol with the module's head deadline and connection cap."""

    full = False  # the cap was reached: said once when reached, once when left (not one line a connection)
    turned_away = 0

    def connection_made(self, transport) -> None:
        super().connection_made(transport)
        cls = DeadlineH11
        if len(self.connections) > MAX_CONNECTIONS:
            if not cls.full:
                cls.full = True
                log.warning("the lab server holds %d connections, its cap: new ones are closed until one ends",
                            MAX_CONNECTIONS)
            cls.turned_away += 1
            transport.abort()  # nothing read, nothing answered (connection_lost takes it out of the count)
            return
        self._arm()

    def connection_lost(self, exc) -> None:
        super().connection_lost(exc)
        self._disarm()
        cls = DeadlineH11
        if cls.full and len(self.connections) < MAX_CONNECTIONS:
            cls.full = False
            log.warning("the lab server takes connections again (%d turned away at its cap of %d)",
                        cls.turned_away, MAX_CONNECTIONS)
            cls.turned_away = 0

    def on_response_complete(self) -> None:
        super().on_response_complete()
        if not self.transport.is_closing():  # kept alive: the next request's head has READ_S too
            self._arm()

    def _arm(self) -> None:
        self._disarm()
        self._head_timer = self.loop.call_later(READ_S, self._head_late, self.cycle)

    def _disarm(self) -> None:
        timer = getattr(self, "_head_timer", None)
        if timer is not None:
            timer.cancel()
            self._head_timer = None

    def _head_late(self, cycle) -> None:
        """READ_S after arming: late if no request head came since (the same cycle, h11 still waiting for one).
        A connection that became a WebSocket is no longer this protocol's."""
        self._head_timer = None
        if self.transport.is_closing() or self.transport.get_protocol() is not self:
            return
        if self.cycle is cycle and self.conn.their_state is h11.IDLE:
            client = self._client()
            bursts.said(self.loop, ("no head", client),
                        f"closed a connection from {client}: no whole request head within {READ_S:g} s",
                        lambda n: f"closed {counted(n, 'more connection')} from {client} that sent no whole request "
                                  f"head within {READ_S:g} s")
            self.transport.write(TIMED_OUT)
            self.transport.close()

    def send_400_response(self, msg: str) -> None:
        """uvicorn's answer to a request h11 cannot read (not HTTP, or a head past its 16 KiB), said with the
        client (uvicorn's own line, without it, is dropped: serverlog.SAID_BY_US)."""
        client = self._client()
        bursts.said(self.loop, ("not http", client),
                    f"answered 400 to a request from {client}: not HTTP, or a head over 16 KiB",
                    lambda n: f"answered 400 to {counted(n, 'more request')} from {client} that were not HTTP, "
                              "or had a head over 16 KiB")
        super().send_400_response(msg)

    def _unsupported_upgrade_warning(self) -> None:
        """A request asking for a protocol other than WebSocket (h2c...): answered as plain HTTP, said with the
        client (uvicorn's private hook: on a uvicorn without it, its own line is said in ours)."""
        client = self._client()
        bursts.said(self.loop, ("upgrade", client),
                    f"a request from {client} asked to upgrade to a protocol the lab server does not serve: "
                    "answered as plain HTTP",
                    lambda n: f"{counted(n, 'more request')} from {client} asked to upgrade to a protocol the lab "
                              "server does not serve: answered as plain HTTP")

    def _client(self) -> str:
        return str((self.client or ("?",))[0])
