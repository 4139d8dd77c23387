"""Every event of the bus and the recording, as tagged msgspec Structs.

Rule: one class per fact, past tense, tag = class name, envelope from
`envelope.Event`. Anything random that was decided is recorded as its outcome
(the deal, the chosen action and how it was chosen, the simulated user's
perception), so a fold over the log rebuilds every state without re-drawing.
Rounds and turns count from 0; `attempt` counts the suggestions within a turn
(a "wrong suggestion" press asks for another one). Cards are board indices
row * 6 + col; card sets are 18-bit masks.

Who publishes what (source = the service name):
  game:        SessionStarted, RoundStarted, CardRevealed, PickRejected,
               CardObserved (first-pick source), SuggestionRequested,
               TurnResolved, RoundEnded, SessionEnded, ControlTaken
  participant: CardPicked, CardObserved (intended source), SuggestionPerceived
  board:       CardPicked, WrongSuggestionPressed, QuestionnaireAnswered (the lab's pages)
  tracker:     GazeFixated (an eye tracker)
  learner:     SuggestionMade, RewardGiven, QUpdated (Q-learning), LSPIUpdated (LSPI)
  combiner:    PolicyCombined (answering CombineRequested)
  experimenter: SessionPaused, SessionResumed, SessionAborted (the console; the game obeys them)
  robot:       RobotActed (schemas/robot.py)
  recorder:    RecordingGap (a restarted recorder continues the session's file)
  any service: ServiceStarted, MessageRejected
"""

from __future__ import annotations

from typing import Annotated, Union

import msgspec

from .envelope import Event, Nanos, Seq, dec_hook, enc_hook
from .session import SessionConfig
from .nesting import JsonDecoder


# Ranges of the fields, checked on decode (where a message enters; schemas/trust.py)
Count = Annotated[int, msgspec.Meta(ge=0, le=2**31 - 1)]  # rounds, turns, attempts, sizes
Card = Annotated[int, msgspec.Meta(ge=0, le=17)]  # board index row * 6 + col
CardOrNone = Annotated[int, msgspec.Meta(ge=-1, le=17)]  # -1: no card
Face = Annotated[int, msgspec.Meta(ge=0, le=8)]
State = Annotated[int, msgspec.Meta(ge=0, le=23)]  # thesis 4.1: 23 spatial states + Error
Action = Annotated[int, msgspec.Meta(ge=0, le=87)]  # core.actions
Mask = Annotated[int, msgspec.Meta(ge=0, le=2**18 - 1)]  # a set of cards
Int64 = Annotated[int, msgspec.Meta(ge=-2**63, le=2**63 - 1)]


class ServiceStarted(Event, tag="ServiceStarted"):
    service: str
    version: str = ""
    resumed_events: Count = 0  # events folded from the log when it restarted
    # the inputs this service marks where it took them (its logic's PLACED: the game's pause and resume, each
    # answered by a ControlTaken): a log whose ServiceStarted names them holds a mark for each one taken, so
    # one without a mark was refused, even in a log with no mark at all (services/node.py resume); [] in a
    # log made before the marks, which is fed in file order
    marks: list[str] = []


class SessionStarted(Event, tag="SessionStarted"):
    config: SessionConfig


class RoundStarted(Event, tag="RoundStarted"):
    round: Count
    faces: Annotated[list[Face], msgspec.Meta(min_length=18, max_length=18)]  # the deal: face (pair id 0..8) of each of the 18 cards


class CardPicked(Event, tag="CardPicked"):
    """The participant touched a card (an input: the game may reject it)."""

    round: Count
    turn: Count
    card: Int64  # any number: an off-board pick is answered with PickRejected
    # The board page's clock at the touch: performance.timeOrigin + performance.now(), ms
    # (0: not from a page). The envelope's time_ns is the server's clock when it took the touch.
    page_time_ms: float = 0.0


class CardRevealed(Event, tag="CardRevealed"):
    """The game accepted a pick and turned the card face up."""

    round: Count
    turn: Count
    card: Card
    face: Face
    pick: Annotated[int, msgspec.Meta(ge=0, le=1)]  # 0 = first card of the turn, 1 = second
    pick_seq: Seq = 0  # seq of the CardPicked it accepts


class PickRejected(Event, tag="PickRejected"):
    round: Count
    turn: Count
    card: Int64  # any number: an off-board pick is answered with PickRejected
    reason: str
    pick_source: str = ""
    pick_seq: Seq = 0


class CardObserved(Event, tag="CardObserved"):
    """The card the user looks at before the second pick (SPEC "Observed card")."""

    round: Count
    turn: Count
    card: Card
    observed_source: str  # "intended" | "first-pick"


