"""Routes of the participant's board: the page, and the WebSocket every lab page talks through.

Rule: `/s/<session>/board?t=<token>` is the touch screen (static/board.html);
`/s/<session>/ws?t=<token>&page=board|mirror&client=<id>` is the WebSocket a
page opens (hub.py says what goes over it). A wrong token or an unknown
session gets 403 and nothing about the session; a refused WebSocket is
recorded in the session it named, if that session exists.
"""

from __future__ import annotations

import re

from starlette.requests import Request
from starlette.responses import FileResponse, PlainTextResponse
from starlette.routing import Route, WebSocketRoute
from starlette.websockets import WebSocket

PAGES_OF_WS = ("board", "mirror")
CLIENT_ID = re.compile(r"^[A-Za-z0-9_-]{1,64}$")


def page_response(request: Request, filename: str):
    """The static page `filename` if the URL's session and token match, else 403."""
    from pairplay.services.lab.app import STATIC

    lab = request.app.state.lab
    if lab.hub_for(request.path_params["session"], request.query_params.get("t", "")) is None:
        return PlainTextResponse("unknown session or wrong token\n", status_code=403)
    return FileResponse(STATIC / filename, media_type="text/html")


async def board_page(request: Request):
    return page_response(request, "board.html")


async def page_socket(ws: WebSocket) -> None:
    lab = ws.app.state.lab
    session = ws.path_params["session"]
    page = ws.query_params.get("page", "board")
    client_id = ws.query_params.get("client", "")
    hub = lab.hub_for(session, ws.query_params.get("t", ""))
    if hub is None or page not in PAGES_OF_WS or not CLIENT_ID.match(client_id):
        known = lab.hubs.get(session)
        if known is not None:
            why = "wrong token" if hub is None else f"bad page {page!r} or client id {client_id[:64]!r}"
            known.record_refusal(f"WebSocket refused: {why}", f"ws/{session}/{page[:16]}")
        await ws.close(code=4403)  # before accept: the handshake gets 403
        return
    await ws.accept()
    await hub.serve(ws, page, client_id)


def routes() -> list:
    return [Route("/s/{session}/board", board_page), WebSocketRoute("/s/{session}/ws", page_socket)]
