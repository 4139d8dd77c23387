"""What the live view draws, as a fold over session events (no rerun, no I/O).

Rule: the view is a consumer of events only. `ViewModel.apply(event)` folds one
event into what to draw (card states, highlights, the suggestion in words, the
Q-table, the curves) and returns what changed, so the rerun layer logs only
that. The same fold runs on the live bus and on a recording, so both give the
same view. A malformed event (a card off the board, a state or action out of
range) changes nothing and comes back as a note; the fold never raises on
event content.

Choices where the events leave room:
- The Q-table starts at zeros (the learner's start, thesis 5.1) and takes
  `q_after` of every QUpdated. A view that joins a live session late misses the
  earlier updates; it says so (`q_partial`) when a `q_before` disagrees.
- The "candidate set" highlighted is SuggestionPerceived's `candidate_mask`
  when the participant reports one (non-zero); otherwise the cards the suggestion points at among
  the covered ones (appendix B: every part perceived, nothing remembered),
  which is the candidate set of a user with no memory who perceived it all.
- Picks per round = 2 x the turns of the round (RoundEnded): 18 is perfect play.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from enum import IntEnum

import numpy as np

from pairplay.core.actions import FACIAL, GAZE, HEAD, N_ACTIONS, SPEECH, SPEECH_EXACT, action
from pairplay.core.geometry import ALL_CARDS, COLS, N_CARDS, N_STATES, STATE_NAMES, card_col, card_row
from pairplay.core.interpretation import HEAR_SET, VIS_SET
from pairplay.numbers import counted


class Cell(IntEnum):
    """How a card is drawn; the value is the class id of the board image."""

    COVERED = 0
    FACE_UP = 1
    MATCHED = 2


class Change(IntEnum):
    """What an event changed, so the drawing layer redraws only that."""

    BOARD = 1  # card states
    HIGHLIGHT = 2  # observed card, matching card, candidate set
    SUGGESTION = 3  # the suggestion text
    SCHEDULE = 4  # epsilon, alpha, psi
    REWARD = 5
    Q = 6  # the Q-table
    ROUND_END = 7  # picks per round
    SESSION = 8  # started / ended
    NOTE = 9  # a line for the event log


def position(card: int) -> str:
    """Spoken position, 1-based as in the robot's speech (SPEC "Board and game")."""
    return f"row {card_row(card) + 1}, column {card_col(card) + 1}"


def suggestion_parts(code: int, target: int | None) -> dict[str, str]:
    """The four parts of a composite action in words (thesis tables 4.1-4.4)."""
    act = action(code)
    speech = SPEECH[act.speech]
    if act.speech == SPEECH_EXACT and target is not None and 0 <= target < N_CARDS:
        speech = f"\"Try at row {card_row(target) + 1} and column {card_col(target) + 1}\""
    return {"speech": speech, "facial": FACIAL[act.facial], "head": HEAD[act.head], "gaze": GAZE[act.gaze]}


def _card_ok(card) -> bool:
    return isinstance(card, int) and 0 <= card < N_CARDS


@dataclass
class ViewModel:
    """Everything the view shows, folded from events."""

    session: str = ""
    participant: str = ""
    algorithm: str = ""
    rounds: int = 0
    round: int = -1
    turn: int = -1
    faces: list[int] = field(default_factory=lambda: [-1] * N_CARDS)
    face_up: int = 0  # bit masks of cards
    matched: int = 0
    observed: int = -1
    match: int = -1
    candidates: int = 0
    candidates_reported: bool = False  # True: the participant's own candidate set
    state: int = -1
    action: int = -1
    target: int = -1
    suggested_from: int = -1  # the observed card the suggestion was made for
    chosen_by: str = ""
    perceived: str = ""
    epsilon: float | None = None
    alpha: float | None = None
    psi: float | None = None
    reward: float | None = None
    learned: bool = False
    q: np.ndarray = field(default_factory=lambda: np.zeros((N_STATES, N_ACTIONS)))
    q_updates: int = 0
    q_partial: bool = False
    picks_per_round: dict[int, int] = field(default_factory=dict)
    last_round_ended: int = -1
    events: int = 0
    ended: str = ""

    # -- what to draw -------------------------------------------------------
    def cells(self) -> np.ndarray:
        """(3, 6) uint8 Cell value per card."""
        flat = np.full(N_CARDS, Cell.COVERED, dtype=np.uint8)
        for card in range(N_CARDS):
            if self.matched >> card & 1:
                flat[card] = Cell.MATCHED
            elif self.face_up >> card & 1:
                flat[card] = Cell.FACE_UP
        return flat.reshape(-1, COLS)

    def suggestion_text(self) -> str:
        """Markdown of the current state and suggestion, for a text panel."""
        if self.action < 0:
            return "No suggestion yet."
        parts = suggestion_parts(self.action, self.target)
        state = STATE_NAMES[self.state] if 0 <= self.state < N_STATES else "?"
        lines = [
            f"**Round {self.round + 1}, turn {self.turn + 1}**",
            f"- state: `{state}` ({self.state})",
            f"- action {self.action}: {action(self.action).name} (by {self.chosen_by or '?'})",
            f"- speech: {parts['speech']}",
            f"- facial: {parts['facial']}",
            f"- head: {parts['head']}",
            f"- gaze: {parts['gaze']}",
        ]
        if _card_ok(self.suggested_from):
            lines.append(f"- observed card: {position(self.suggested_from)}")
        if _card_ok(self.target):
            lines.append(f"- matching card: {position(self.target)}")
        if self.perceived:
            lines.append(f"- user: {self.perceived}")
        if self.reward is not None:
            lines.append(f"- reward: {self.reward:+.3f}" + ("" if self.learned else " (not learned from)"))
        return "\n".join(lines)

    # -- the fold -----------------------------------------------------------
    def apply(self, event) -> tuple[set[Change], str]:
        """Fold one event; return what changed and a line for the event log."""
        self.events += 1
        handler = _HANDLERS.get(type(event).__name__)
        if handler is None:
            return {Change.NOTE}, f"{type(event).__name__}"
        return handler(self, event)

    def _clear_turn(self) -> None:
        self.observed = self.match = -1
        self.candidates = 0
        self.candidates_reported = False


