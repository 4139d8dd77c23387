"""The lab server's one limit on a request body, before any route or token check.

Rule: a request whose Content-Length is above MAX_BODY is answered 413 at once,
its body unread; a body sent without a length (chunked) is read as it comes and
answered 413 as soon as it passes MAX_BODY. Either way the connection is closed
("connection: close": nothing more of that body is read) and the refusal is
logged with the client and the path, and recorded (a MessageRejected) in the
recording of every session the lab serves then. What a route reads is the body this
middleware read, at most MAX_BODY bytes. Before (trial28 F13) the console read
a body whole and compared its length after: an 800 MB POST took the lab server
from 130 MB to 1.43 GB, on a route that needs no token.
WebSocket messages have their own limit (hub.MAX_FRAME, uvicorn's ws_max_size).

A body must also come whole within deadlines.READ_S of its request's head: one
still coming then is answered 408, the connection closed, logged and recorded
the same way (trial29 F11: a request that sent its headers and 100 bytes of a
60,000-byte body, then nothing, was held for ever; 900 of them were). The
request's head has the same deadline (deadlines.DeadlineH11). The log says the
first refusal from a client at once and counts the rest of its burst
(serverlog.py); each is recorded.
"""

from __future__ import annotations

import asyncio

import msgspec

from starlette.types import ASGIApp, Message, Receive, Scope, Send

from pairplay.numbers import counted
from pairplay.services.lab.deadlines import READ_S
from pairplay.services.lab.serverlog import bursts

MAX_BODY = 64 * 1024  # bytes: every body the lab takes is a small JSON object (a console request, the answers)


class BodyLimit:
    def __init__(self, app: ASGIApp, limit: int = MAX_BODY, read_s: float = READ_S):
        self.app, self.limit, self.read_s = app, limit, read_s

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] != "http":
            return await self.app(scope, receive, send)
        length = dict(scope["headers"]).get(b"content-length")
        if length is not None and (not length.isdigit() or int(length) > self.limit):
            return await self.refuse(scope, send, f"a body of {length[:24].decode('latin-1')!r} bytes")
        parts: list[bytes] = []
        try:
            async with asyncio.timeout(self.read_s):
                whole = await self._read(receive, parts)
        except TimeoutError:  # the refusal is sent outside the deadline's scope: it must not be cut by it
            return await self.refuse(scope, send, f"a body not sent whole within {self.read_s:g} s", status=408,
                                     error=f"request too slow: a body must come whole within {self.read_s:g} s")
        if whole is None:  # the client went away: nothing to answer
            return
        if not whole:
            return await self.refuse(scope, send, f"a body of more than {counted(self.limit, 'byte')} (sent without a length)")
        body = b"".join(parts)
        given = False

        async def replay() -> Message:
            nonlocal given
            if not given:
                given = True
                return {"type": "http.request", "body": body, "more_body": False}
            return await receive()  # after the body: the disconnect, as uvicorn says it

        await self.app(scope, replay, send)

    async def _read(self, receive: Receive, parts: list[bytes]) -> bool | None:
        """Read the whole body into `parts`, at most `limit` bytes, so that no route holds more: True when
        whole, False when it passed the limit, None when the client went away."""
        size = 0
        while True:
            message = await receive()
            if message["type"] != "http.request":
                return None
            part = message.get("body", b"")
            size += len(part)
            if size > self.limit:
                return False
            parts.append(part)
            if not message.get("more_body", False):
                return True

    async def refuse(self, scope: Scope, send: Send, what: str, status: int = 413, error: str = "") -> None:
        client, path = (scope.get("client") or ("?", 0))[0], scope.get("path", "?")
        limit = counted(self.limit, "byte") if status == 413 else f"{self.read_s:g} s"
        # the terminal's line, one for a burst from the client (serverlog.py); the recordings' below, one a request
        why = f"over the limit of {limit}" if status == 413 else f"not sent whole within {limit}"
        bursts.said(asyncio.get_running_loop(), ("body", status, client),
                    f"refused {what} to {path} from {client}: the limit is {limit}",
                    lambda n: f"refused {counted(n, 'more request body', 'more request bodies')} from {client} {why}")
        lab = getattr(getattr(scope.get("app"), "state", None), "lab", None)  # Starlette puts itself in the scope
        for hub in list(getattr(lab, "hubs", {}).values()):
            # the recorded line names the limit as a number of bytes, as before (readers may match it)
            hub.record_refusal(f"HTTP request refused: {what}, the limit is {self.limit if status == 413 else limit}",
                               f"http{path[:64]}", str(client))
        error = error or f"request too large: the limit is {counted(self.limit, 'byte')}"
        text = msgspec.json.encode({"error": error})
        await send({"type": "http.response.start", "status": status,
                    "headers": [(b"content-type", b"application/json"), (b"content-length", str(len(text)).encode()),
                                (b"connection", b"close")]})
        await send({"type": "http.response.body", "body": text})
