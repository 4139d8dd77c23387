"""The robot bridge's contract: the RobotActed event and the robot's config files.

Rule: RobotActed is published once per suggestion, when its fate is known: what
was written on the wire (each message exactly as sent), to which backend, when
the robot acknowledged it, or why it failed. Outcomes:
  "done"           every command sent and every reply the protocol promises came
  "sent"           every command sent; the commands promise no reply (gaze only)
  "superseded"     a newer suggestion came before all its commands were written:
                   it is stale (the participant has picked since), so those not
                   written were dropped, never written (`unsent`); `commands`
                   has what was (often nothing), `error` says by which suggestion.
                   Not if its due commands could not be written (robot
                   unreachable, nobody subscribed): that is "failed"
  "aborted"        every command was written, and a newer suggestion cut its
                   speech short (or the robot reports it aborted); not if the
                   connection died before its reply: "unacknowledged"
  "stopped"        the robot reports its speech stopped early, and not by us
                   (IrisTK monitor.speech.end with "stopped": another client cut it)
  "unacknowledged" sent, but the robot never confirmed within the ack timeout, or
                   a command was written just before the connection died, or the
                   connection died while its reply was awaited (see `unconfirmed`)
  "failed"         not delivered (robot unreachable or not connected yet, nobody
                   subscribed on the broker, access refused, the bridge closed
                   while the robot could not take it; also
                   when a newer suggestion came while it could not be written;
                   see `error` and `unsent`), or the robot reports it failed
                   (Realtime response.speak.end "failed": true)
  "nothing"        the "do nothing" action: nothing to send
  "in-flight"      the session ended while it was on its way: the robot's acknowledgement
                   still awaited (it may have come after the recording closed), or
                   commands the robot could take not yet due (see `unsent`)

The calibration and the robot config are files a researcher edits, so they are
strict: an unknown field is an error, not a silently ignored typo. New fields of
RobotActed get defaults and go at the end (envelope.py rule).
"""

from __future__ import annotations

import re
from typing import ClassVar

import msgspec

from pairplay.numbers import shown

from .envelope import Event, Nanos

# IrisTK's speeds for action.gaze / action.attend (IrisTK doc/markdown/events.md line 301).
IRISTK_SPEEDS = ("x-slow", "slow", "medium", "fast", "x-fast")
# The characters IrisTK's NameFilter.compile accepts (core/src/iristk/util/NameFilter.java line 77);
# the broker refuses a SUBSCRIBE with anything else and the client then receives nothing.
_FILTER_CHARS = re.compile(r"[A-Za-z0-9_!.*; ]*")


def check_name_filter(spec: str) -> None:
    """ValueError unless IrisTK's broker would compile `spec` as a NameFilter."""
    if not _FILTER_CHARS.fullmatch(spec):
        bad = "".join(sorted({c for c in spec if not _FILTER_CHARS.fullmatch(c)}))
        raise ValueError(f"name filter {spec!r} has characters IrisTK refuses: {bad!r}"
                         " (allowed: A-Z a-z 0-9 _ ! . * ; and space)")

OUTCOMES = ("done", "sent", "superseded", "aborted", "stopped", "unacknowledged", "failed", "nothing", "in-flight")


class RobotActed(Event, tag="RobotActed"):
    round: int
    turn: int
    attempt: int
    action: int  # composite action code 0..87
    backend: str  # "virtual", "iristk://host:1932", "furhat://host:9000"
    outcome: str  # one of OUTCOMES
    commands: list[str] = []  # the wire messages, in the order written
    replies: list[str] = []  # the robot's replies about this suggestion, in order
    suggestion_seq: int = 0  # seq of the SuggestionMade it performs
    received_ns: Nanos = 0  # the bridge received the suggestion
    sent_ns: Nanos = 0  # its first command was written on the wire (0: never)
    acked_ns: Nanos = 0  # the robot's first reply about it (0: none)
    done_ns: Nanos = 0  # the robot's last promised reply (0: not all came)
    error: str = ""
    reconnects: int = 0  # connections re-opened while it was pending
    unsent: list[str] = []  # wire messages never written (superseded, held, unreachable, refused), in order
    unconfirmed: list[str] = []  # written, but nothing shows they reached the robot: a promised
    # reply never came, or written within inflight_window_s before the connection died

    def __post_init__(self) -> None:
        super().__post_init__()
        for name in ("received_ns", "sent_ns", "acked_ns", "done_ns"):
            value = getattr(self, name)
            if type(value) is int and value:
                msgspec.structs.force_setattr(self, name, Nanos(value))


