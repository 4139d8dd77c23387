"""A test double of the Furhat Realtime API server, written from the maker's client.

Source: furhat-realtime-api 0.1.3 (`pip download --no-deps`, read, not copied),
furhat_realtime_api/async_furhat_client.py and events.py:
  - ws://HOST:9000/v1/events (line 21); other paths: HTTP 404.
  - request.auth {key?, request_id} is answered by response.auth {access, scope}
    echoing request_id (the client waits for exactly that, lines 39-49, 163-175);
    access only with the right "key" when the robot has one. `answers_auth=False`
    stands for a robot that never answers (the maker's client then fails after
    5 s). Before access any other request is ignored.
  - a response echoes "request_id" only when the request carried one (the client
    adds it only in send_event_and_wait, line 165; fire-and-forget requests have
    none, lines 244-246, 318-325, 352-360).
  - the fields "aborted" and "failed" of response.speak.end are not read by the
    0.1.3 client; they are as issue 13 reports the server sending them.
Then:
  request.speak.text    response.speak.start, and after speech_s response.speak.end
                        {aborted: false, failed: false}; a text in `fail_texts`
                        ends at once with failed: true; "abort": true ends the
                        current speech at once with response.speak.end {aborted: true}
  request.speak.stop    ends the current speech (aborted)
  request.gesture.start response.gesture.start, response.gesture.end if "monitor"
  request.attend.location  needs numbers x, y, z
  request.face.headpose    needs numbers yaw, pitch, roll and a bool "relative"
Every response echoes the request's "request_id" (as the robot does for its own
Python client). Malformed frames and bad requests are logged in `bad` and
ignored. Controls: `drop_all()` closes every connection, `inject(frame)` sends a
raw frame to every client (malformed frames from the robot side).
"""

from __future__ import annotations

import http
import json
import threading

from websockets.exceptions import ConnectionClosed
from websockets.sync.server import ServerConnection, serve

NUMBERS = {"request.attend.location": ("x", "y", "z"), "request.face.headpose": ("yaw", "pitch", "roll")}


class FurhatRealtimeServer:
    def __init__(self, key: str = "", speech_s: float = 0.05, answers_auth: bool = True,
                 fail_texts: frozenset[str] = frozenset()) -> None:
        self.key, self.speech_s, self.answers_auth, self.fail_texts = key, speech_s, answers_auth, fail_texts
        self.requests: list[dict] = []  # every well-formed request after auth, in order
        self.bad: list[str] = []
        self.auths: list[bool] = []
        self.auth_ids: list[str] = []
        self._connections: list[ServerConnection] = []
        self._speaking: dict[ServerConnection, dict] = {}
        self._lock = threading.Lock()
        self._changed = threading.Condition()

    def start(self) -> "FurhatRealtimeServer":
        self._server = serve(self._handle, "127.0.0.1", 0, process_request=self._check_path)
        self.port = self._server.socket.getsockname()[1]
        threading.Thread(target=self._server.serve_forever, daemon=True, name="realtime double").start()
        return self

    def stop(self) -> None:
        self._server.shutdown()
        self.drop_all()

    def drop_all(self) -> None:
        with self._lock:
            connections, self._connections = self._connections, []
        for connection in connections:
            connection.close()

    def inject(self, frame: str | bytes) -> None:
        with self._lock:
            connections = list(self._connections)
        for connection in connections:
            connection.send(frame)

    def wait_for(self, predicate, timeout: float = 30.0) -> bool:  # a bound, not a measure
        with self._changed:
            return self._changed.wait_for(lambda: predicate(self), timeout)

    def _note(self, attr: str, value) -> None:
        with self._changed:
            getattr(self, attr).append(value)
            self._changed.notify_all()

    @staticmethod
    def _check_path(connection: ServerConnection, request):
        if request.path != "/v1/events":
            return connection.respond(http.HTTPStatus.NOT_FOUND, "no such endpoint\n")
        return None

    def _handle(self, connection: ServerConnection) -> None:
        with self._lock:
            self._connections.append(connection)
        authorised = False
        try:
            for raw in connection:
                try:
                    message = json.loads(raw) if isinstance(raw, str) else None
                except json.JSONDecodeError:
                    message = None
                if not isinstance(message, dict) or not isinstance(message.get("type"), str):
                    self._note("bad", f"not a JSON object with a type: {raw!r:.80}")
                    continue
                if message["type"] == "request.auth":
                    authorised = not self.key or message.get("key") == self.key
                    self.auth_ids.append(str(message.get("request_id")))
                    self._note("auths", authorised)
                    if self.answers_auth:
                        self._respond(connection, message, "response.auth", access=authorised,
                                      scope="all" if authorised else "none")
                elif not authorised:
                    self._note("bad", f"{message['type']} before access")
                else:
                    self._request(connection, message)
        except ConnectionClosed:
            pass
        finally:
            with self._lock:
                if connection in self._connections:
                    self._connections.remove(connection)
                self._speaking.pop(connection, None)

    def _request(self, connection: ServerConnection, message: dict) -> None:
        kind = message["type"]
        if any(not isinstance(message.get(k), (int, float)) or isinstance(message.get(k), bool)
               for k in NUMBERS.get(kind, ())):
            return self._note("bad", f"{kind} needs numbers {NUMBERS[kind]}")
        if kind == "request.face.headpose" and not isinstance(message.get("relative"), bool):
            return self._note("bad", "request.face.headpose needs a bool relative")
        if kind == "request.speak.text" and not isinstance(message.get("text"), str):
            return self._note("bad", "request.speak.text needs a text")
        if kind == "request.gesture.start" and not isinstance(message.get("name"), str):
            return self._note("bad", "request.gesture.start needs a name")
        if kind not in ("request.speak.text", "request.speak.stop", "request.gesture.start", *NUMBERS):
            return self._note("bad", f"unknown request {kind}")
        self._note("requests", message)
        if kind in ("request.speak.stop",) or (kind == "request.speak.text" and message.get("abort")):
            self._end_speech(connection, aborted=True)
        if kind == "request.speak.text" and message["text"] in self.fail_texts:
            self._respond(connection, message, "response.speak.end", text=message["text"], aborted=False, failed=True)
        elif kind == "request.speak.text":
            with self._lock:
                self._speaking[connection] = message
            self._respond(connection, message, "response.speak.start", text=message["text"])
            _later(self.speech_s, self._speech_done, connection, message)
        elif kind == "request.gesture.start":
            self._respond(connection, message, "response.gesture.start", name=message["name"])
            if message.get("monitor"):
                self._respond(connection, message, "response.gesture.end", name=message["name"])

    def _end_speech(self, connection: ServerConnection, aborted: bool) -> None:
        with self._lock:
            current = self._speaking.pop(connection, None)
        if current is not None:
            self._respond(connection, current, "response.speak.end", text=current["text"], aborted=aborted,
                          failed=False)

    def _speech_done(self, connection: ServerConnection, message: dict) -> None:
        with self._lock:
            if self._speaking.get(connection) is not message:
                return
        self._end_speech(connection, aborted=False)

    @staticmethod
    def _respond(connection: ServerConnection, request: dict, kind: str, **fields) -> None:
        reply = {"type": kind, **fields}
        if "request_id" in request:
            reply["request_id"] = request["request_id"]
        try:
            connection.send(json.dumps(reply))
        except ConnectionClosed:
            pass


def _later(delay: float, function, *args) -> None:
    """Run function(*args) after delay on a daemon timer (a test never waits for it at exit)."""
    timer = threading.Timer(delay, function, args=args)
    timer.daemon = True
    timer.start()
