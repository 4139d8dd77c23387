"""A request body above 64 KiB is refused before it is read, and the lab server's memory does not grow by it.

Rule (services/lab/bodylimit.py): the lab app (console, questionnaire, board, mirror) answers 413 at once to a
Content-Length above MAX_BODY and stops reading a body sent without a length as soon as it passes MAX_BODY, before
any route or token check. The trial (trial28 F13): an 800 MB POST to /api/questionnaire/answer, a route without a
token, took `protocol serve` from 130 MB to 1.43 GB of RSS, then "request too large". Here a real `protocol serve`
gets 500 MB both ways (curl's way: Content-Length with `Expect: 100-continue`; and chunked); its peak RSS (VmHWM,
reset through clear_refs first) must stay within 100 MB of its RSS before. No timing is asserted.
"""

from __future__ import annotations

import contextlib
import queue
import socket
import threading
from pathlib import Path
from urllib.parse import urlsplit

import pytest

from pairplay.replay.studydata import StudyData

from test_study_guard import serving, stopped

STUDY = Path(__file__).parent / "data" / "pilot-study.toml"
BODY = 500 * 1024 * 1024
GROWTH_KB = 100 * 1024


def _status(pid: int) -> dict[str, int]:
    """VmRSS and VmHWM of the process, in KB."""
    lines = Path(f"/proc/{pid}/status").read_text().splitlines()
    return {k: int(v.split()[0]) for k, v in (line.split(":", 1) for line in lines) if k in ("VmRSS", "VmHWM")}


@pytest.fixture(scope="module")
def server(tmp_path_factory):
    data = StudyData.create(tmp_path_factory.mktemp("bodylimit") / "study", STUDY)
    proc = serving(data.folder)
    try:
        yield proc
    finally:
        stopped(proc)


def _send_body(sock: socket.socket, chunked: bool) -> None:
    """BODY zero bytes, in 1 MiB pieces (chunked: each framed), until the server stops taking them."""
    piece = bytes(1 << 20)
    framed = b"%x\r\n" % len(piece) + piece + b"\r\n" if chunked else piece
    try:
        for _ in range(BODY // len(piece)):
            sock.sendall(framed)
        if chunked:
            sock.sendall(b"0\r\n\r\n")
    except OSError:  # refused: the server closed the connection
        pass


def _post(url: str, path: str, chunked: bool) -> bytes:
    """The status line of the server's final answer to a BODY-byte POST of `path`."""
    parts = urlsplit(url)
    sock = socket.create_connection((parts.hostname, parts.port))
    head = (f"POST {path} HTTP/1.1\r\nHost: {parts.netloc}\r\nContent-Type: application/json\r\n"
            + ("Transfer-Encoding: chunked\r\n" if chunked else f"Content-Length: {BODY}\r\nExpect: 100-continue\r\n")
            + "\r\n")
    sock.sendall(head.encode())
    answers = sock.makefile("rb")
    sender = None
    if chunked:
        sender = threading.Thread(target=_send_body, args=(sock, True), daemon=True)
        sender.start()
    line = answers.readline()
    if line.startswith(b"HTTP/1.1 100"):  # the server asked for the body: it means to read it
        answers.readline()  # the blank line after the interim answer
        sender = threading.Thread(target=_send_body, args=(sock, False), daemon=True)
        sender.start()
        line = answers.readline()
    with contextlib.suppress(OSError):  # the server may have closed it first (ENOTCONN): as meant
        sock.shutdown(socket.SHUT_RDWR)  # the sender stops at once, whatever the server did
    if sender is not None:
        sender.join()
    sock.close()
    return line


@pytest.mark.parametrize("chunked", [False, True], ids=["content-length", "chunked"])
def test_a_huge_body_is_refused_before_it_is_read(server, chunked):
    url = "http://" + urlsplit(server.console_url).netloc
    try:
        Path(f"/proc/{server.pid}/clear_refs").write_text("5")  # VmHWM from now on
    except OSError:
        pass
    before = _status(server.pid)["VmRSS"]
    line = _post(url, "/api/questionnaire/answer", chunked)
    grew = _status(server.pid)["VmHWM"] - before
    assert grew < GROWTH_KB, f"the server's RSS grew by {grew} KB for a body of {BODY} bytes (answer {line!r})"
    assert line.startswith(b"HTTP/1.1 413"), line


def test_a_refused_body_is_recorded_in_the_session_the_lab_serves(tmp_path):
    """The refusal is a MessageRejected in the running session's recording, naming the path and the limit."""
    from labutil import human_config, running_lab
    from pairplay.replay.reader import read_log
    from pairplay.schemas.keys import session_keys

    seen: queue.Queue = queue.Queue()
    with running_lab(tmp_path, human_config("lab-body"),
                     before_start=lambda bus: bus.subscribe(session_keys("lab-body"), lambda k, p: seen.put(k))) as lab:
        while "SessionStarted" not in str(seen.get(timeout=60)):  # the board's node is on the bus: it records
            pass
        parts = urlsplit(lab.urls.board)
        sock = socket.create_connection((parts.hostname, parts.port))
        sock.sendall(f"POST /s/lab-body/board HTTP/1.1\r\nHost: {parts.netloc}\r\nContent-Length: 70000\r\n\r\n"
                     .encode())
        line = sock.makefile("rb").readline()
        sock.close()
        lab.stop.set()
        path = lab.wait()
    assert line.startswith(b"HTTP/1.1 413"), line
    refused = [r.event for r in read_log(path).events if type(r.event).__name__ == "MessageRejected"]
    assert [(r.reason, r.key) for r in refused] == [
        ("HTTP request refused: a body of '70000' bytes, the limit is 65536", "http/s/lab-body/board")]
