"""IrisTK broker client (thesis appendix D): Furhat as the thesis drove it, as IrisTK's BrokerClient does.

Rule: connect over TCP (default port 1932), write `CONNECT <ticket> <name>`, read
until `CONNECTED` (the broker first sends `SUBSCRIBE <filter>`: what the other
clients of the ticket want), then `SUBSCRIBE monitor.**` for the robot's replies.
Commands become events (iristk_protocol): action.speech {text, abort},
action.speech.stop, action.gesture {name}, action.gaze {location, mode, speed}
(or, with iristk_head_event "attend", head turns as action.attend {location,
mode, speed, agent} for an IrisTK SystemAgentFlow). The robot confirms speech
with monitor.speech.start / .end and gestures with monitor.gesture.end, each
carrying "action" = our event's id; a monitor.speech.end with "stopped" (ms)
means the speech was cut short.

The broker's latest SUBSCRIBE line is the truth about who listens: the broker
relays an event only to clients subscribed at that moment and keeps nothing, and
IrisTK's own BrokerClient sends nothing its filter rejects, starting from NONE
(BrokerClient.java 37, 124-130). So an event that no other client subscribes to
is held, in order, never written into the void; the driver gives it up as
unsent after give_up_s. A reader that ends for any reason (EOF, a read error,
an unreadable EVENT header, the broker's CLOSE, a bug) reports Disconnected
with the reason and the driver re-makes the connection. Leaving writes `CLOSE`
and then reads on until the broker closes its end (Broker.java 264-267 closes
the socket after removing the client), so the broker never writes into a socket
we already closed.
"""

from __future__ import annotations

import logging
import socket
import threading

from pairplay.schemas.robot import RobotConfig

