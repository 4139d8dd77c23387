"""A test double of the Furhat robot as an IrisTK client, written from appendix D.

Rule: it joins the broker like any IrisTK module (CONNECT, waits for CONNECTED,
SUBSCRIBE action.**), and reads events as the Java side does: an event without
"class": "iristk.system.Event", with a JSON null anywhere, or with an event_time
not in "yyyy-MM-dd HH:mm:ss.SSS" is dropped (logged in `dropped`). It performs
  action.speech       monitor.speech.start {action: id}; after speech_s
                      monitor.speech.end {action: id}; "abort": true cuts the
                      current speech (which then never reports its end)
  action.speech.stop  cuts the current speech
  action.gesture      monitor.gesture.end {action: id, name}
  action.gaze         needs location {class iristk.util.Location, x, y, z numbers}
and keeps everything it performed in `performed` (event name, event). Like an
IrisTK module it rejoins the broker when the connection drops (every 20 ms, for
at most 10 s).
"""

from __future__ import annotations

import datetime as dt
import json
import socket
import threading
import time

EVENT_CLASS = "iristk.system.Event"


def has_null(value) -> bool:
    if value is None:
        return True
    if isinstance(value, dict):
        return any(has_null(v) for v in value.values())
    if isinstance(value, list):
        return any(has_null(v) for v in value)
    return False


def valid_time(text) -> bool:
    if not isinstance(text, str) or len(text) != 23:
        return False
    try:
        dt.datetime.strptime(text, "%Y-%m-%d %H:%M:%S.%f")
    except ValueError:
        return False
    return True


class IrisTKFurhat:
    def __init__(self, port: int, ticket: str = "furhat", name: str = "furhat", speech_s: float = 0.05) -> None:
        self.port, self.ticket, self.name, self.speech_s = port, ticket, name, speech_s
        self.performed: list[tuple[str, dict]] = []
        self.dropped: list[tuple[str, str]] = []  # (event name, why)
        self.replies: list[dict] = []
        self._speaking: str | None = None
        self._lock = threading.Lock()
        self._changed = threading.Condition()
        self._sock: socket.socket | None = None
        self._counter = 0
        self._closed = False
        self.joins = 0  # how many times it (re)joined the broker

    def start(self) -> "IrisTKFurhat":
        self._closed = False
        self._join()
        return self

    def _join(self) -> None:
        sock = socket.create_connection(("127.0.0.1", self.port))
        sock.sendall(f"CONNECT {self.ticket} {self.name}\n".encode())
        stream = sock.makefile("rb")
        while (line := stream.readline()) and line != b"CONNECTED\n":
            pass  # SUBSCRIBE lines: information
        sock.sendall(b"SUBSCRIBE action.**\n")
        self._sock = sock
        with self._changed:
            self.joins += 1
            self._changed.notify_all()
        threading.Thread(target=self._read, args=(stream,), daemon=True, name="furhat double").start()

    def _rejoin(self) -> None:
        deadline = time.monotonic() + 10.0
        while not self._closed and time.monotonic() < deadline:
            try:
                return self._join()
            except OSError:
                time.sleep(0.02)

    def close(self) -> None:
        self._closed = True
        if self._sock is not None:
            try:
                self._sock.sendall(b"CLOSE\n")
            except OSError:
                pass
            self._sock.close()

    def wait_for(self, predicate, timeout: float = 5.0) -> bool:
        with self._changed:
            return self._changed.wait_for(lambda: predicate(self), timeout)

    def _read(self, stream) -> None:
        try:
            while line := stream.readline():
                words = line.decode().rstrip("\n").split(" ")
                if words[0] == "EVENT" and len(words) == 3:
                    payload = stream.read(int(words[2]))
                    self._event(words[1], payload)
        except (OSError, ValueError):
            pass
        if not self._closed:
            self._rejoin()

    def _event(self, name: str, payload: bytes) -> None:
        try:
            event = json.loads(payload)
        except json.JSONDecodeError:
            return self._drop(name, "not JSON")
        if event.get("class") != EVENT_CLASS:
            return self._drop(name, "no class iristk.system.Event")
        if has_null(event):
            return self._drop(name, "JSON null")
        if "event_time" in event and not valid_time(event["event_time"]):
            return self._drop(name, f"event_time {event['event_time']!r}")
        if name == "action.gaze":
            loc = event.get("location", {})
            if loc.get("class") != "iristk.util.Location" or not all(
                    isinstance(loc.get(k), (int, float)) for k in "xyz"):
                return self._drop(name, "bad location")
        with self._changed:
            self.performed.append((name, event))
            self._changed.notify_all()
        event_id = event.get("event_id", "")
        if name == "action.speech":
            with self._lock:
                self._speaking = event_id  # abort or not, the newest speech is what plays here
            self._send("monitor.speech.start", action=event_id, text=event.get("text", ""))
            _later(self.speech_s, self._speech_done, event_id)
        elif name == "action.speech.stop":
            with self._lock:
                self._speaking = None
        elif name == "action.gesture":
            self._send("monitor.gesture.end", action=event_id, name=event.get("name", ""))

    def _speech_done(self, event_id: str) -> None:
        with self._lock:
            if self._speaking != event_id:
                return  # aborted
            self._speaking = None
        self._send("monitor.speech.end", action=event_id)

    def _drop(self, name: str, why: str) -> None:
        with self._changed:
            self.dropped.append((name, why))
            self._changed.notify_all()

    def _send(self, event_name: str, **fields) -> None:
        self._counter += 1
        event = {"class": EVENT_CLASS, "event_name": event_name, "event_id": f"furhat.{self._counter}",
                 "event_sender": self.name, **fields}
        body = json.dumps(event).encode() + b"\n"
        with self._changed:
            self.replies.append(event)
            self._changed.notify_all()
        try:
            assert self._sock is not None
            self._sock.sendall(f"EVENT {event_name} {len(body)}\n".encode() + body)
        except OSError:
            pass  # the broker went away


def _later(delay: float, function, *args) -> None:
    """Run function(*args) after delay on a daemon timer (a test never waits for it at exit)."""
    timer = threading.Timer(delay, function, args=args)
    timer.daemon = True
    timer.start()
