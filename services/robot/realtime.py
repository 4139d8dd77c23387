"""Furhat Realtime API client: today's Furhat robots (WebSocket, JSON with a "type").

Rule: open ws://<robot>:9000/v1/events and send request.auth, as the robot
maker's own client does; with a configured key, wait for response.auth with
"access": true (false is an error), without one go on at once (a later
refusal ends the connection with the reason). Then commands become
  Say        request.speak.text {text, abort}
  StopSpeech request.speak.stop
  Gesture    request.gesture.start {name, intensity, duration, monitor: true}
  Look       request.attend.location {x, y, z}            (eyes at a card)
  Look(head) request.face.headpose {yaw, pitch, roll, relative: false}   (head turn)
Each request carries a "request_id" (as the robot's own Python client does); the
robot echoes it on response.speak.start / response.speak.end /
response.gesture.end, which is how replies find their suggestion; a
response.speak.end with "aborted": true marks the suggestion aborted. Headpose
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

from websockets.exceptions import ConnectionClosed, InvalidHandshake, InvalidURI
from websockets.sync.client import ClientConnection, connect

from pairplay.schemas.robot import RobotConfig

from pairplay.services.robot.render import Command, Gesture, Look, Say, StopSpeech
from pairplay.services.robot.transport import GESTURE_END, SPEECH_END, SPEECH_START, Deliver, Disconnected, Rejected, Reply, Wire

log = logging.getLogger("pairplay.robot.realtime")

DEFAULT_PORT = 9000
PATH = "/v1/events"
REPLIES = {"response.speak.start": SPEECH_START, "response.speak.end": SPEECH_END,
           "response.gesture.end": GESTURE_END}
OPEN_TIMEOUT_S = 5.0


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
        message["request_id"] = command_id
        text = json.dumps(message, separators=(",", ":"))
        return Wire(text, text, replies)

    def connect(self, deliver: Deliver, generation: int) -> None:
        try:
            ws = _open(self.ws_url)
        except (InvalidHandshake, InvalidURI) as exc:
            raise ConnectionError(f"{self.ws_url}: {exc}") from exc
        try:
            self._authenticate(ws)
        except BaseException:
            ws.close()
            raise
        with self._lock:
            self._ws = ws
        threading.Thread(target=self._read, args=(ws, deliver, generation),
                         name=f"realtime reader {self.url}", daemon=True).start()

    def _authenticate(self, ws: ClientConnection) -> None:
        request = {"type": "request.auth", "request_id": "pairplay.auth"}
        if self.config.realtime_key:
            request["key"] = self.config.realtime_key
        try:
            ws.send(json.dumps(request))
            if not self.config.realtime_key:
                return  # as the maker's client does, ask; without a key, do not wait (a refusal ends the link)
            while True:
                raw = ws.recv(timeout=OPEN_TIMEOUT_S)
                message = _object(raw)
                if message is not None and message.get("type") == "response.auth":
                    break
        except TimeoutError:
            raise ConnectionError(f"robot did not answer request.auth within {OPEN_TIMEOUT_S:g} s") from None
        except ConnectionClosed as exc:
            raise ConnectionError(f"robot closed the connection during auth: {exc}") from None
        if message.get("access") is not True:
            raise PermissionError(f"robot refused access (response.auth {json.dumps(message)[:200]})")
        self.scope = str(message.get("scope", ""))

    def _read(self, ws: ClientConnection, deliver: Deliver, generation: int) -> None:
        reason = "robot closed the connection"
        try:
            for raw in ws:
                message = _object(raw)
                if message is None or not isinstance(message.get("type"), str):
                    excerpt = raw[:200] if isinstance(raw, str) else repr(raw[:60])
                    deliver(Rejected(generation, "frame is not a JSON object with a string \"type\"", excerpt))
                    continue
                if message["type"] == "response.auth" and message.get("access") is not True:
                    reason = f"robot refused access (response.auth {json.dumps(message)[:200]})"
                    ws.close()
                    break
                kind = REPLIES.get(message["type"])
                if kind is not None:
                    ref = message.get("request_id")
                    deliver(Reply(generation, kind, ref if isinstance(ref, str) else None, message["type"],
                                  aborted=message.get("aborted") is True))
        except ConnectionClosed as exc:
            reason = f"connection lost: {exc}"
        deliver(Disconnected(generation, reason))

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


def _open(url: str) -> ClientConnection:
    """A plain connection we close ourselves (websockets >= 17 wants that said: legacy=True)."""
    try:
        return connect(url, open_timeout=OPEN_TIMEOUT_S, close_timeout=1.0, legacy=True)
    except TypeError:  # websockets < 17: no such flag, and this is its only behaviour
        return connect(url, open_timeout=OPEN_TIMEOUT_S, close_timeout=1.0)


def _object(raw: str | bytes) -> dict | None:
    """A text frame's JSON object, or None (binary, not JSON, not an object)."""
    if not isinstance(raw, str):
        return None
    try:
        value = json.loads(raw)
    except json.JSONDecodeError:
        return None
    return value if isinstance(value, dict) else None
