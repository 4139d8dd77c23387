"""The lab's ASGI app: route groups from the page modules, the static files, the sessions.

Rule: `create_app(lab)` builds a Starlette app from `PAGES` (modules with a
`routes()` function) plus `/static`; the sessions it serves are `lab.hubs`
(session id -> LabHub), so a page reaches a session only through its id and
its token (`Lab.hub_for`). A request body above 64 KiB is refused before any
route reads it (`bodylimit.BodyLimit`). Responses carry no-store and a same-origin content
security policy: pages load nothing from elsewhere.
"""

from __future__ import annotations

from pathlib import Path

from starlette.applications import Starlette
from starlette.middleware import Middleware
from starlette.responses import Response
from starlette.routing import Mount, Route
from starlette.staticfiles import StaticFiles
from starlette.types import ASGIApp, Receive, Scope, Send

from pairplay.services.lab import board, mirror
from pairplay.services.lab.bodylimit import BodyLimit
from pairplay.services.lab.hub import LabHub

STATIC = Path(__file__).resolve().parent / "static"
PAGES = (board, mirror)  # each: routes() -> list of Starlette routes
CSP = b"default-src 'self'; connect-src 'self'; img-src 'self' data:; style-src 'self'; script-src 'self'"


class Lab:
    """The sessions one lab server serves."""

    def __init__(self, hubs: dict[str, LabHub] | None = None):
        self.hubs: dict[str, LabHub] = dict(hubs or {})

    def add(self, hub: LabHub) -> LabHub:
        self.hubs[hub.session] = hub
        return hub

    def hub_for(self, session: str, token: str) -> LabHub | None:
        """The session's hub if `token` is its token, else None (unknown session or wrong token)."""
        hub = self.hubs.get(session)
        return hub if hub is not None and hub.token_ok(token) else None


class SecurityHeaders:
    """no-store (a page always shows the live state) and the content security policy."""

    def __init__(self, app: ASGIApp):
        self.app = app

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] != "http":
            return await self.app(scope, receive, send)

        async def send_with_headers(message):
            if message["type"] == "http.response.start":
                message.setdefault("headers", [])
                message["headers"] = list(message["headers"]) + [
                    (b"cache-control", b"no-store"), (b"content-security-policy", CSP),
                    (b"x-content-type-options", b"nosniff"), (b"referrer-policy", b"no-referrer")]
            await send(message)

        await self.app(scope, receive, send_with_headers)


def create_app(lab: Lab, pages=PAGES) -> Starlette:
    routes = [r for page in pages for r in page.routes()]
    routes.append(Mount("/static", StaticFiles(directory=STATIC), name="static"))
    routes.append(Route("/favicon.ico", lambda request: Response(status_code=204)))  # browsers ask; nothing to show
    app = Starlette(routes=routes, middleware=[Middleware(SecurityHeaders), Middleware(BodyLimit)])
    app.state.lab = lab
    return app
