"""IrisTK broker client (thesis appendix D): Furhat as the thesis drove it.

Rule: connect over TCP (default port 1932), write `CONNECT <ticket> <name>`, read
until `CONNECTED` (the broker first sends `SUBSCRIBE <filter>` lines: what the
other clients want; taken as information, here and at any later time), then
`SUBSCRIBE monitor.**` for the robot's replies. Commands become events
(iristk_protocol): action.speech {text, abort}, action.speech.stop,
action.gesture {name}, action.gaze {location {class iristk.util.Location, x, y, z},
mode, speed}. The robot confirms speech with monitor.speech.start / .end and
gestures with monitor.gesture.end, each carrying "action" = our event's id.
Leaving writes `CLOSE`. The broker relays an event only to clients subscribed
at that moment and keeps nothing, so while its latest SUBSCRIBE line says that
no other client wants an event (the robot has not joined yet, or not again after
a broker restart), that event is held back, in order, until one does, for at
most RobotConfig.iristk_subscriber_wait_s (then it goes anyway, and that filter
is not trusted again until the broker sends another: the broker's word is
information, and a broker whose SUBSCRIBE lines mean something else must not
silence or slow the robot); before any SUBSCRIBE line, we send. Every frame from the broker that cannot be read is
reported (Rejected) and skipped; the connection goes on.
"""

from __future__ import annotations

import logging
import socket
import threading
import time

from pairplay.schemas.robot import RobotConfig

from pairplay.services.robot.iristk_protocol import (
    LOCATION_CLASS, BadFrame, EventFrame, FrameReader, Line, NameFilter, decode_event, event_frame,
    make_event,
)
from pairplay.services.robot.render import Command, Gesture, Look, Say, StopSpeech
from pairplay.services.robot.transport import (
    GESTURE_END, SPEECH_END, SPEECH_START, Changed, Deliver, Disconnected, Rejected, Reply, Wire,
)

log = logging.getLogger("pairplay.robot.iristk")

# The robot's replies we listen for: IrisTK event name -> reply kind.
REPLIES = {"monitor.speech.start": SPEECH_START, "monitor.speech.end": SPEECH_END,
           "monitor.gesture.end": GESTURE_END}
HANDSHAKE_TIMEOUT_S = 5.0