from pairplay.services.robot.iristk_protocol import (
    LOCATION_CLASS, BadFrame, EventFrame, FrameReader, Line, NameFilter, decode_event, event_frame,
    make_event, subscribe_filter,
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
CLOSE_WAIT_S = 1.0  # after CLOSE, how long we read on for the broker to close its end


class IrisTKTransport:
    def __init__(self, host: str, port: int, config: RobotConfig) -> None:
        self.host, self.port, self.config = host, port, config
        self.url = f"iristk://{host}:{port}"
        self.broker_filter: str | None = None  # the latest SUBSCRIBE of this connection (None: none yet)
        self._filter: NameFilter | None = None
        self._sock: socket.socket | None = None
        self._reader_done: threading.Event | None = None
        self._lock = threading.Lock()

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
            name = "action.attend" if command.head and cfg.iristk_head_event == "attend" else "action.gaze"
            event = make_event(name, command_id, cfg.iristk_name, time_ns, location=location,
                               mode=cfg.head_mode if command.head else cfg.gaze_mode,
                               speed=cfg.head_speed if command.head else cfg.gaze_speed, agent=agent)
        else:
            raise TypeError(f"no IrisTK event for {command!r}")
        frame = event_frame(event)
        return Wire(frame, frame.decode(), replies, event["event_name"])

    def ready(self, wire: Wire) -> str:
        """"" if some other client of the broker subscribes to this event, else why it waits."""
        spec, compiled = self.broker_filter, self._filter
        if spec is None or compiled is None:
            return "the broker has not said yet who subscribes (no SUBSCRIBE line)"
        if compiled.matches(wire.name):
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
            self.broker_filter, self._filter = None, None
            early = self._handshake(sock, reader, deliver, generation)
            sock.sendall(f"SUBSCRIBE {self.config.iristk_subscribe}\n".encode())
            sock.settimeout(None)
        except (OSError, ConnectionError):
            sock.close()
            raise
        done = threading.Event()
        with self._lock:
            self._sock, self._reader_done = sock, done
        threading.Thread(target=self._read, args=(sock, reader, early, deliver, generation, done),
                         name=f"iristk reader {self.url}", daemon=True).start()

    def _handshake(self, sock: socket.socket, reader: FrameReader, deliver: Deliver, generation: int) -> list:
        """Read up to CONNECTED; return frames that came after it in the same read."""
        while True:
            try:
                data = sock.recv(65536)
            except socket.timeout:
                raise ConnectionError(f"broker did not answer CONNECT with CONNECTED within {HANDSHAKE_TIMEOUT_S:g} s") from None
            if not data:
                raise ConnectionError("broker closed the connection during CONNECT")
            frames = reader.feed(data)
            for i, frame in enumerate(frames):
                if isinstance(frame, Line) and frame.text == "CONNECTED":
                    return frames[i + 1:]
                ended = self._on_frame(frame, deliver, generation)
                if ended:
                    raise ConnectionError(f"during CONNECT: {ended}")

    def _read(self, sock: socket.socket, reader: FrameReader, early: list, deliver: Deliver, generation: int,
              done: threading.Event) -> None:
        reason = ""
        try:
            for frame in early:
                reason = reason or self._on_frame(frame, deliver, generation)
            while not reason:
                try:
                    data = sock.recv(65536)
                except OSError as exc:
                    reason = f"read failed: {exc}"
                    break
                if not data:
                    reason = "broker closed the connection"
                    break
                for frame in reader.feed(data):
                    reason = reason or self._on_frame(frame, deliver, generation)
        except BaseException as exc:  # noqa: BLE001 - whatever kills the reader is reported, never silent
            reason = f"reader failed: {type(exc).__name__}: {exc}"
            log.exception("broker %s: reader failed", self.url)
        finally:
            done.set()
            deliver(Disconnected(generation, reason or "reader ended"))

    def _on_frame(self, frame, deliver: Deliver, generation: int) -> str:
        """Handle one frame; a non-empty return ends the connection (with that reason)."""
        if isinstance(frame, Line):
            spec = subscribe_filter(frame.text)
            if spec is not None:
                try:
                    compiled = NameFilter(spec)
                except ValueError as exc:
                    deliver(Rejected(generation, f"SUBSCRIBE from the broker refused: {exc}", frame.text[:200]))
                    return ""
                self.broker_filter, self._filter = spec, compiled
                deliver(Changed(generation))
            elif frame.text == "CLOSE":
                return "the broker sent CLOSE"
            elif frame.text != "CONNECTED":
                deliver(Rejected(generation, f"unknown line from the broker: {frame.text[:60]!r}", frame.text[:200]))
        elif isinstance(frame, BadFrame):
            deliver(Rejected(generation, frame.reason, frame.excerpt.decode("utf-8", "replace")))
            if frame.fatal:
                return f"unreadable stream from the broker: {frame.reason}"
        elif isinstance(frame, EventFrame):
            try:
                event = decode_event(frame)
            except ValueError as exc:
                deliver(Rejected(generation, str(exc), frame.payload[:200].decode("utf-8", "replace")))
                return ""
            kind = REPLIES.get(frame.name)
            ref = event.get("action")
            if kind is not None and isinstance(ref, str):  # no "action": not about one of our events
                stopped = event.get("stopped") if kind == SPEECH_END else None
                detail = ""
                if stopped is not None:
                    detail = (f"stopped at {stopped} ms" if isinstance(stopped, (int, float)) and not isinstance(stopped, bool)
                              else f"stopped ({str(stopped)[:40]!r})")
                deliver(Reply(generation, kind, ref, frame.name, stopped=stopped is not None, detail=detail))
        return ""

    def send(self, wire: Wire) -> None:
        with self._lock:
            sock = self._sock
        if sock is None:
            raise ConnectionError("not connected")
        if _peer_closed(sock):  # the broker left and our reader has not said so yet
            raise ConnectionError("broker closed the connection")
        sock.sendall(wire.data if isinstance(wire.data, bytes) else wire.data.encode())

    def close(self) -> None:
        """Say CLOSE if the line is still up, read on until the broker closes its end, release the socket."""
        with self._lock:
            sock, self._sock = self._sock, None
            done = self._reader_done
        if sock is None:
            return
        try:
            sock.sendall(b"CLOSE\n")
            if done is not None and not done.is_set():
                done.wait(CLOSE_WAIT_S)  # our reader sees the broker's EOF (and records late replies)
            else:
                _drain(sock, CLOSE_WAIT_S)
        except OSError:
            pass  # already gone: nothing more to say
        sock.close()


def _drain(sock: socket.socket, timeout: float) -> None:
    """Read and discard until EOF or timeout (the reader is gone, the broker may still write)."""
    sock.settimeout(timeout)
    try:
        while sock.recv(65536):
            pass
    except OSError:
        pass


def _keepalive(sock: socket.socket) -> None:
    """TCP keepalive: a broker that vanished without closing (cable, power) is noticed in ~11 s."""
    sock.setsockopt(socket.SOL_SOCKET, socket.SO_KEEPALIVE, 1)
    for option, value in (("TCP_KEEPIDLE", 5), ("TCP_KEEPINTVL", 2), ("TCP_KEEPCNT", 3)):
        if hasattr(socket, option):  # Linux names; elsewhere the system defaults stay
            sock.setsockopt(socket.IPPROTO_TCP, getattr(socket, option), value)


def _peer_closed(sock: socket.socket) -> bool:
    """True if the broker's end is closed (EOF waiting), without consuming any data.

    A write to a connection the broker already closed still "succeeds" locally
    and is lost; checking first leaves only the in-flight window (the driver
    records commands written in it as unconfirmed).
    """
    try:
        return sock.recv(1, socket.MSG_PEEK | socket.MSG_DONTWAIT) == b""
    except BlockingIOError:
        return False
    except OSError:
        return True