class SuggestionRequested(Event, tag="SuggestionRequested"):
    round: Count
    turn: Count
    attempt: Count
    state: State
    observed: Card
    match: Card  # the card matching the first pick: the target of a suggestion
    covered_mask: Mask
    first: CardOrNone = -1  # the first card of the turn


class SuggestionMade(Event, tag="SuggestionMade"):
    round: Count
    turn: Count
    attempt: Count
    state: State
    action: Action  # composite action code 0..87 (core.actions)
    chosen_by: str  # "greedy" | "explore" | "bias" | "fixed"
    epsilon: float
    alpha: float
    psi: float
    observed: Card
    target: Card  # the matching card: what "row x column y" and the gaze point at
    action_name: str = ""
    request_seq: Seq = 0


class SuggestionPerceived(Event, tag="SuggestionPerceived"):
    """What the simulated user made of a suggestion (thesis 6.1.3).

    The human study has no such event: there the reward follows the picks'
    timing (thesis 7.1.2) and the wrong-suggestion button.
    """

    round: Count
    turn: Count
    attempt: Count
    considered: bool
    consistent: bool
    candidate_size: Count
    from_memory: bool = False  # the match was known: the suggestion is not learned from
    candidate_mask: Mask = 0  # the candidate set (0 when inconsistent or not considered)
    second: CardOrNone = -1  # the card the user will pick second


class WrongSuggestionPressed(Event, tag="WrongSuggestionPressed"):
    round: Count
    turn: Count
    attempt: int = -1  # the suggestion judged wrong (-1: the open one, as in recordings before 0.3)
    page_time_ms: float = 0.0  # the board page's clock at the press (see CardPicked)


class TurnResolved(Event, tag="TurnResolved"):
    round: Count
    turn: Count
    first: Card
    second: Card
    matched: bool
    round_over: bool
    interval_ms: float = 0.0  # between the two picks, from their envelope times
    ignored_by_time: bool = False  # interval under the session's ignore window
    page_interval_ms: float = -1.0  # between the picks on the page's clock (-1: no page times)


class RewardGiven(Event, tag="RewardGiven"):
    round: Count
    turn: Count
    attempt: Count
    state: State
    action: Action
    reward: float
    learned: bool  # False: ignored suggestion, no update (thesis 6.1.3, 7.1.2)
    reason: str = ""


class QUpdated(Event, tag="QUpdated"):
    round: Count
    turn: Count
    attempt: Count
    state: State
    action: Action
    alpha: float
    reward: float
    q_before: float
    q_after: float


class LSPIUpdated(Event, tag="LSPIUpdated"):
    """One sample learned by online LSPI (algorithm 2 lines 8-15, core/lspi.py).

    A fold replays the samples in order through the same code and gets the
    learner's weights bit for bit; `weights` (a digest of them, after a policy
    improvement) and q_before let it prove so.
    """

    round: Count
    turn: Count
    attempt: Count
    state: State
    action: Action
    reward: float
    samples: Count  # samples learned so far, this one included
    improved: bool  # this sample ended a batch of K: the policy was improved
    q_before: float  # Q(state, action) of the policy in force before the sample
    q_after: float  # ... after it (differs only when improved)
    weights: str = ""  # core.lspi.weights_digest of the weights after an improvement


class RoundEnded(Event, tag="RoundEnded"):
    round: Count
    turns: Count
    matches: Count


class CombineRequested(Event, tag="CombineRequested"):
    """Profile and merge users' policies (thesis 5.2, algorithms 3 and 4)."""

    request_id: str
    policies: list[str] = []  # policy file paths
    recordings: list[str] = []  # recordings to rebuild policies from
    seed: Int64 = 0  # picks each user's representative policy, as the study does
    output_path: str = ""  # where to write the combined policy file ("" = nowhere)
    exclude: list[str] = []  # users left out (e.g. the participant the bias policy is for)


class PolicyCombined(Event, tag="PolicyCombined"):
    request_id: str
    inputs: list[str]
    actions: list[Action]  # greedy action per state of the combined policy
    decided_by: list[str] = []  # per state: which rule of the algebra decided
    ok: bool = True
    error: str = ""
    output_path: str = ""
    users: list[str] = []  # the users combined, in order
    speech_error: float = 0.0  # merged user information (min of the errors, AND of the booleans)
    head_error: float = 0.0
    facial: bool = False
    gaze: bool = False


class QuestionnaireAnswered(Event, tag="QuestionnaireAnswered"):
    questionnaire: str
    answers: dict[str, str]


class SessionPaused(Event, tag="SessionPaused"):
    """The experimenter paused the game: the game refuses touches until SessionResumed."""

    reason: str = ""


class SessionResumed(Event, tag="SessionResumed"):
    """The experimenter resumed a paused game."""