def _session_started(m: ViewModel, e) -> tuple[set[Change], str]:
    cfg = e.config
    m.session, m.participant, m.algorithm, m.rounds = cfg.session, cfg.participant, cfg.algorithm, cfg.rounds
    return {Change.SESSION, Change.NOTE}, f"session {cfg.session}: {cfg.participant}, {cfg.algorithm}, {counted(cfg.rounds, 'round')}"


def _round_started(m: ViewModel, e) -> tuple[set[Change], str]:
    if len(e.faces) != N_CARDS:
        return {Change.NOTE}, f"ignored RoundStarted with {counted(len(e.faces), 'face')} (expected {N_CARDS})"
    m.round, m.turn = e.round, 0
    m.faces = list(e.faces)
    m.face_up = m.matched = 0
    m._clear_turn()
    return {Change.BOARD, Change.HIGHLIGHT, Change.NOTE}, f"round {e.round + 1} dealt"


def _card_revealed(m: ViewModel, e) -> tuple[set[Change], str]:
    if not _card_ok(e.card):
        return {Change.NOTE}, f"ignored CardRevealed of card {e.card!r}: off the board"
    changes = {Change.BOARD, Change.NOTE}
    if e.pick == 0:  # a new turn: last turn's highlights go
        m._clear_turn()
        changes.add(Change.HIGHLIGHT)
    m.round, m.turn = e.round, e.turn
    m.face_up |= 1 << e.card
    m.faces[e.card] = e.face
    return changes, f"card {position(e.card)} revealed (pick {e.pick + 1})"


def _card_observed(m: ViewModel, e) -> tuple[set[Change], str]:
    if not _card_ok(e.card):
        return {Change.NOTE}, f"ignored CardObserved of card {e.card!r}: off the board"
    m.observed = e.card
    return {Change.HIGHLIGHT, Change.NOTE}, f"user looks at {position(e.card)} ({e.observed_source})"


def _suggestion_requested(m: ViewModel, e) -> tuple[set[Change], str]:
    if not (_card_ok(e.observed) and _card_ok(e.match) and 0 <= e.state < N_STATES):
        return {Change.NOTE}, f"ignored SuggestionRequested: observed {e.observed!r}, match {e.match!r}, state {e.state!r}"
    m.observed, m.match, m.state = e.observed, e.match, e.state
    m.candidates, m.candidates_reported = 0, False
    return {Change.HIGHLIGHT, Change.NOTE}, f"suggestion asked in state {STATE_NAMES[e.state]}"


def _suggestion_made(m: ViewModel, e) -> tuple[set[Change], str]:
    if not (0 <= e.action < N_ACTIONS and 0 <= e.state < N_STATES and _card_ok(e.observed) and _card_ok(e.target)):
        return {Change.NOTE}, f"ignored SuggestionMade: action {e.action!r}, state {e.state!r}"
    m.round, m.turn = e.round, e.turn
    m.state, m.action, m.target, m.chosen_by = e.state, e.action, e.target, e.chosen_by
    m.observed, m.match, m.suggested_from = e.observed, e.target, e.observed
    m.epsilon, m.alpha, m.psi = e.epsilon, e.alpha, e.psi
    m.perceived, m.reward = "", None
    act = action(e.action)
    covered = ALL_CARDS & ~m.face_up & ~m.matched
    m.candidates = covered & int(HEAR_SET[e.observed, e.target, act.hearing]) & int(VIS_SET[e.observed, e.target, act.visual])
    m.candidates_reported = False
    return ({Change.SUGGESTION, Change.HIGHLIGHT, Change.SCHEDULE, Change.NOTE},
            f"suggests {e.action}: {act.name} ({e.chosen_by})")


