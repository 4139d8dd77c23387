"""What a robot backend is to the driver: a connection that writes commands and hears replies.

Rule: a Transport turns neutral commands into its protocol's wire messages,
opens a connection (raising ConnectionError with the reason when it cannot), and
reports what the robot says through one callback, from its own reader thread:
  Reply        the robot confirms a command (speech start/end, gesture end);
               `ref` is the id we gave the command, or None if the protocol has none
  Rejected     a frame from the robot that could not be read (kept for the record)
  Disconnected the connection is gone (the driver reconnects with backoff;
               `permanent`: the robot refused us, do not retry: fail at once)
  Changed      the robot side changed who listens (IrisTK: a broker SUBSCRIBE);
               the driver asks `ready(wire)` again for commands it holds back
Only the driver's worker thread calls send and close, so writes never
interleave; connect runs on a thread of its own (it may block up to its
timeouts), never beside a send or another connect: the driver writes nothing
until it returned, and a connection it made after the driver shut down is
closed by that thread. `connects_at_once` (default False) says connect cannot
block (the in-process virtual robot): the worker calls it itself. `generation`
tells a stale reader's reports from the live one's. A transport whose replies
come on its own time without a connection (the virtual robot) may offer
`due()` (when its earliest reply is due, or None) and `serve_due(now)`: the
worker wakes then and calls it, so it needs no thread of its own.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable, Protocol

from pairplay.services.robot.render import Command

SPEECH_START, SPEECH_END, GESTURE_END = "speech.start", "speech.end", "gesture.end"


@dataclass(frozen=True)
class Reply:
    generation: int
    kind: str  # SPEECH_START | SPEECH_END | GESTURE_END
    ref: str | None
    wire_name: str  # the protocol's own name, for the record
    aborted: bool = False  # the robot says it cut this command short (speech end, aborted)
    stopped: bool = False  # the robot says the speech was stopped early (IrisTK "stopped": ms)
    failed: bool = False  # the robot says the command failed (Realtime "failed": true)
    detail: str = ""  # what the robot said about it, for the record ("stopped at 840 ms")


@dataclass(frozen=True)
class Rejected:
    generation: int
    reason: str
    excerpt: str


@dataclass(frozen=True)
class Disconnected:
    generation: int
    reason: str
    permanent: bool = False  # e.g. access refused: retrying cannot help


class AccessRefused(PermissionError):
    """The robot refused us (Realtime response.auth without access): retrying cannot help."""


@dataclass(frozen=True)
class Changed:
    generation: int


Report = Reply | Rejected | Disconnected | Changed
Deliver = Callable[[Report], None]


@dataclass(frozen=True)
class Wire:
    """One encoded command: what to write, its text for the record, promised replies.

    `replies` are the reply kinds whose absence makes the command unconfirmed.
    """

    data: bytes | str
    text: str
    replies: tuple[str, ...] = ()
    name: str = ""  # the protocol's name for the message (IrisTK event name)


class Transport(Protocol):
    url: str  # the backend as RobotActed names it

    def encode(self, command: Command, command_id: str, time_ns: int) -> Wire: ...

    def connect(self, deliver: Deliver, generation: int) -> None: ...

    def ready(self, wire: Wire) -> str:
        """"" if the wire can go now, else why it must wait (nobody listens for it yet)."""
        ...

    def send(self, wire: Wire) -> None: ...

    def close(self) -> None: ...
