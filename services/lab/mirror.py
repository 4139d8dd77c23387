"""Routes of the mirror: the robot's stand-in for a pilot without a robot.

Rule: `/s/<session>/mirror?t=<token>` (static/mirror.html) shows the board as
the participant sees it, the open suggestion (its speech in words, the card
region its head or gaze part points at, an arrow from the observed card) and
what the robot bridge did and when (RobotActed). It is read-only; it talks
through the board's WebSocket with `page=mirror`.
"""

from __future__ import annotations

from starlette.requests import Request
from starlette.routing import Route

from pairplay.services.lab.board import page_response


async def mirror_page(request: Request):
    return page_response(request, "mirror.html")


def routes() -> list:
    return [Route("/s/{session}/mirror", mirror_page)]