class ControlTaken(Event, tag="ControlTaken"):
    """The game took the experimenter's SessionPaused or SessionResumed here, in its own numbered stream:
    after the inputs its earlier outputs answer, before those its later outputs answer. A recorder files
    the console's message as it reaches it, not as the game took it, so it may sit on the other side of a
    touch in flight; verify and a restart feed it where this event stands (services/node.py `resume`).
    A refused control (already paused, already running) has none: it changed nothing."""

    control: str  # the tag taken: "SessionPaused" | "SessionResumed"
    control_source: str
    control_seq: Seq


class SessionAborted(Event, tag="SessionAborted"):
    """The experimenter stopped the game; the game ends it (SessionEnded "aborted", the reason as detail)."""

    reason: str


class GazeFixated(Event, tag="GazeFixated"):
    """An eye tracker saw the participant fixate a card (observed source "gaze", docs/lab.md).

    Published by source "tracker" when the fixation has lasted `duration_ms`; the
    envelope's time_ns is the tracker's clock then (the bus's wall clock)."""

    card: Card
    duration_ms: float = 0.0


class MessageRejected(Event, tag="MessageRejected"):
    """A service refused a bus message; it keeps running."""

    reason: str
    key: str
    offending_source: str = ""
    offending_seq: Seq = 0
    excerpt: str = ""  # the first bytes of the payload, for the record


class RecordingGap(Event, tag="RecordingGap"):
    """A restarted recorder continues an earlier file of the session: what it copied, what
    it refilled from the services' own records of what they published, and the gap."""

    earlier_file: str  # the file this one continues (its readable events are copied first)
    copied: Count  # events copied from it
    last_copied_ns: Nanos  # log time of the last event the earlier file kept: the gap starts after it
    resumed_ns: Nanos  # when this recorder started listening: the gap ends there
    refilled: Count = 0  # events of the gap the services re-sent (written with their publish time)
    refilled_from: list[str] = []  # the services that answered
    unanswered: list[str] = []  # sources seen before the gap that did not answer: their gap events may be lost


END_REASONS = ("completed", "interrupted", "aborted", "failed")


class SessionEnded(Event, tag="SessionEnded"):
    """Why the session ended (END_REASONS: completed; interrupted by SIGINT/SIGTERM; aborted by the
    experimenter; a service failed) and how far it got."""

    reason: str = "completed"
    rounds_played: Count = 0  # rounds finished
    detail: str = ""  # e.g. "SIGTERM", "learner left the bus and did not come back within 30 s"
    round: Annotated[int, msgspec.Meta(ge=-1, le=2**31 - 1)] = -1  # the round under way when it ended (-1: none)
    turns_in_round: Count = 0  # turns of that round resolved when it ended


def _robot_events() -> tuple[type[Event], ...]:
    """RobotActed lives in schemas/robot.py (the robot bridge's contract)."""
    try:
        from .robot import RobotActed
    except ModuleNotFoundError as missing:
        if missing.name != __package__ + ".robot":
            raise
        return ()
    return (RobotActed,)


EVENT_TYPES: tuple[type[Event], ...] = (
    ServiceStarted, SessionStarted, RoundStarted, CardPicked, CardRevealed, PickRejected,
    CardObserved, SuggestionRequested, SuggestionMade, SuggestionPerceived,
    WrongSuggestionPressed, TurnResolved, RewardGiven, QUpdated, LSPIUpdated, RoundEnded,
    CombineRequested, PolicyCombined, QuestionnaireAnswered, MessageRejected, SessionEnded, RecordingGap,
    SessionPaused, SessionResumed, SessionAborted,
) + _robot_events() + (GazeFixated, ControlTaken)
EVENT_BY_TAG: dict[str, type[Event]] = {t.__struct_config__.tag: t for t in EVENT_TYPES}
AnyEvent = Union[EVENT_TYPES]  # type: ignore[valid-type]

event_decoder = JsonDecoder(AnyEvent, dec_hook=dec_hook)
_encoder = msgspec.json.Encoder(enc_hook=enc_hook)


def decode_event(payload: bytes) -> Event:
    """Decode one JSON event; raises msgspec.ValidationError / DecodeError with a reason."""
    return event_decoder.decode(payload)


class _Envelope(msgspec.Struct):
    seq: int = 0


_seq_decoder = msgspec.json.Decoder(_Envelope)


def own_seq(payload: bytes) -> int:
    """The seq of an event this process published (an Outbox's `sent`), read from its envelope alone and
    never raising: a shutdown or a peer's query reads its own outbox, and one payload its peers refuse
    (an offending_seq of 2**64 in a MessageRejected: trial28 F9) made `decode_event` kill `pairplay lab`'s
    close, the recording left cut. -1 for what has no readable seq (then it is above no cut, below none)."""
    try:
        return _seq_decoder.decode(payload).seq
    except (msgspec.DecodeError, msgspec.ValidationError):
        return -1


def encode_event(event: Event) -> bytes:
    return _encoder.encode(event)
