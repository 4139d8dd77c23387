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
"""

from __future__ import annotations

import logging

from starlette.types import ASGIApp, Message, Receive, Scope, Send

from pairplay.numbers import counted

log = logging.getLogger("pairplay.lab")
MAX_BODY = 64 * 1024  # bytes: every body the lab takes is a small JSON object (a console request, the answers)


class BodyLimit:
    def __init__(self, app: ASGIApp, limit: int = MAX_BODY):
        self.app, self.limit = app, limit

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] != "http":
            return await self.app(scope, receive, send)
        length = dict(scope["headers"]).get(b"content-length")
        if length is not None and (not length.isdigit() or int(length) > self.limit):
            return await self.refuse(scope, send, f"a body of {length[:24].decode('latin-1')!r} bytes")
        parts, size = [], 0
        while True:  # read here, the whole body at most `limit` bytes, so that no route holds more
            message = await receive()
            if message["type"] != "http.request":  # the client went away: nothing to answer
                return
            part = message.get("body", b"")
            size += len(part)
            if size > self.limit:
                return await self.refuse(scope, send, f"a body of more than {counted(self.limit, 'byte')} (sent without a length)")
            parts.append(part)
            if not message.get("more_body", False):
                break
        body = b"".join(parts)
        given = False

        async def replay() -> Message:
            nonlocal given
            if not given:
                given = True
                return {"type": "http.request", "body": body, "more_body": False}
            return await receive()  # after the body: the disconnect, as uvicorn says it

        await self.app(scope, replay, send)

    async def refuse(self, scope: Scope, send: Send, what: str) -> None:
        client, path = (scope.get("client") or ("?", 0))[0], scope.get("path", "?")
        log.warning("refused %s to %s from %s: the limit is %d bytes", what, path, client, self.limit)
        lab = getattr(getattr(scope.get("app"), "state", None), "lab", None)  # Starlette puts itself in the scope
        for hub in list(getattr(lab, "hubs", {}).values()):
            hub.record_refusal(f"HTTP request refused: {what}, the limit is {self.limit}", f"http{path[:64]}",
                               str(client))
        text = f'{{"error":"request too large: the limit is {counted(self.limit, "byte")}"}}'.encode()
        await send({"type": "http.response.start", "status": 413,
                    "headers": [(b"content-type", b"application/json"), (b"content-length", str(len(text)).encode()),
                                (b"connection", b"close")]})
        await send({"type": "http.response.body", "body": text})
