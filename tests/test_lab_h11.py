"""The lab's web server speaks HTTP through h11, whatever else is installed: its request heads are bounded.

Rule (services/lab/server.py `WebServer`, the one uvicorn server pairplay starts: `pairplay lab` and `protocol
serve` both run it): uvicorn's `http` option is given a protocol class, services/lab/deadlines.py's DeadlineH11,
uvicorn's h11 protocol with the lab's deadlines. With "auto" uvicorn takes httptools when it is importable, which
has no limit on a request head's size (h11 refuses a head of which it holds 16 KiB, not yet whole) and none of
the lab's deadlines. httptools is
no dependency of pairplay; installed beside it (`pip install httptools`), this test still holds. Real parts: a
real WebServer on loopback and a raw socket sending a head of 20 KiB.
"""

from __future__ import annotations

import socket

from uvicorn.protocols.http.h11_impl import H11Protocol

from pairplay.services.lab.app import Lab, create_app
from pairplay.services.lab.server import WebServer

HEAD_LIMIT = 16 * 1024  # h11's max_incomplete_event_size, uvicorn's default


def _answer(host: str, port: int, request: bytes) -> bytes:
    """The status line the server answers `request` with."""
    with socket.create_connection((host, port), timeout=30) as sock:
        sock.sendall(request)
        answer = b""
        while b"\r\n" not in answer:
            got = sock.recv(4096)
            if not got:
                break
            answer += got
    return answer.split(b"\r\n", 1)[0]


def test_the_lab_server_is_h11_even_with_httptools_importable(caplog, capfd):
    """And the 400 is said by pairplay's logger, in its words, with the client; uvicorn prints nothing of its own
    (trial32 H: "WARNING:  Invalid HTTP request received.", uvicorn's handler and words)."""
    server = WebServer(create_app(Lab())).start()
    try:
        assert issubclass(server.server.config.http_protocol_class, H11Protocol)
        host, port = server.address
        small = _answer(host, port, b"GET /nothing HTTP/1.1\r\nHost: x\r\n\r\n")
        assert small.startswith(b"HTTP/1.1 ") and not small.startswith(b"HTTP/1.1 400"), small
        # a head past the limit and not yet whole (h11's limit is on what it holds of an incomplete head): h11
        # refuses it at once; httptools waits for more, the socket's timeout
        big = b"GET /nothing HTTP/1.1\r\nHost: x\r\nX-Filler: " + b"a" * (HEAD_LIMIT + 4096)
        assert _answer(host, port, big) == b"HTTP/1.1 400 Bad Request"
    finally:
        server.stop()
    said = [(r.name, r.getMessage()) for r in caplog.records if "400" in r.getMessage()]
    assert said == [("pairplay.lab", f"answered 400 to a request from {host}: not HTTP, or a head over 16 KiB")]
    assert "Invalid HTTP request" not in capfd.readouterr().err
