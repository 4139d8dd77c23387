"""What a service trusts on the bus: who may publish which event, sequence numbers, sizes.

Rule: a message is taken only if
- its payload is at most `MAX_PAYLOAD` bytes (the largest event pairplay
  writes, a SessionStarted with a fixed policy, is ~2 KiB; a 10 MB "pick" is
  refused before it is even decoded);
- its source may publish its event (`PUBLISHERS`: only the game announces
  or ends a session, only a player source picks, only the learner suggests,
  only the robot reports RobotActed; ServiceStarted and MessageRejected from
  any known service; every source name outside `SOURCES` is refused);
- its sequence number rises on its key and lies at most `MAX_SEQ_JUMP` above
  the highest one seen from its source (a forged seq 1e9 is refused instead
  of making every later real message look like a duplicate). A source's
  numbers rise by one per event; a listener sees them with gaps (it does not
  subscribe to every key), but no service publishes `MAX_SEQ_JUMP` events
  a listener cannot see between two it can: rejections are rate-limited
  (`REJECTIONS_PER_S`);
- its envelope is in range (schemas/envelope.py: seq 1..2^53, time_ns 0..2^63).
Every event pairplay builds fits `MAX_PAYLOAD` by construction, whatever outside text it
copies (a listener sheds a larger one unread: a hole in the recording no refill fills; trial28
F20, F21): outside text is bounded where it enters (a console reason over `MAX_REASON`
characters is refused in one line) and every copy of it in our own events is `clip`ped
(`MAX_REASON` characters of a reason, `MAX_NAME` of a key or source, with a marker saying how
much was cut). Even a reason of escaped control characters (6 bytes each in JSON) is then far
below the limit.
One session has one SessionStarted and one SessionEnded: a second is refused, and
so is one that does not fit its source's sequence (services/guard.py; issue
"forge": Zenoh names no publisher per message, so whatever came first claiming
to be the game used to win: a forged end ended the services).
Everything refused is recorded (MessageRejected, rate-limited with counts).
Who can put a message on a key at all is Zenoh's access control
(docs/bus.md "Security"): these rules hold whatever the network lets through.
"""

from __future__ import annotations

from pairplay.numbers import counted

MAX_PAYLOAD = 64 * 1024  # bytes
MAX_SEQ_JUMP = 10_000
MAX_REASON = 1000  # characters of a reason (a refusal's, the experimenter's pause or abort) in an event
MAX_NAME = 200  # characters of a key or a source name copied into an event (real ones are far shorter)
REJECTIONS_PER_S = 20  # recorded one by one per service and second; beyond that, counted
PLAYERS = frozenset({"participant", "board"})
SERVICES = frozenset({"game", "learner", "participant", "board", "robot", "combiner", "recorder", "tracker"})
CLIENTS = frozenset({"console", "experimenter"})  # people's tools: requests and questionnaires
SOURCES = SERVICES | CLIENTS

GAME = frozenset({"game"})
PUBLISHERS: dict[str, frozenset[str]] = {
    "ServiceStarted": SERVICES,
    "MessageRejected": SERVICES,
    "SessionStarted": GAME,
    "RoundStarted": GAME,
    "CardRevealed": GAME,
    "PickRejected": GAME,
    "SuggestionRequested": GAME,
    "TurnResolved": GAME,
    "RoundEnded": GAME,
    "SessionEnded": GAME,
    "ControlTaken": GAME,
    "CardObserved": GAME | PLAYERS,  # first-pick (game) or intended (the player)
    "CardPicked": PLAYERS,
    "SuggestionPerceived": frozenset({"participant"}),
    "WrongSuggestionPressed": PLAYERS,
    "QuestionnaireAnswered": PLAYERS | CLIENTS,
    "SuggestionMade": frozenset({"learner"}),
    "RewardGiven": frozenset({"learner"}),
    "QUpdated": frozenset({"learner"}),
    "LSPIUpdated": frozenset({"learner"}),
    "RobotActed": frozenset({"robot"}),
    "CombineRequested": CLIENTS,
    "PolicyCombined": frozenset({"combiner"}),
    "RecordingGap": frozenset({"recorder"}),
    "GazeFixated": frozenset({"tracker"}),  # an eye tracker (observed source "gaze", issue 14)
    "SessionPaused": CLIENTS,  # the experimenter's console (issue 15)
    "SessionResumed": CLIENTS,
    "SessionAborted": CLIENTS,
}
ONCE_PER_SESSION = frozenset({"SessionStarted", "SessionEnded"})
# who starts and ends a session (the game): one process per session, numbering every event it publishes.
# Other source names may be several publishers' (every page of the lab publishes as "board").
STARTERS = frozenset().union(*(PUBLISHERS[tag] for tag in ONCE_PER_SESSION))


def publisher_refusal(tag: str, source: str) -> str | None:
    """Why `source` may not publish `tag` (None: it may)."""
    allowed = PUBLISHERS.get(tag)
    if allowed is None:
        return f"no event type {tag!r}"
    if source not in allowed:
        return f"{tag} is published only by {', '.join(sorted(allowed))}, not by {source!r}"
    return None


def clip(text: str, most: int) -> str:
    """`text` cut to at most its first `most` characters, with a marker saying how much was cut
    (unchanged if it fits): how outside text is copied into our own events (see rule). The cut is
    at the last space within them when one is in their second half (a reason cut mid-word, or
    mid-parenthesis, read as if it said that much: trial33 L), else at `most` (one long word)."""
    if len(text) <= most:
        return text
    space = text.rfind(" ", 0, most + 1)
    cut = space if space > most // 2 else most
    return f"{text[:cut]}... [{counted(len(text) - cut, 'more character', 'more characters')} cut]"
