"""A request that is not sent whole in time is answered 408 and closed; no more than MAX_CONNECTIONS are held.

Rule (services/lab/deadlines.py, bodylimit.py): the lab server (here a real `protocol serve`, the console's)
gives a request's head and its body READ_S each; a connection beyond MAX_CONNECTIONS is closed as soon as it is
accepted. The trial (trial29 F11): 900 connections each sending a POST's headers with Content-Length: 60000 and
100 bytes of body, then nothing, were all held 20 s and more. Real sockets; no timing is asserted: each slow
connection is read until the server answers or closes it.

Its log (services/lab/serverlog.py): one line for a burst from a client, not one a connection, and the counts
said (trial32 H: 300 idle connections printed 201 lines "closed a connection from 127.0.0.1: no whole request head
within 10 s", and a 200 KB head uvicorn's own "WARNING:  Invalid HTTP request received.", its format and words).
The counts are said when the client has gone quiet or when the server stops, whichever comes first: the test
reads them after the stop, so it asserts no timing; a burst a loaded machine split in two says its first line
twice, and the counts still add up.
"""

from __future__ import annotations

import re
import socket
from pathlib import Path
from urllib.parse import urlsplit

from pairplay.replay.studydata import StudyData
from pairplay.services.lab.deadlines import MAX_CONNECTIONS

from test_study_guard import serving, stopped

STUDY = Path(__file__).parent / "data" / "pilot-study.toml"


def _open(netloc: str, sent: bytes) -> socket.socket:
    host, port = netloc.rsplit(":", 1)
    sock = socket.create_connection((host, int(port)))
    if sent:
        sock.sendall(sent)
    return sock


def _answer(sock: socket.socket) -> bytes:
    """All the server sends until it closes the connection (b"" if it closed without a word)."""
    sock.settimeout(120)  # a bound, not a measure: before the fix this waited for ever
    got = b""
    try:
        while chunk := sock.recv(65536):
            got += chunk
    except ConnectionResetError:
        pass
    sock.close()
    return got


def _still_open(sock: socket.socket) -> bool:
    """Nothing has come on `sock` and it is not closed (a read would wait)."""
    sock.setblocking(False)
    try:
        sock.recv(1, socket.MSG_PEEK)
    except BlockingIOError:
        return True
    finally:
        sock.setblocking(True)
    return False


def _get_state(netloc: str, token: str) -> bytes:
    sock = _open(netloc, f"GET /api/console/state?token={token} HTTP/1.1\r\nHost: {netloc}\r\n"
                         "Connection: close\r\n\r\n".encode())
    return _answer(sock).split(b"\r\n", 1)[0]


def test_slow_heads_and_bodies_are_answered_408_and_connections_are_capped(tmp_path):
    data = StudyData.create(tmp_path / "study", STUDY)
    proc = serving(data.folder)
    try:
        url = urlsplit(proc.console_url)
        token = url.query.split("token=", 1)[1]
        netloc = url.netloc
        body = (f"POST /api/console/register?token={token} HTTP/1.1\r\nHost: {netloc}\r\n"
                "Content-Type: application/json\r\nContent-Length: 60000\r\n\r\n").encode() + b"{" * 100
        head = f"GET /api/console/state?token={token} HTTP/1.1\r\nHost: {netloc}\r\n".encode()  # no end of head
        slow = [_open(netloc, body) for _ in range(20)] + [_open(netloc, head) for _ in range(20)] \
            + [_open(netloc, b"") for _ in range(20)]
        # meanwhile the console answers
        assert all(_still_open(s) for s in slow)
        assert _get_state(netloc, token) == b"HTTP/1.1 200 OK"
        # the cap: connections beyond it are closed at once, unanswered; those within it wait for their deadline
        extra = 5
        fillers = [_open(netloc, b"") for _ in range(MAX_CONNECTIONS - len(slow) + extra)]
        answers = [_answer(s) for s in slow + fillers]
        assert all(a.startswith(b"HTTP/1.1 408 ") for a in answers[:len(slow)]), {a[:40] for a in answers}
        assert b"a body must come whole within" in answers[0]
        assert sum(a == b"" for a in answers) == extra
        assert sum(a.startswith(b"HTTP/1.1 408 ") for a in answers) == MAX_CONNECTIONS
        assert _get_state(netloc, token) == b"HTTP/1.1 200 OK"  # and it takes connections again
        # a head past h11's 16 KiB: answered 400, said in pairplay's words with the client
        bad = [_open(netloc, head + b"X-Filler: " + b"a" * (20 * 1024)) for _ in range(3)]
        assert all(_answer(s).startswith(b"HTTP/1.1 400 ") for s in bad)
    finally:
        stopped(proc)
    proc.err_read.join(30)
    lines = "".join(proc.err).splitlines()
    assert lines[-1].startswith("pairplay protocol serve: stopped (SIGTERM)"), lines
    lines = lines[:-1]
    assert not [line for line in lines if not line.startswith("WARNING pairplay.lab: ")], lines  # uvicorn's none
    heads = MAX_CONNECTIONS - 20  # the idle and half-headed ones within the cap (20 slow bodies are said apart)
    assert _said(lines, "closed a connection from 127.0.0.1: no whole request head within 10 s",
                 r"closed (\d+) more connections? from 127\.0\.0\.1 that sent no whole request head within 10 s") == heads
    assert _said(lines, "refused a body not sent whole within 10 s to /api/console/register from 127.0.0.1: "
                        "the limit is 10 s",
                 r"refused (\d+) more request bod(?:y|ies) from 127\.0\.0\.1 not sent whole within 10 s") == 20
    assert _said(lines, "answered 400 to a request from 127.0.0.1: not HTTP, or a head over 16 KiB",
                 r"answered 400 to (\d+) more requests? from 127\.0\.0\.1 that were not HTTP, or had a head over "
                 r"16 KiB") == 3
    assert len(lines) < 20, lines  # 228 connections said: one line for each, before


def _said(lines: list[str], first: str, more: str) -> int:
    """How many of a kind the log said: its first lines (one a burst) and the counts of its "n more" lines."""
    lines = [line.split(": ", 1)[1] for line in lines]
    return sum(line == first for line in lines) + sum(int(m[1]) for line in lines if (m := re.fullmatch(more, line)))
