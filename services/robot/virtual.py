"""The virtual robot, the default backend: a session runs with no hardware.

Rule: it behaves as a robot does on the wire, in-process: it "performs" each
command at once (logged and kept in `performed`), confirms speech with a start
and an end (the end after SPEECH_S_PER_WORD per word, times `time_scale`), a
gesture with an end after GESTURE_S, and a newer speech or a stop ends the
current speech early. Its wire messages are the neutral commands as JSON with
their id, so a recording shows what a robot would have been asked to do.
Its delayed replies wait in one heap served by the driver's own worker
(services/robot/driver.py): `due()` says when the earliest is due, the worker
sleeps until then and `serve_due()` hands on what is due. No thread of its own
(there was one per transport, started by its first delayed reply: where a thread
could not start, `ulimit -v`, the driver's tick failed with a traceback and no
later reply of that robot ever came, its suggestions recorded unacknowledged).
"""

from __future__ import annotations

import heapq
import itertools
import logging
import threading
import time

import msgspec

from pairplay.services.robot.render import Command, Gesture, Say, StopSpeech
from pairplay.services.robot.transport import GESTURE_END, SPEECH_END, SPEECH_START, Deliver, Reply, Wire
from pairplay.schemas.nesting import json_loads

log = logging.getLogger("pairplay.robot.virtual")

SPEECH_S_PER_WORD = 0.3
GESTURE_S = 0.8
_encode = msgspec.json.Encoder().encode


class VirtualTransport:
    url = "virtual"
    connects_at_once = True  # in-process: its connect cannot block (transport.py)

    def __init__(self, time_scale: float = 1.0) -> None:
        if time_scale < 0:
            raise ValueError(f"virtual robot time_scale must be >= 0, got {time_scale}")
        self.time_scale = time_scale
        self.performed: list[tuple[int, str]] = []  # (time ns, wire text)
        self._deliver: Deliver | None = None
        self._generation = 0
        self._due: list[tuple[float, int, str, str, str, bool]] = []  # heap: (when, n, kind, id, name, speech)
        self._order = itertools.count()
        self._speaking: str | None = None  # id of the speech playing now
        self._lock = threading.Lock()

    def encode(self, command: Command, command_id: str, time_ns: int) -> Wire:
        body = _encode(command).decode()  # '{"type":...}': the id goes first, as a field of the same object
        text = _encode({"id": command_id}).decode()[:-1] + "," + body[1:]
        replies = (SPEECH_START, SPEECH_END) if isinstance(command, Say) else \
            (GESTURE_END,) if isinstance(command, Gesture) else ()
        return Wire(text, text, replies)

    def connect(self, deliver: Deliver, generation: int) -> None:
        self._deliver, self._generation = deliver, generation

    def ready(self, wire: Wire) -> str:
        return ""

    def send(self, wire: Wire) -> None:
        if self._deliver is None:
            raise ConnectionError("virtual robot not connected")
        message = json_loads(wire.data)
        self.performed.append((time.time_ns(), wire.text))
        log.debug("virtual robot performs %s", wire.text)  # RobotActed records it; a session stays readable
        kind, command_id = message["type"], message["id"]
        if kind in ("say", StopSpeech.__struct_config__.tag):
            self._end_current_speech()
        if kind == "say":
            with self._lock:
                self._speaking = command_id
            self._reply(SPEECH_START, command_id, "speech.start", 0.0)
            words = max(1, len(message["text"].split()))
            self._reply(SPEECH_END, command_id, "speech.end", words * SPEECH_S_PER_WORD, speech=True)
        elif kind == "gesture":
            self._reply(GESTURE_END, command_id, "gesture.end", GESTURE_S)

    def _end_current_speech(self) -> None:
        with self._lock:
            current, self._speaking = self._speaking, None
        if current is not None:
            self._emit(SPEECH_END, current, "speech.end", aborted=True)

    def _reply(self, kind: str, command_id: str, name: str, after_s: float, speech: bool = False) -> None:
        delay = after_s * self.time_scale
        if delay <= 0:
            self._fire(kind, command_id, name, speech)
            return
        with self._lock:
            heapq.heappush(self._due, (time.monotonic() + delay, next(self._order), kind, command_id, name, speech))

    def due(self) -> float | None:
        """When the earliest delayed reply is due (time.monotonic), None if none waits: the driver's
        worker wakes then (its `_next_wakeup`)."""
        with self._lock:
            return self._due[0][0] if self._due else None

    def serve_due(self, now: float) -> None:
        """Hand on every reply due by `now`, in order (the driver's worker, each tick)."""
        with self._lock:
            due = []
            while self._due and self._due[0][0] <= now:
                due.append(heapq.heappop(self._due))
        for _, _, kind, command_id, name, speech in due:
            self._fire(kind, command_id, name, speech)

    def _fire(self, kind: str, command_id: str, name: str, speech: bool) -> None:
        if speech:
            with self._lock:
                if self._speaking != command_id:
                    return  # aborted: its end was already reported
                self._speaking = None
        self._emit(kind, command_id, name)

    def _emit(self, kind: str, command_id: str, name: str, aborted: bool = False) -> None:
        deliver = self._deliver
        if deliver is not None:
            deliver(Reply(self._generation, kind, command_id, name, aborted))

    def close(self) -> None:
        with self._lock:
            self._due.clear()
            self._speaking = None
        self._deliver = None