def _suggestion_perceived(m: ViewModel, e) -> tuple[set[Change], str]:
    if not e.considered:
        m.perceived = "ignored the suggestion"
    elif e.from_memory:
        m.perceived = "knew the match from memory"
    elif not e.consistent:
        m.perceived = "found it inconsistent"
    else:
        m.perceived = f"considered it: {e.candidate_size} candidate card(s)"
    changes = {Change.SUGGESTION, Change.NOTE}
    reported = getattr(e, "candidate_mask", 0)  # 0: none reported (or an older recording)
    if isinstance(reported, int) and 0 < reported <= ALL_CARDS:
        m.candidates, m.candidates_reported = reported, True
        changes.add(Change.HIGHLIGHT)
    return changes, f"user {m.perceived}"


def _turn_resolved(m: ViewModel, e) -> tuple[set[Change], str]:
    if not (_card_ok(e.first) and _card_ok(e.second)):
        return {Change.NOTE}, f"ignored TurnResolved of cards {e.first!r}, {e.second!r}"
    both = (1 << e.first) | (1 << e.second)
    m.face_up &= ~both
    if e.matched:
        m.matched |= both
    m._clear_turn()
    m.turn = e.turn + 1
    return {Change.BOARD, Change.HIGHLIGHT, Change.NOTE}, ("match" if e.matched else "miss") + f" ({position(e.first)} / {position(e.second)})"


def _reward_given(m: ViewModel, e) -> tuple[set[Change], str]:
    m.reward, m.learned = float(e.reward), bool(e.learned)
    why = f" ({e.reason})" if e.reason else ""
    return {Change.REWARD, Change.SUGGESTION, Change.NOTE}, f"reward {e.reward:+.3f}" + ("" if e.learned else " not learned" + why)


def _q_updated(m: ViewModel, e) -> tuple[set[Change], str]:
    if not (0 <= e.state < N_STATES and 0 <= e.action < N_ACTIONS):
        return {Change.NOTE}, f"ignored QUpdated of Q[{e.state!r}, {e.action!r}]: out of the table"
    if m.q[e.state, e.action] != e.q_before:
        m.q_partial = True  # joined late, or an update went missing
    m.q[e.state, e.action] = e.q_after
    m.q_updates += 1
    return {Change.Q}, ""


def _lspi_updated(m: ViewModel, e) -> tuple[set[Change], str]:
    """LSPI changes every entry of the sampled actions at a policy improvement; the event carries
    only this sample's entry, so the table shows the entries as they were last sampled."""
    if not (0 <= e.state < N_STATES and 0 <= e.action < N_ACTIONS):
        return {Change.NOTE}, f"ignored LSPIUpdated of Q[{e.state!r}, {e.action!r}]: out of the table"
    m.q[e.state, e.action] = e.q_after
    m.q_updates += 1
    return {Change.Q}, ""


def _round_ended(m: ViewModel, e) -> tuple[set[Change], str]:
    m.picks_per_round[e.round] = 2 * e.turns
    m.last_round_ended = e.round
    return {Change.ROUND_END, Change.NOTE}, f"round {e.round + 1} over: {counted(2 * e.turns, 'pick')}"


def _session_ended(m: ViewModel, e) -> tuple[set[Change], str]:
    m.ended = e.reason or "ended"
    return {Change.SESSION, Change.NOTE}, f"session ended: {m.ended}, {counted(e.rounds_played, 'round')}"


def _rejected(m: ViewModel, e) -> tuple[set[Change], str]:
    return {Change.NOTE}, f"{type(e).__name__}: {e.reason}"


_HANDLERS = {
    "SessionStarted": _session_started,
    "RoundStarted": _round_started,
    "CardRevealed": _card_revealed,
    "CardObserved": _card_observed,
    "SuggestionRequested": _suggestion_requested,
    "SuggestionMade": _suggestion_made,
    "SuggestionPerceived": _suggestion_perceived,
    "TurnResolved": _turn_resolved,
    "RewardGiven": _reward_given,
    "QUpdated": _q_updated,
    "LSPIUpdated": _lspi_updated,
    "RoundEnded": _round_ended,
    "SessionEnded": _session_ended,
    "PickRejected": _rejected,
    "MessageRejected": _rejected,
}
