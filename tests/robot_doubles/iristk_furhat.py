"""A test double of a Furhat running IrisTK modules on a broker, written from IrisTK's source.

Rule: it is an IrisSystem with two modules, joined to the broker by a BrokerClient,
each part as IrisTK's core/src/iristk/... has it (read, not copied):
  BrokerClient.java  CONNECT, wait for CONNECTED (10 ms x 100, lines 51-68), then
                     SUBSCRIBE the union of the modules' filters (IrisSystem
                     updateSubscriptions, IrisSystem.java 382-392); an event is
                     kept only if Record.fromJSON makes an iristk.system.Event
                     of it (BrokerClient.java 91-96): no "class" or another class,
                     not JSON, not an object, or a JSON null anywhere drops it
                     (Record.java 653-672, 700-720; minimal-json asString() throws
                     on null). event_time is a plain String (Event.java 86-94):
                     any text is accepted. It sends an event only if the broker's
                     latest SUBSCRIBE accepts it (BrokerClient.java 124-130), as
                     `EVENT <name> <len>` + JSON. IrisTK's BrokerClient never
                     rejoins a broker (its reader spins on "" at EOF); `rejoin=True`
                     stands for a lab that restarts the robot's system.
  IrisModule.java    each module has an event queue of `queue_limit` (1000, line 24);
                     when an add finds it full the module logs "Event queue full" and
                     takes no event ever again (lines 135-142): `disabled`.
  SynthesizerModule  subscribes "action.speech** monitor.lipsync** action.voice"
                     plus "*.system.** *.module.**" (SynthesizerModule.java 133,
                     IrisModule.java 52); ignores events whose "agent" is not its own
                     (171); action.speech is queued, "abort": true clears the queue
                     and stops the current utterance (188-193); a stopped utterance
                     ends with monitor.speech.end {action, stopped: ms} (469-477);
                     one aborted before it started sends nothing (363);
                     action.speech.stop clears and stops (211-214, 234-237).
                     Each utterance: monitor.speech.start {action, text, length}
                     then, after speech_s, monitor.speech.end {action}.
  face module        (the Furhat's own is in furhat-skill.jar, not readable; this
                     follows situated/VirtualAgent.java): action.gesture ->
                     monitor.gesture.end {action} (lines 19-22), but only for a
                     gesture it has (`gestures`, default IrisTK's stock
                     addon/Face/gestures.xml names; set confirm_any=True for
                     VirtualAgent's behaviour); action.gaze needs a location with
                     numbers x, y, z (24-28) and answers monitor.gaze.
  SystemAgentFlow    with `system_agent` set: action.attend with a location of class
                     iristk.situated.Location and "agent" equal to it becomes a gaze
                     with its mode and speed (SystemAgentFlow.xml 33-35, 129-137).
Everything performed is kept in `performed` (event name, event), everything
dropped in `dropped` (event name, why).
"""

from __future__ import annotations

import json
import queue
import socket
import threading
import time

from robot_doubles.javaish import JavaNameFilter, java_parse_int, java_split_space

EVENT_CLASS = "iristk.system.Event"
SYNTH_FILTER = "action.speech** monitor.lipsync** action.voice *.system.** *.module.**"
FACE_FILTER = "action.gesture action.gaze action.attend *.system.** *.module.**"
STOCK_GESTURES = frozenset({  # addon/Face/gestures.xml
    "nod", "shake", "smile", "brow_up", "brow_down", "brow_raise", "brow_frown", "sleep", "wake_up",
    "blink", "gaze_away", "express_disgust", "express_sad", "emotion_anger", "emotion_disgust",
    "emotion_fear", "emotion_sad", "emotion_neutral", "smile_on", "smile_off"})


def has_null(value) -> bool:
    if value is None:
        return True
    if isinstance(value, dict):
        return any(has_null(v) for v in value.values())
    if isinstance(value, list):
        return any(has_null(v) for v in value)
    return False


def _number(value) -> bool:
    return isinstance(value, (int, float)) and not isinstance(value, bool)


