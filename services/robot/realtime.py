"""Furhat Realtime API client: today's Furhat robots (WebSocket, JSON with a "type").

Source: the robot maker's client, furhat-realtime-api 0.1.3 (`pip download`,
read, not copied): furhat_realtime_api/async_furhat_client.py; docs/robot.md
cites the lines.

Rule: open ws://<robot>:9000/v1/events, never through an HTTP proxy
(websockets would follow http_proxy/https_proxy by default; the robot is on
the lab network; RobotConfig.realtime_proxy names one if wanted), and send request.auth (with "key" if configured) carrying a
fresh request_id, then wait for the response.auth with that id: "access": true
goes on, anything else is a refusal, which the driver does not retry (the
maker's client: connect() awaits send_event_and_wait(request.auth) and raises
unless access == True, lines 39-49, 163-175). Then commands become
  Say        request.speak.text {text, abort}
  StopSpeech request.speak.stop
  Gesture    request.gesture.start {name, intensity, duration, monitor: true}
  Look       request.attend.location {x, y, z}            (eyes at a card)
  Look(head) request.face.headpose {yaw, pitch, roll, relative: false}   (head turn)
Only requests whose reply we await carry a "request_id" (a fresh uuid4, as
send_event_and_wait does, line 164): request.speak.text (awaits
response.speak.end, lines 204-205) and request.gesture.start with monitor
(awaits response.gesture.end, lines 336-339); the stop, attend and headpose
requests are fire-and-forget there and here (lines 244-246, 318-325, 352-360).
The robot echoes the id, which is how replies find their suggestion. A
response.speak.end with "aborted": true marks the suggestion aborted, with
"failed": true failed (neither field is read by the 0.1.3 client, which hands
the whole message back; the issue-13 run against a Realtime server saw both). Headpose
angles are degrees from the robot's straight-ahead: yaw towards +x (its left),
pitch towards +y (up), each times a configurable sign (RobotConfig.yaw_sign,
pitch_sign) because the robot's convention could not be checked here.
Binary frames, non-JSON text and objects without "type" are reported and skipped.
"""

from __future__ import annotations

import json
import logging
import math
import threading
import time
import uuid

from websockets.exceptions import ConnectionClosed, InvalidHandshake, InvalidURI
from websockets.sync.client import ClientConnection, connect

from pairplay.schemas.robot_url import DEFAULT_PORTS
from pairplay.schemas.robot import RobotConfig

from pairplay.services.robot.render import Command, Gesture, Look, Say, StopSpeech
from pairplay.services.robot.transport import (
    GESTURE_END, SPEECH_END, SPEECH_START, AccessRefused, Deliver, Disconnected, Rejected, Reply, Wire,
)
from pairplay.schemas.nesting import json_loads

log = logging.getLogger("pairplay.robot.realtime")

DEFAULT_PORT = DEFAULT_PORTS["furhat"]
PATH = "/v1/events"
REPLIES = {"response.speak.start": SPEECH_START, "response.speak.end": SPEECH_END,
           "response.gesture.end": GESTURE_END}
OPEN_TIMEOUT_S = 5.0  # the WebSocket opening handshake
AUTH_TIMEOUT_S = 5.0  # then the response.auth to our request.auth


def headpose_angles(x: float, y: float, z: float, config: RobotConfig) -> tuple[float, float]:
    """(yaw, pitch) in degrees that point the head at (x, y, z) in the robot's frame."""
    yaw = math.degrees(math.atan2(x, z)) * config.yaw_sign
    pitch = math.degrees(math.atan2(y, math.hypot(x, z))) * config.pitch_sign
    return round(yaw, 2), round(pitch, 2)


