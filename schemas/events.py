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
               TurnResolved, RoundEnded, SessionEnded
  participant: CardPicked, CardObserved (intended source), SuggestionPerceived,
               WrongSuggestionPressed, QuestionnaireAnswered
  learner:     SuggestionMade, RewardGiven, QUpdated (Q-learning), LSPIUpdated (LSPI)
  combiner:    PolicyCombined (answering CombineRequested)
  robot:       RobotActed (schemas/robot.py)
  any service: ServiceStarted, MessageRejected
"""

from __future__ import annotations

from typing import Union

import msgspec

from .envelope import Event, dec_hook, enc_hook
from .session import SessionConfig


class ServiceStarted(Event, tag="ServiceStarted"):
    service: str
    version: str = ""
    resumed_events: int = 0  # events folded from the log when it restarted


class SessionStarted(Event, tag="SessionStarted"):
    config: SessionConfig


class RoundStarted(Event, tag="RoundStarted"):
    round: int
    faces: list[int]  # the deal: face (pair id 0..8) of each of the 18 cards


class CardPicked(Event, tag="CardPicked"):
    """The participant touched a card (an input: the game may reject it)."""

    round: int
    turn: int
    card: int


class CardRevealed(Event, tag="CardRevealed"):
    """The game accepted a pick and turned the card face up."""

    round: int
    turn: int
    card: int
    face: int
    pick: int  # 0 = first card of the turn, 1 = second
    pick_seq: int = 0  # seq of the CardPicked it accepts


class PickRejected(Event, tag="PickRejected"):
    round: int
    turn: int
    card: int
    reason: str
    pick_source: str = ""
    pick_seq: int = 0


class CardObserved(Event, tag="CardObserved"):
    """The card the user looks at before the second pick (SPEC "Observed card")."""

    round: int
    turn: int
    card: int
    observed_source: str  # "intended" | "first-pick"


class SuggestionRequested(Event, tag="SuggestionRequested"):
    round: int
    turn: int
    attempt: int
    state: int
    observed: int
    match: int  # the card matching the first pick: the target of a suggestion
    covered_mask: int
    first: int = -1  # the first card of the turn


class SuggestionMade(Event, tag="SuggestionMade"):
    round: int
    turn: int
    attempt: int
    state: int
    action: int  # composite action code 0..87 (core.actions)
    chosen_by: str  # "greedy" | "explore" | "bias" | "fixed"
    epsilon: float
    alpha: float
    psi: float
    observed: int
    target: int  # the matching card: what "row x column y" and the gaze point at
    action_name: str = ""
    request_seq: int = 0


class SuggestionPerceived(Event, tag="SuggestionPerceived"):
    """What the simulated user made of a suggestion (thesis 6.1.3).

    The human study has no such event: there the reward follows the picks'
    timing (thesis 7.1.2) and the wrong-suggestion button.
    """

    round: int
    turn: int
    attempt: int
    considered: bool
    consistent: bool
    candidate_size: int
    from_memory: bool = False  # the match was known: the suggestion is not learned from
    candidate_mask: int = 0  # the candidate set (0 when inconsistent or not considered)
    second: int = -1  # the card the user will pick second


class WrongSuggestionPressed(Event, tag="WrongSuggestionPressed"):
    round: int
    turn: int


class TurnResolved(Event, tag="TurnResolved"):
    round: int
    turn: int
    first: int
    second: int
    matched: bool
    round_over: bool
    interval_ms: float = 0.0  # between the two picks, from their envelope times
    ignored_by_time: bool = False  # interval under the session's ignore window


class RewardGiven(Event, tag="RewardGiven"):
    round: int
    turn: int
    attempt: int
    state: int
    action: int
    reward: float
    learned: bool  # False: ignored suggestion, no update (thesis 6.1.3, 7.1.2)
    reason: str = ""


class QUpdated(Event, tag="QUpdated"):
    round: int
    turn: int
    attempt: int
    state: int
    action: int
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

    round: int
    turn: int
    attempt: int
    state: int
    action: int
    reward: float
    samples: int  # samples learned so far, this one included
    improved: bool  # this sample ended a batch of K: the policy was improved
    q_before: float  # Q(state, action) of the policy in force before the sample
    q_after: float  # ... after it (differs only when improved)
    weights: str = ""  # core.lspi.weights_digest of the weights after an improvement


class RoundEnded(Event, tag="RoundEnded"):
    round: int
    turns: int
    matches: int


class CombineRequested(Event, tag="CombineRequested"):
    """Profile and merge users' policies (thesis 5.2, algorithms 3 and 4)."""

    request_id: str
    policies: list[str] = []  # policy file paths
    recordings: list[str] = []  # recordings to rebuild policies from
    seed: int = 0  # picks each user's representative policy, as the study does
    output_path: str = ""  # where to write the combined policy file ("" = nowhere)
    exclude: list[str] = []  # users left out (e.g. the participant the bias policy is for)


class PolicyCombined(Event, tag="PolicyCombined"):
    request_id: str
    inputs: list[str]
    actions: list[int]  # greedy action per state of the combined policy
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


class MessageRejected(Event, tag="MessageRejected"):
    """A service refused a bus message; it keeps running."""

    reason: str
    key: str
    offending_source: str = ""
    offending_seq: int = 0
    excerpt: str = ""  # the first bytes of the payload, for the record


END_REASONS = ("completed", "interrupted", "aborted", "failed")


class SessionEnded(Event, tag="SessionEnded"):
    """Why the session ended (END_REASONS: completed; interrupted by SIGINT/SIGTERM; aborted by the
    experimenter; a service failed) and how far it got."""

    reason: str = "completed"
    rounds_played: int = 0  # rounds finished
    detail: str = ""  # e.g. "SIGTERM", "learner left the bus and did not come back within 30 s"
    round: int = -1  # the round under way when it ended (-1: none; a completed session ends between rounds)
    turns_in_round: int = 0  # turns of that round resolved when it ended


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
    CombineRequested, PolicyCombined, QuestionnaireAnswered, MessageRejected, SessionEnded,
) + _robot_events()
EVENT_BY_TAG: dict[str, type[Event]] = {t.__struct_config__.tag: t for t in EVENT_TYPES}
AnyEvent = Union[EVENT_TYPES]  # type: ignore[valid-type]

_decoder = msgspec.json.Decoder(AnyEvent, dec_hook=dec_hook)
_encoder = msgspec.json.Encoder(enc_hook=enc_hook)


def decode_event(payload: bytes) -> Event:
    """Decode one JSON event; raises msgspec.ValidationError / DecodeError with a reason."""
    return _decoder.decode(payload)


def encode_event(event: Event) -> bytes:
    return _encoder.encode(event)
