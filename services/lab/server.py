"""Run the lab: uvicorn in a thread, and one whole live session with its board.

Rule: `WebServer` serves an ASGI app on (host, port) from its own thread
(port 0: the OS picks one, read back once uvicorn is up) and stops when
asked. `run_lab` is `pairplay lab`: the web server first (so the URLs can be
printed), then the session of services/session.py with the hub's Node among
its services (the game waits for the board to be on the bus), recorded like
any session. When the game ends the session, the pages keep the final view
for `linger_s`, then the server stops. Nothing listens beyond loopback unless
the caller gives another host.
"""

from __future__ import annotations

import socket
import threading
import time
from dataclasses import dataclass
from pathlib import Path

import uvicorn

from pairplay.schemas.session import SessionConfig
from pairplay.services.bus import SHUTDOWN_S, BusOptions, Deadline, shutdown_wait
from pairplay.services.lab.app import Lab, create_app
from pairplay.services.lab.deadlines import DeadlineH11
from pairplay.services.lab.hub import MAX_FRAME, LabHub
from pairplay.services.lab.reach import reachable_host
from pairplay.services.lab.serverlog import bursts, quiet_uvicorn
from pairplay.services.robot.choice import RobotChoice
from pairplay.services.session import run_session


class WebServer:
    def __init__(self, app, host: str = "127.0.0.1", port: int = 0, ssl_certfile: str | None = None,
                 ssl_keyfile: str | None = None):
        # DeadlineH11: a request's head within READ_S, at most MAX_CONNECTIONS open (deadlines.py). A class, never
        # "auto": uvicorn would take httptools when it is importable (a user's venv may hold it), which bounds no
        # request head's size (h11 refuses one past 16 KiB) and has none of these deadlines (tests/test_lab_h11.py)
        # log_config None: no handler of uvicorn's; its lines are said in ours (serverlog.quiet_uvicorn)
        quiet_uvicorn()
        config = uvicorn.Config(app, host=host, port=port, log_config=None, log_level="warning", lifespan="off",
                                http=DeadlineH11,
                                ws_max_size=MAX_FRAME, ws_ping_interval=5.0, ws_ping_timeout=10.0,
                                ssl_certfile=ssl_certfile, ssl_keyfile=ssl_keyfile, access_log=False,
                                timeout_graceful_shutdown=2)  # open pages must not hold up a SIGTERM
        self.server = uvicorn.Server(config)
        self.scheme = "https" if ssl_certfile else "http"
        self.thread: threading.Thread | None = None

    def start(self, timeout_s: float = 10.0) -> "WebServer":
        """Serve from a thread; OSError (its strerror says why: "Address already in use") when the address
        cannot be bound. We bind the socket here and hand it to uvicorn: uvicorn binding it itself in its
        thread printed its own "ERROR: [Errno 98] ..." line beside the verb's one line."""
        sock = _bind(self.server.config.host, self.server.config.port)
        thread = threading.Thread(target=self.server.run, kwargs={"sockets": [sock]}, name="pairplay-lab-web",
                                  daemon=True)
        thread.start()
        self.thread = thread  # only once started: `stop` joins it
        deadline = time.monotonic() + timeout_s
        while not self.server.started:
            if not self.thread.is_alive() or time.monotonic() > deadline:
                raise OSError(f"the lab's web server did not start on {self.server.config.host}:"
                              f"{self.server.config.port}")
            time.sleep(0.01)
        return self

    @property
    def address(self) -> tuple[str, int]:
        sock = self.server.servers[0].sockets[0]
        host, port = sock.getsockname()[:2]
        return host, port

    def base_url(self) -> str:
        host, port = self.address
        return f"{self.scheme}://{reachable_host(host)}:{port}"  # a wildcard: the address the touch screen can open

    def stop(self, timeout_s: float = 10.0) -> None:
        """Ask uvicorn to stop; wait for its thread at most `timeout_s` (a stopped process takes what
        its shutdown's deadline leaves: `shutdown_wait`; the daemon thread is left to the exit)."""
        self.server.should_exit = True
        if self.thread is not None:
            self.thread.join(timeout_s)
        bursts.flush()  # the counts of bursts still open are said: their timers die with the server's loop


def _bind(host: str, port: int) -> socket.socket:
    """A TCP socket bound to (host, port) as uvicorn binds one (SO_REUSEADDR; an IPv6 host on AF_INET6)."""
    family, _, _, _, address = socket.getaddrinfo(host or None, port, type=socket.SOCK_STREAM,
                                                  flags=socket.AI_PASSIVE)[0]
    sock = socket.socket(family, socket.SOCK_STREAM)
    sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
    try:
        sock.bind(address)
    except OSError:
        sock.close()
        raise
    return sock


@dataclass(frozen=True)
class LabUrls:
    board: str
    mirror: str


def urls_of(base: str, hub: LabHub) -> LabUrls:
    return LabUrls(f"{base}/s/{hub.session}/board?t={hub.token}", f"{base}/s/{hub.session}/mirror?t={hub.token}")


def linger(stop: threading.Event, seconds: float) -> None:
    """Wait `seconds` (the pages show the session's end), or until a signal. run_session sets `stop` as its
    services stop, whatever ended it, so the flag says nothing here: before, `stop.wait(linger_s)` returned at
    once and `--linger` was never waited (the lab read its recording back ~1 s after the game's end). A signal
    is `stop.why` (services/bus.py stop_on_signals); one during the linger gets a signal's shutdown deadline
    from now (the flag's, set at the session's end, may have seconds left, more than a signal's exit allows)."""
    if getattr(stop, "why", ""):  # the session was stopped by a signal: no linger
        return
    end = time.monotonic() + seconds
    while time.monotonic() < end:
        if getattr(stop, "why", ""):
            stop.deadline = Deadline(SHUTDOWN_S)
            return
        time.sleep(min(0.05, max(0.0, end - time.monotonic())))


def run_lab(config: SessionConfig, path: str | Path, *, host: str = "127.0.0.1", port: int = 0,
            bus_options: BusOptions | None = None, robot: RobotChoice | None = RobotChoice(),
            stop: threading.Event | None = None, on_ready=None, linger_s: float = 3.0,
            ssl_certfile: str | None = None, ssl_keyfile: str | None = None, token: str | None = None,
            nodes_out: dict | None = None, summary: dict | None = None) -> Path:
    """One live session with its board; return the recording's path.

    `on_ready(urls, bus)` is called once the pages can be opened (the bus is
    up; the game starts when the board's Node is on it). `summary`: as
    run_session's (what an interrupted caller prints without reading the file)."""
    config.validate()
    stop = stop or threading.Event()
    hub = LabHub(config, token=token)
    lab = Lab()
    lab.add(hub)
    web = WebServer(create_app(lab), host, port, ssl_certfile, ssl_keyfile).start()
    urls = urls_of(web.base_url(), hub)

    def on_bus(bus) -> None:
        if on_ready is not None:
            on_ready(urls, bus)

    try:
        out = run_session(config, path, bus_options=bus_options, stop=stop, on_bus=on_bus, robot=robot,
                          extra_nodes=lambda bus: [hub.make_node(bus)], nodes_out=nodes_out, summary=summary)
        linger(stop, linger_s)  # the pages show the end before the server goes
        return out
    finally:
        # stopped: the recording is finished; the web server and the hub get what the deadline leaves
        web.stop(shutdown_wait(stop, 10.0, reserve=0.3))
        hub.close(shutdown_wait(stop, 5.0, reserve=0.3))