class RealtimeTransport:
    def __init__(self, host: str, port: int, config: RobotConfig) -> None:
        self.host, self.port, self.config = host, port, config
        self.url = f"furhat://{host}:{port}"
        self.ws_url = f"ws://{host}:{port}{PATH}"
        self.scope = ""
        self._ws: ClientConnection | None = None
        self._lock = threading.Lock()

    def encode(self, command: Command, command_id: str, time_ns: int) -> Wire:
        replies: tuple[str, ...] = ()
        if isinstance(command, Say):
            message = {"type": "request.speak.text", "text": command.text, "abort": command.abort,
                       "monitor_words": False}
            replies = (SPEECH_START, SPEECH_END)
        elif isinstance(command, StopSpeech):
            message = {"type": "request.speak.stop"}
        elif isinstance(command, Gesture):
            message = {"type": "request.gesture.start", "name": command.name, "intensity": 1.0,
                       "duration": 1.0, "monitor": True}
            replies = (GESTURE_END,)
        elif isinstance(command, Look) and command.head:
            yaw, pitch = headpose_angles(command.x, command.y, command.z, self.config)
            message = {"type": "request.face.headpose", "yaw": yaw, "pitch": pitch, "roll": 0.0,
                       "relative": False}
        elif isinstance(command, Look):
            message = {"type": "request.attend.location", "x": command.x, "y": command.y, "z": command.z}
        else:
            raise TypeError(f"no Realtime API request for {command!r}")
        if replies:  # only where a reply is awaited, as the maker's client does
            message["request_id"] = command_id
        text = json.dumps(message, separators=(",", ":"))
        return Wire(text, text, replies)

    def connect(self, deliver: Deliver, generation: int) -> None:
        try:
            ws = _open(self.ws_url, self.config.realtime_proxy or None)
        except (InvalidHandshake, InvalidURI) as exc:
            raise ConnectionError(f"{self.ws_url}: {exc}") from exc
        except TimeoutError as exc:
            raise ConnectionError(f"{self.ws_url}: no WebSocket handshake within {OPEN_TIMEOUT_S:g} s") from exc
        try:
            self._authenticate(ws, deliver, generation)
        except BaseException:
            ws.close()
            raise
        with self._lock:
            self._ws = ws
        threading.Thread(target=self._read, args=(ws, deliver, generation),
                         name=f"realtime reader {self.url}", daemon=True).start()

    def _authenticate(self, ws: ClientConnection, deliver: Deliver, generation: int) -> None:
        request_id = str(uuid.uuid4())
        request = {"type": "request.auth", "request_id": request_id}
        if self.config.realtime_key:
            request["key"] = self.config.realtime_key
        deadline = time.monotonic() + AUTH_TIMEOUT_S
        try:
            ws.send(json.dumps(request))
            while True:  # frames before our response.auth are not ours to judge yet
                raw = ws.recv(timeout=max(0.0, deadline - time.monotonic()))
                message = _object(raw)
                if message is None or not isinstance(message.get("type"), str):
                    excerpt = raw[:200] if isinstance(raw, str) else repr(raw[:60])
                    deliver(Rejected(generation, "frame is not a JSON object with a string \"type\"", excerpt))
                    continue
                if (message is not None and message.get("type") == "response.auth"
                        and message.get("request_id", request_id) == request_id):
                    break
        except TimeoutError:
            raise ConnectionError(f"robot did not answer request.auth within {AUTH_TIMEOUT_S:g} s") from None
        except ConnectionClosed as exc:
            raise ConnectionError(f"robot closed the connection during auth: {exc}") from None
        if message.get("access") is not True:
            key = "with the configured key" if self.config.realtime_key else "without a key (set realtime_key or ?key=)"
            raise AccessRefused(f"{self.url} refused access {key}: response.auth {json.dumps(message)[:160]}")
        self.scope = str(message.get("scope", ""))

    def _read(self, ws: ClientConnection, deliver: Deliver, generation: int) -> None:
        reason = "robot closed the connection"
        permanent = False
        try:
            for raw in ws:
                message = _object(raw)
                if message is None or not isinstance(message.get("type"), str):
                    excerpt = raw[:200] if isinstance(raw, str) else repr(raw[:60])
                    deliver(Rejected(generation, "frame is not a JSON object with a string \"type\"", excerpt))
                    continue
                if message["type"] == "response.auth" and message.get("access") is not True:
                    reason = f"{self.url} withdrew access: response.auth {json.dumps(message)[:160]}"
                    permanent = True
                    ws.close()
                    break
                kind = REPLIES.get(message["type"])
                if kind is not None:
                    ref = message.get("request_id")
                    deliver(Reply(generation, kind, ref if isinstance(ref, str) else None, message["type"],
                                  aborted=message.get("aborted") is True, failed=message.get("failed") is True))
        except ConnectionClosed as exc:
            reason = f"connection lost: {exc}"
        except BaseException as exc:  # noqa: BLE001 - whatever kills the reader is reported, never silent
            reason = f"reader failed: {type(exc).__name__}: {exc}"
            log.exception("robot %s: reader failed", self.url)
        deliver(Disconnected(generation, reason, permanent=permanent))

    def ready(self, wire: Wire) -> str:
        return ""  # the robot itself is the other end: connected means it listens

    def send(self, wire: Wire) -> None:
        with self._lock:
            ws = self._ws
        if ws is None:
            raise ConnectionError("not connected")
        try:
            ws.send(wire.data)
        except ConnectionClosed as exc:
            raise ConnectionError(f"connection lost: {exc}") from exc

    def close(self) -> None:
        with self._lock:
            ws, self._ws = self._ws, None
        if ws is not None:
            ws.close()


def _open(url: str, proxy: str | None) -> ClientConnection:
    """A connection through `proxy` only if configured (never from http_proxy/https_proxy), closed by us.

    websockets >= 17 wants a plain connection said (legacy=True); before 15 there
    was no proxy support at all, so no flag is needed there.
    """
    for flags in ({"legacy": True, "proxy": proxy}, {"proxy": proxy}, {}):  # >= 17, 15-16, < 15
        if not flags and proxy:
            raise ConnectionError(f"{url}: realtime_proxy needs websockets >= 15")
        try:
            return connect(url, open_timeout=OPEN_TIMEOUT_S, close_timeout=1.0, **flags)
        except TypeError:  # this websockets does not know one of the flags
            continue
    raise ConnectionError(f"{url}: this websockets cannot open a connection")


def _object(raw: str | bytes) -> dict | None:
    """A text frame's JSON object, or None (binary, not JSON, not an object)."""
    if not isinstance(raw, str):
        return None
    try:
        value = json_loads(raw)
    except json.JSONDecodeError:
        return None
    return value if isinstance(value, dict) else None