class Point(msgspec.Struct, frozen=True, array_like=True):
    """A point in the robot's frame, metres: x to the robot's left, y up, z forward."""

    x: float
    y: float
    z: float


class BoardCalibration(msgspec.Struct, frozen=True, forbid_unknown_fields=True):
    """Where the 18 cards and the participant are, seen from the robot.

    `cards[i]` is the centre of card i = row * 6 + col (rows top to bottom and
    columns left to right as the participant sees the board). `rest` is where
    a head turn ends (the participant's face).
    """

    cards: list[Point]
    rest: Point = Point(0.0, 0.0, 1.0)
    description: str = ""


class GestureNames(msgspec.Struct, frozen=True, forbid_unknown_fields=True):
    """The robot's names for the two gestures of the action table."""

    smile: str
    nod: str


# Gesture name sets: the thesis's robot, IrisTK's shipped gestures, today's Furhat.
# "thesis": smile_open is the thesis's name (appendix D, figure D.4); it is NOT among
# IrisTK's stock gestures (addon/Face/gestures.xml: nod, shake, smile, brow_*, blink,
# smile_on, smile_off, ...), so a robot without it never confirms it: the suggestion
# is then recorded "unacknowledged", the gesture listed in RobotActed.unconfirmed.
GESTURE_PRESETS: dict[str, GestureNames] = {
    "thesis": GestureNames(smile="smile_open", nod="nod"),
    "iristk": GestureNames(smile="smile", nod="nod"),
    "furhat": GestureNames(smile="BigSmile", nod="Nod"),
}
PRESET_NOTES: dict[str, str] = {
    "thesis": "gesture 'smile_open' is the thesis's (appendix D); IrisTK's stock gestures.xml has no such"
              " gesture (it has smile, smile_on, smile_off): install it on the robot, or a smile is never"
              " confirmed (recorded unacknowledged)",
}


class SpeechTexts(msgspec.Struct, frozen=True, forbid_unknown_fields=True):
    """What the robot says for speech codes 1..6 (thesis table 4.1).

    `exact` is formatted with the matching card's 1-based {row} and {column}.
    """

    right_card: str = "It is the right card"
    exact: str = "Try at row {row} and column {column}"
    up: str = "Maybe up"
    down: str = "Maybe down"
    left: str = "Maybe left"
    right: str = "Maybe right"


# each number of the robot config, its range: (lowest, whether the lowest itself is allowed, highest). A time
# beyond its highest is no setting anyone means, and a huge one (1e20 s) overflowed the driver's thread wait
# (OverflowError: timestamp out of range): refused when the file is read, with the range
RANGES = {
    "head_turn_offset_m": (0.0, False, 2.0),  # past the observed card, on a board a metre or so wide
    "ack_timeout_s": (0.0, False, 600.0),
    "abort_grace_s": (0.0, False, 60.0),
    "give_up_s": (0.0, False, 3600.0),
    "reconnect_min_s": (0.0, False, 60.0),
    "reconnect_max_s": (0.0, False, 600.0),
    "head_turn_lead_s": (0.0, True, 60.0),
    "head_turn_hold_s": (0.0, True, 60.0),
    "inflight_window_s": (0.0, True, 10.0),
    # 1e6: the limit lifted (the bench's robot row measures the path, not the limiter); above it, no rate anyone means
    "max_commands_per_s": (0.0, False, 1e6),
}
SIGNS = ("yaw_sign", "pitch_sign")  # a direction: +1 or -1 (0 froze the head on one axis, 2 doubled its turns)


