"""The lab server of a study: the experimenter's console, each game's board and mirror, the questionnaire.

Rule: `StudyLabServer(runner)` serves, in one Starlette app of the lab
(services/lab/app.create_app: its security headers, its board and mirror
routes), the console and questionnaire routes (app.py) on HOST:PORT (port 0:
the OS picks one), in a thread of this process beside the study's bus. The
runner adds each game's LabHub to the app's `Lab` while the game runs, so the
board page of the game that is on is `/s/<session>/board?t=<token>`, and the
console links to it. On loopback unless the caller gives another host; TLS
with a certificate and key, as `pairplay lab`.
"""

from __future__ import annotations

import secrets
from types import SimpleNamespace

from pairplay.services.console.app import Console, console_routes
from pairplay.services.lab.app import PAGES, Lab, create_app
from pairplay.services.lab.server import WebServer
from pairplay.services.protocol import StudyRunner


class StudyLabServer:
    def __init__(self, runner: StudyRunner, token: str | None = None, host: str = "127.0.0.1", port: int = 0,
                 ssl_certfile: str | None = None, ssl_keyfile: str | None = None):
        self.token = token or secrets.token_urlsafe(18)
        self.lab = runner.lab if runner.lab is not None else Lab()
        runner.lab = self.lab

        def board_url(session: str) -> str | None:
            hub = self.lab.hubs.get(session)
            return None if hub is None else f"/s/{session}/board?t={hub.token}"
        self.console = Console(runner, self.token, board_url=board_url)
        page = SimpleNamespace(routes=lambda: console_routes(self.console))
        self.app = create_app(self.lab, pages=PAGES + (page,))
        self.web = WebServer(self.app, host, port, ssl_certfile, ssl_keyfile)

    def start(self) -> "StudyLabServer":
        self.web.start()
        return self

    @property
    def url(self) -> str:
        return self.web.base_url()

    @property
    def console_url(self) -> str:
        return f"{self.url}/console?token={self.token}"

    def close(self, timeout_s: float = 10.0) -> None:
        """Stop the web server, waiting for it at most `timeout_s`."""
        self.web.stop(timeout_s)


ConsoleServer = StudyLabServer  # the name the console had before it joined the lab server