class IrisTKTransport:
    def __init__(self, host: str, port: int, config: RobotConfig) -> None:
        self.host, self.port, self.config = host, port, config
        self.url = f"iristk://{host}:{port}"
        self.broker_filter: str | None = None  # the latest SUBSCRIBE line of this connection
        self._sock: socket.socket | None = None
        self._lock = threading.Lock()
        self._holding: tuple[Wire, float] | None = None  # the wire held back, since when
        self._distrusted: str | None = None  # a broker filter that proved wrong once: no more holding

    # -- encoding -------------------------------------------------------------------------
    def encode(self, command: Command, command_id: str, time_ns: int) -> Wire:
        cfg = self.config
        agent = cfg.iristk_agent or None  # None fields are dropped: no JSON nulls
        replies: tuple[str, ...] = ()
        if isinstance(command, Say):
            event = make_event("action.speech", command_id, cfg.iristk_name, time_ns,
                               text=command.text, abort=command.abort, agent=agent)
            replies = (SPEECH_START, SPEECH_END)
        elif isinstance(command, StopSpeech):
            event = make_event("action.speech.stop", command_id, cfg.iristk_name, time_ns, agent=agent)
        elif isinstance(command, Gesture):
            event = make_event("action.gesture", command_id, cfg.iristk_name, time_ns, name=command.name, agent=agent)
            replies = (GESTURE_END,) if cfg.iristk_gesture_replies else ()
        elif isinstance(command, Look):
            location = {"class": LOCATION_CLASS, "x": command.x, "y": command.y, "z": command.z}
            event = make_event("action.gaze", command_id, cfg.iristk_name, time_ns, location=location,
                               mode=cfg.head_mode if command.head else cfg.gaze_mode,
                               speed=cfg.gaze_speed, agent=agent)
        else:
            raise TypeError(f"no IrisTK event for {command!r}")
        frame = event_frame(event)
        return Wire(frame, frame.decode(), replies, event["event_name"])

    def ready(self, wire: Wire) -> str:
        spec = self.broker_filter
        if spec is None or spec == self._distrusted or NameFilter(spec).matches(wire.name):
            self._holding = None
            return ""
        now = time.monotonic()
        if self._holding is None or self._holding[0] is not wire:
            self._holding = (wire, now)
        if now - self._holding[1] >= self.config.iristk_subscriber_wait_s:
            log.warning("broker %s: still no subscriber for %s after %.1f s (filter %r); sending anyway,"
                        " and not holding again until the broker's filter changes",
                        self.url, wire.name, self.config.iristk_subscriber_wait_s, spec)
            self._holding = None
            self._distrusted = spec
            return ""
        return f"no client of the broker subscribes to {wire.name} (broker's filter {spec!r})"

    # -- connection -----------------------------------------------------------------------
    def connect(self, deliver: Deliver, generation: int) -> None:
        sock = socket.create_connection((self.host, self.port), timeout=HANDSHAKE_TIMEOUT_S)
        try:
            sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
            _keepalive(sock)
            sock.sendall(f"CONNECT {self.config.iristk_ticket} {self.config.iristk_name}\n".encode())
            reader = FrameReader()
            self.broker_filter = None
            early = self._handshake(sock, reader, deliver, generation)
            sock.sendall(f"SUBSCRIBE {self.config.iristk_subscribe}\n".encode())
            sock.settimeout(None)
        except (OSError, ConnectionError):
            sock.close()
            raise
        with self._lock:
            self._sock = sock
        threading.Thread(target=self._read, args=(sock, reader, early, deliver, generation),
                         name=f"iristk reader {self.url}", daemon=True).start()

    def _handshake(self, sock: socket.socket, reader: FrameReader, deliver: Deliver, generation: int) -> list:
        """Read up to CONNECTED; return frames that came after it in the same read."""
        while True:
            try:
                data = sock.recv(65536)
            except socket.timeout:
                raise ConnectionError(f"broker did not answer CONNECT with CONNECTED within {HANDSHAKE_TIMEOUT_S:g} s") from None
            if not data:
                raise ConnectionError("broker closed the connection during CONNECT (wrong ticket?)")
            frames = reader.feed(data)
            for i, frame in enumerate(frames):
                if isinstance(frame, Line) and frame.text == "CONNECTED":
                    return frames[i + 1:]
                self._on_frame(frame, deliver, generation)

    def _read(self, sock: socket.socket, reader: FrameReader, early: list, deliver: Deliver, generation: int) -> None:
        for frame in early:
            self._on_frame(frame, deliver, generation)
        reason = "broker closed the connection"
        while True:
            try:
                data = sock.recv(65536)
            except OSError as exc:
                reason = f"read failed: {exc}"
                break
            if not data:
                break
            for frame in reader.feed(data):
                self._on_frame(frame, deliver, generation)
        deliver(Disconnected(generation, reason))

    def _on_frame(self, frame, deliver: Deliver, generation: int) -> None:
        if isinstance(frame, Line):
            if frame.text == "SUBSCRIBE" or frame.text.startswith("SUBSCRIBE "):
                self.broker_filter = frame.text[len("SUBSCRIBE "):]
                if self.broker_filter != self._distrusted:
                    self._distrusted = None  # the broker's word changed: worth believing again
                deliver(Changed(generation))
            elif frame.text != "CONNECTED":
                deliver(Rejected(generation, f"unknown line from the broker: {frame.text[:60]!r}", frame.text[:200]))
        elif isinstance(frame, BadFrame):
            deliver(Rejected(generation, frame.reason, frame.excerpt.decode("utf-8", "replace")))
        elif isinstance(frame, EventFrame):
            try:
                event = decode_event(frame)
            except ValueError as exc:
                deliver(Rejected(generation, str(exc), frame.payload[:200].decode("utf-8", "replace")))
                return
            kind = REPLIES.get(frame.name)
            if kind is not None:
                ref = event.get("action")
                deliver(Reply(generation, kind, ref if isinstance(ref, str) else None, frame.name,
                              aborted=event.get("aborted") is True))

    def send(self, wire: Wire) -> None:
        with self._lock:
            sock = self._sock
        if sock is None:
            raise ConnectionError("not connected")
        if _peer_closed(sock):  # the broker left and our reader has not said so yet
            raise ConnectionError("broker closed the connection")
        sock.sendall(wire.data if isinstance(wire.data, bytes) else wire.data.encode())

    def close(self) -> None:
        """Say CLOSE if the line is still up, then release the socket."""
        with self._lock:
            sock, self._sock = self._sock, None
        if sock is None:
            return
        try:
            sock.sendall(b"CLOSE\n")
            sock.shutdown(socket.SHUT_RDWR)  # sends what is buffered, then wakes our reader
        except OSError:
            pass  # already gone: nothing more to say
        sock.close()



def _keepalive(sock: socket.socket) -> None:
    """TCP keepalive: a broker that vanished without closing (cable, power) is noticed in ~11 s."""
    sock.setsockopt(socket.SOL_SOCKET, socket.SO_KEEPALIVE, 1)
    for option, value in (("TCP_KEEPIDLE", 5), ("TCP_KEEPINTVL", 2), ("TCP_KEEPCNT", 3)):
        if hasattr(socket, option):  # Linux names; elsewhere the system defaults stay
            sock.setsockopt(socket.IPPROTO_TCP, getattr(socket, option), value)


def _peer_closed(sock: socket.socket) -> bool:
    """True if the broker's end is closed (EOF waiting), without consuming any data.

    A write to a connection the broker already closed still "succeeds" locally
    and is lost; checking first leaves only the in-flight window, which no TCP
    client can close (IrisTK has no acknowledgement for most events).
    """
    try:
        return sock.recv(1, socket.MSG_PEEK | socket.MSG_DONTWAIT) == b""
    except BlockingIOError:
        return False
    except OSError:
        return True