class RobotConfig(msgspec.Struct, frozen=True, forbid_unknown_fields=True):
    """How the bridge renders and delivers suggestions; every field has a default.

    gestures: None means the backend's own preset ("iristk" over the broker,
    "furhat" over the Realtime API).
    """

    # keys an older pairplay's config file may hold, each with what does its work now: a file holding one is refused
    # saying so (schemas/jsonfile.py `retired_key`), not as a typo of a key of another meaning
    RETIRED: ClassVar[dict[str, str]] = {
        "iristk_subscriber_wait_s": "an IrisTK event nobody subscribes to is now held until the broker says someone "
                                    "does, for at most `give_up_s` (then the suggestion is failed)",
        "iristk_wait_for_subscriber": "an IrisTK event nobody subscribes to is now always held until the broker says "
                                      "someone does, for at most `give_up_s` (then the suggestion is failed)",
    }

    gestures: GestureNames | None = None
    speech: SpeechTexts = SpeechTexts()
    gaze_mode: str = "default"  # IrisTK action.gaze mode for looking at a card
    head_mode: str = "headpose"  # IrisTK action.gaze mode for a head turn
    gaze_speed: str = "medium"  # card gazes (thesis figure D.3); one of iristk_protocol.SPEEDS
    head_turn_offset_m: float = 0.2  # how far past the observed card the head turns
    head_turn_lead_s: float = 0.3  # look at the observed card, then turn after this
    head_turn_hold_s: float = 0.8  # hold the turn, then look back at the participant
    ack_timeout_s: float = 10.0  # a promised reply later than this: "unacknowledged"
    abort_grace_s: float = 1.0  # a superseded suggestion's replies in flight are awaited this long
    give_up_s: float = 30.0  # undelivered this long with the robot unreachable: "failed"
    reconnect_min_s: float = 0.05
    reconnect_max_s: float = 2.0
    iristk_ticket: str = "furhat"
    iristk_name: str = "pairplay"
    iristk_subscribe: str = "monitor.**"
    iristk_agent: str = ""  # sent as "agent" when set (multi-agent IrisTK systems)
    iristk_gesture_replies: bool = True  # await monitor.gesture.end for gestures
    realtime_key: str = ""  # Realtime API auth key, if the robot requires one
    yaw_sign: float = 1.0  # Realtime headpose: + yaw turns towards +x (the robot's left)
    pitch_sign: float = 1.0  # Realtime headpose: + pitch turns towards +y (up)
    head_speed: str = "x-fast"  # head turns: the thesis's action.attend speed (figure D.5)
    iristk_head_event: str = "gaze"  # head turns as "gaze" (action.gaze, any Furhat) or "attend"
    # (action.attend, as the thesis: needs an IrisTK SystemAgentFlow and iristk_agent)
    max_commands_per_s: float = 10.0  # robot-side rate limit (token bucket), so no module's
    command_burst: int = 20  # 1000-event queue (IrisModule.java 24) can be flooded by us
    inflight_window_s: float = 0.25  # commands written this soon before a drop: unconfirmed
    realtime_proxy: str = ""  # an HTTP/SOCKS proxy URL for the Realtime connection; "" = direct,
    # whatever http_proxy/https_proxy say (the robot is on the lab network)

    def validate(self) -> None:
        """Raise ValueError with a clear reason if the config cannot work."""
        for name, (low, low_ok, high) in RANGES.items():
            value = getattr(self, name)
            if not ((value >= low if low_ok else value > low) and value <= high):  # also refuses nan
                need = f"{shown(low)}..{shown(high)}" if low_ok else f"> {shown(low)} and at most {shown(high)}"
                raise ValueError(f"robot config: {name} must be {need}, got {shown(value)}")
        for name in SIGNS:
            if getattr(self, name) not in (1, -1):
                raise ValueError(f"robot config: {name} must be 1 or -1 (a direction), got {shown(getattr(self, name))}")
        if self.reconnect_max_s < self.reconnect_min_s:
            raise ValueError("robot config: reconnect_max_s must be >= reconnect_min_s")
        for name in ("iristk_ticket", "iristk_name"):
            value = getattr(self, name)
            if not value or any(c.isspace() or not c.isprintable() for c in value):
                raise ValueError(f"robot config: {name} must be one word without spaces, got {value!r}")
        try:
            check_name_filter(self.iristk_subscribe)  # as the broker compiles it (NameFilter.java 77)
        except ValueError as exc:
            raise ValueError(f"robot config: iristk_subscribe: {exc}") from None
        for name in ("gaze_speed", "head_speed"):
            if getattr(self, name) not in IRISTK_SPEEDS:
                raise ValueError(f"robot config: {name} must be one of {', '.join(IRISTK_SPEEDS)},"
                                 f" got {getattr(self, name)!r}")
        if self.iristk_head_event not in ("gaze", "attend"):
            raise ValueError(f"robot config: iristk_head_event must be gaze or attend, got {self.iristk_head_event!r}")
        if self.iristk_head_event == "attend" and not self.iristk_agent:
            raise ValueError("robot config: iristk_head_event attend needs iristk_agent (SystemAgentFlow only"
                             " takes an action.attend location whose agent is its own)")
        if not 1 <= self.command_burst <= 500:
            raise ValueError(f"robot config: command_burst must be 1..500 (an IrisTK module queue holds 1000),"
                             f" got {self.command_burst}")
        if "{row}" not in self.speech.exact or "{column}" not in self.speech.exact:
            raise ValueError("robot config: speech.exact must contain {row} and {column}")