class _Module:
    """An IrisModule: a bounded queue, a thread, and a handler that may be slow."""

    def __init__(self, name: str, spec: str, handler, queue_limit: int, process_s: float, furhat) -> None:
        self.name, self.filter, self.handler = name, JavaNameFilter(spec), handler
        self.queue: queue.Queue = queue.Queue(maxsize=queue_limit)
        self.process_s, self.furhat = process_s, furhat
        self.healthy = True
        threading.Thread(target=self._run, daemon=True, name=f"furhat {name}").start()

    def invoke(self, name: str, event: dict) -> None:
        if not self.healthy:
            return
        try:
            self.queue.put_nowait((name, event))
        except queue.Full:  # IrisModule.invokeEvent: "Event queue full", and never again
            self.healthy = False
            self.furhat._note("disabled", self.name)

    def _run(self) -> None:
        while True:
            name, event = self.queue.get()
            if self.process_s:
                time.sleep(self.process_s)
            try:
                self.handler(name, event)
            except Exception as exc:  # IrisModule.run logs "Problem processing event" and goes on
                self.furhat._note("dropped", (name, f"{type(exc).__name__}: {exc}"))


class IrisTKFurhat:
    def __init__(self, port: int, ticket: str = "furhat", name: str = "furhat", speech_s: float = 0.05,
                 agent: str | None = None, gestures: frozenset[str] = STOCK_GESTURES, confirm_any: bool = False,
                 system_agent: str | None = None, queue_limit: int = 1000, process_s: float = 0.0,
                 rejoin: bool = True) -> None:
        self.port, self.ticket, self.name, self.speech_s = port, ticket, name, speech_s
        self.agent, self.gestures, self.confirm_any = agent, gestures, confirm_any
        self.system_agent, self.rejoin = system_agent, rejoin
        self.performed: list[tuple[str, dict]] = []
        self.dropped: list[tuple[str, str]] = []  # (event name, why)
        self.disabled: list[str] = []  # modules whose queue overflowed
        self.replies: list[dict] = []
        self.joins = 0  # how many times it (re)joined the broker
        self._changed = threading.Condition()
        self._sock: socket.socket | None = None
        self._send_lock = threading.Lock()
        self._broker_filter = JavaNameFilter("")  # BrokerClient.brokerSubscribes starts as NONE
        self._counter = 0
        self._closed = False
        # the synthesizer's state (SynthesizerModule's speechQueue and current SpeechAction)
        self._speech_lock = threading.Lock()
        self._speech_queue: list[dict] = []
        self._current: dict | None = None
        self._wake = threading.Condition(self._speech_lock)
        self.modules = [
            _Module("synthesizer", SYNTH_FILTER, self._synthesizer, queue_limit, process_s, self),
            _Module("face", FACE_FILTER, self._face, queue_limit, process_s, self),
        ]
        threading.Thread(target=self._speech_thread, daemon=True, name="furhat speech").start()

    # -- lifecycle ------------------------------------------------------------------------
    def start(self) -> "IrisTKFurhat":
        self._closed = False
        self._join()
        return self

    def _join(self) -> None:
        sock = socket.create_connection(("127.0.0.1", self.port))
        sock.sendall(f"CONNECT {self.ticket} {self.name}\n".encode())
        stream = sock.makefile("rb")
        deadline = time.monotonic() + 1.0
        while time.monotonic() < deadline:
            line = stream.readline()
            if not line:
                break
            if line.startswith(b"SUBSCRIBE"):
                self._on_subscribe(line.decode("utf-8", "replace").rstrip("\n"))
            elif line.startswith(b"CONNECTED"):
                break
        union = JavaNameFilter("")
        for module in self.modules:
            union = union.combine(module.filter)
        sock.sendall(f"SUBSCRIBE {union}\n".encode())
        self._sock = sock
        with self._changed:
            self.joins += 1
            self._changed.notify_all()
        threading.Thread(target=self._read, args=(stream,), daemon=True, name="furhat reader").start()

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
                self._sock.shutdown(socket.SHUT_WR)
                self._sock.settimeout(1.0)
                while self._sock.recv(65536):
                    pass
            except OSError:
                pass
            self._sock.close()

    def wait_for(self, predicate, timeout: float = 30.0) -> bool:  # a bound, not a measure
        with self._changed:
            return self._changed.wait_for(lambda: predicate(self), timeout)

    def _note(self, attr: str, value) -> None:
        with self._changed:
            getattr(self, attr).append(value)
            self._changed.notify_all()

    # -- BrokerClient ---------------------------------------------------------------------
    def _on_subscribe(self, line: str) -> None:
        if len(line.strip()) == 9:
            self._broker_filter = JavaNameFilter("")
        else:
            self._broker_filter = JavaNameFilter(line[10:].strip())

    def _read(self, stream) -> None:
        try:
            while line := stream.readline():
                text = line.decode("utf-8", "replace").rstrip("\n")
                if text.startswith("EVENT"):
                    cols = java_split_space(text)
                    payload = stream.read(java_parse_int(cols[2]))
                    self._event(cols[1], payload)
                elif text.startswith("SUBSCRIBE"):
                    self._on_subscribe(text)
        except (OSError, ValueError, IndexError):
            pass
        if not self._closed and self.rejoin:
            self._rejoin()

    def _event(self, name: str, payload: bytes) -> None:
        try:
            event = json.loads(payload.decode("utf-8", "replace"))
        except json.JSONDecodeError:
            return self._note("dropped", (name, "not JSON"))
        if not isinstance(event, dict):
            return self._note("dropped", (name, "not a JSON object"))
        if event.get("class") != EVENT_CLASS:
            return self._note("dropped", (name, "not an iristk.system.Event (class)"))
        if has_null(event):
            return self._note("dropped", (name, "JSON null"))
        for module in self.modules:  # IrisSystem.distributeInternal
            if module.filter.accepts(name):
                module.invoke(name, event)

    def _send(self, event_name: str, **fields) -> None:
        self._counter += 1
        event = {"class": EVENT_CLASS, "event_name": event_name, "event_id": f"{self.name}.{self._counter}",
                 "event_sender": self.name, **fields}
        with self._changed:
            self.replies.append(event)
            self._changed.notify_all()
        if not self._broker_filter.accepts(event_name):
            return  # BrokerClient.send: nobody subscribes, nothing is written
        body = json.dumps(event).encode()
        try:
            with self._send_lock:
                assert self._sock is not None
                self._sock.sendall(f"EVENT {event_name} {len(body)}\n".encode() + body)
        except OSError:
            pass  # the broker went away

    def _mine(self, event: dict) -> bool:
        return "agent" not in event or event["agent"] == self.agent

    # -- SynthesizerModule ----------------------------------------------------------------
    def _synthesizer(self, name: str, event: dict) -> None:
        if not self._mine(event):
            return
        if name == "action.speech":
            self._performed(name, event)
            with self._speech_lock:
                if event.get("abort") is True:
                    self._speech_queue.clear()
                self._speech_queue.append(event)
                if event.get("abort") is True and self._current is not None:
                    self._current["abort"] = True
                self._wake.notify_all()
        elif name == "action.speech.stop":
            self._performed(name, event)
            with self._speech_lock:
                self._speech_queue.clear()
                if self._current is not None:
                    self._current["abort"] = True
                self._wake.notify_all()

    def _speech_thread(self) -> None:
        while True:
            with self._speech_lock:
                self._wake.wait_for(lambda: bool(self._speech_queue))
                event = self._speech_queue.pop(0)
                action = {"event": event, "abort": False}
                self._current = action
            event_id = event.get("event_id", "")
            length_ms = int(self.speech_s * 1000)
            self._send("monitor.speech.start", action=event_id, text=event.get("text", ""), length=length_ms)
            started = time.monotonic()
            with self._speech_lock:
                self._wake.wait_for(lambda: action["abort"], timeout=self.speech_s)
                self._current = None
            position = int((time.monotonic() - started) * 1000)
            if position < length_ms - 100:  # SynthesizerModule.java 471-473
                self._send("monitor.speech.end", action=event_id, stopped=position)
            else:
                self._send("monitor.speech.end", action=event_id)

    # -- the face (VirtualAgent) and SystemAgentFlow --------------------------------------
    def _face(self, name: str, event: dict) -> None:
        if name == "action.attend":
            return self._attend(event)
        if not self._mine(event):
            return
        if name == "action.gesture":
            self._performed(name, event)
            if self.confirm_any or event.get("name") in self.gestures:
                self._send("monitor.gesture.end", action=event.get("event_id", ""))
        elif name == "action.gaze":
            location = event.get("location")
            if not isinstance(location, dict) or not all(_number(location.get(k)) for k in "xyz"):
                return self._note("dropped", (name, "location without numbers x, y, z"))
            self._performed(name, event)
            self._send("monitor.gaze", action=event.get("event_id", ""), location=location)

    def _attend(self, event: dict) -> None:
        location = event.get("location")
        if self.system_agent is None or event.get("agent") != self.system_agent:
            return self._note("dropped", ("action.attend", "no SystemAgentFlow for this agent"))
        if not isinstance(location, dict) or location.get("class") != "iristk.situated.Location" \
                or not all(_number(location.get(k)) for k in "xyz"):
            return self._note("dropped", ("action.attend", "location is not an iristk.situated.Location"))
        self._performed("action.attend", event)

    def _performed(self, name: str, event: dict) -> None:
        self._note("performed", (name, event))
