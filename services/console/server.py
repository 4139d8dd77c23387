"""Serving the console on its own: a Starlette app under uvicorn, on loopback unless told otherwise.

Rule: `ConsoleServer(runner, token)` serves the console and questionnaire routes
(app.py) on HOST:PORT (port 0: the OS picks one; `url` says which) in a thread
of this process, beside the study's bus. It stops with `close()`. The lab
server of the board (`pairplay lab`) mounts the same routes in its own app;
this server is for running a study's console where no board page is served
from this process (a pilot with scripted participants, or a board run elsewhere).
"""

from __future__ import annotations

import secrets
import socket
import threading
import time

import uvicorn
from starlette.applications import Starlette

from pairplay.services.console.app import Console, console_routes
from pairplay.services.protocol import StudyRunner


class ConsoleServer:
    def __init__(self, runner: StudyRunner, token: str | None = None, host: str = "127.0.0.1", port: int = 0,
                 board_url=None):
        self.token = token or secrets.token_urlsafe(18)
        self.console = Console(runner, self.token, board_url=board_url)
        self.app = Starlette(routes=console_routes(self.console))
        self.sock = socket.socket(socket.AF_INET6 if ":" in host else socket.AF_INET)
        self.sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        self.sock.bind((host, port))
        self.host, self.port = host, self.sock.getsockname()[1]
        self.server = uvicorn.Server(uvicorn.Config(self.app, log_level="warning", lifespan="off"))
        self.thread: threading.Thread | None = None

    @property
    def url(self) -> str:
        host = f"[{self.host}]" if ":" in self.host else self.host
        return f"http://{host}:{self.port}"

    @property
    def console_url(self) -> str:
        return f"{self.url}/console?token={self.token}"

    def start(self) -> "ConsoleServer":
        self.thread = threading.Thread(target=self.server.run, kwargs={"sockets": [self.sock]},
                                       name="pairplay-console-http", daemon=True)
        self.thread.start()
        deadline = time.monotonic() + 10
        while not self.server.started and time.monotonic() < deadline:
            time.sleep(0.02)
        if not self.server.started:
            raise RuntimeError("the console's web server did not start")
        return self

    def close(self) -> None:
        self.server.should_exit = True
        if self.thread is not None:
            self.thread.join(5)
        self.sock.close()
