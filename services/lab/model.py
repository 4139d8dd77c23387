"""What the lab's pages show, as a fold over the session's events (no I/O, no clocks).

Rule: the pages hold no truth. `LabModel.apply(event)` folds one bus event;
`board_view()` and `mirror_view()` give the JSON each page renders, so a page
that reconnects (or a second page) draws exactly what the log says. The board
view never carries the face of a covered card (a participant could read the
page's traffic); the mirror view adds the suggestion in words and the card
region its visual part points at (core.interpretation's VIS_SET, thesis 4.2),
and what the robot did (RobotActed); whether the experimenter has paused the game
(ControlTaken: what the game took). Malformed event content changes nothing.
"""

from __future__ import annotations

from dataclasses import dataclass, field

from pairplay.core.actions import N_ACTIONS, action
from pairplay.core.geometry import ALL_CARDS, N_CARDS
from pairplay.core.interpretation import HEAR_SET, VIS_SET

from pairplay.services.view.model import position, suggestion_parts


def _card_ok(card) -> bool:
    return isinstance(card, int) and 0 <= card < N_CARDS


def cards_of(mask: int) -> list[int]:
    return [c for c in range(N_CARDS) if mask >> c & 1]


@dataclass
class LabModel:
    session: str = ""
    participant: str = ""
    rounds: int = 0
    turn_back_ms: float = 1500.0
    observed_source: str = ""
    started: bool = False
    round: int = -1
    turn: int = 0
    faces: list[int] = field(default_factory=lambda: [-1] * N_CARDS)
    face_up: int = 0
    matched: int = 0
    first: int = -1  # first card of the open turn
    observed: int = -1
    requested: int = -1  # attempt the game asked for (-1: none this turn)
    suggestion: dict | None = None  # the learner's answer to the open request
    last_turn: dict | None = None  # the last resolved turn, for the page's turn-back
    resolved: int = 0  # turns resolved so far (numbers last_turn)
    matches: int = 0
    robot: list[dict] = field(default_factory=list)  # the robot's last acts, newest last
    notice: dict | None = None  # the game's last refusal of a board input
    paused: bool = False  # the experimenter paused the game (as the game took it: ControlTaken)
    ended: str = ""
    events: int = 0

    # -- the fold ---------------------------------------------------------------
    def apply(self, e) -> None:
        self.events += 1
        handler = getattr(self, "_" + type(e).__name__, None)
        if handler is not None:
            handler(e)

    def _SessionStarted(self, e) -> None:
        c = e.config
        self.session, self.participant, self.rounds = c.session, c.participant, c.rounds
        self.turn_back_ms, self.observed_source, self.started = c.turn_back_ms, c.observed_source, True

    def _RoundStarted(self, e) -> None:
        if len(e.faces) != N_CARDS:
            return
        self.round, self.turn, self.faces = e.round, 0, list(e.faces)
        self.face_up = self.matched = self.matches = 0
        self._new_turn()

    def _new_turn(self) -> None:
        self.first = self.observed = self.requested = -1
        self.suggestion = None

    def _CardRevealed(self, e) -> None:
        if not _card_ok(e.card):
            return
        if e.pick == 0:
            # a request or suggestion of this turn that overtook its first card stays
            early = (self.requested, self.suggestion) if (e.round, e.turn) == (self.round, self.turn) else (-1, None)
            self._new_turn()
            self.requested, self.suggestion = early
            self.first = e.card
        self.round, self.turn = e.round, e.turn
        self.face_up |= 1 << e.card
        self.faces[e.card] = e.face
        self.notice = None

    def _CardObserved(self, e) -> None:
        if _card_ok(e.card):
            self.observed = e.card

    def _SuggestionRequested(self, e) -> None:
        # the learner's answer may overtake the game's request (different keys): a suggestion
        # already here for this attempt or a later one stays
        if (e.round, e.turn) == (self.round, self.turn) and e.attempt > self.requested:
            self.requested = e.attempt
            if self.suggestion is not None and self.suggestion["attempt"] < e.attempt:
                self.suggestion = None

    def _SuggestionMade(self, e) -> None:
        if (e.round, e.turn) != (self.round, self.turn) or not (0 <= e.action < N_ACTIONS) \
                or not (_card_ok(e.observed) and _card_ok(e.target)):
            return
        act = action(e.action)
        covered = ALL_CARDS & ~self.face_up & ~self.matched
        parts = suggestion_parts(e.action, e.target)
        self.suggestion = {
            "attempt": e.attempt, "action": e.action, "name": act.name, "chosen_by": e.chosen_by,
            "observed": e.observed, "target": e.target, "parts": parts,
            # the cards each part points at, among the covered ones (what a user who perceives it all considers)
            "heard": cards_of(covered & int(HEAR_SET[e.observed, e.target, act.hearing])),
            "seen": cards_of(covered & int(VIS_SET[e.observed, e.target, act.visual])),
            "time_ns": int(e.time_ns),
        }

    def _TurnResolved(self, e) -> None:
        if not (_card_ok(e.first) and _card_ok(e.second)):
            return
        both = (1 << e.first) | (1 << e.second)
        self.face_up &= ~both
        if e.matched:
            self.matched |= both
            self.matches += 1
        self.resolved += 1
        self.last_turn = {"id": self.resolved, "round": e.round, "turn": e.turn, "cards": [e.first, e.second],
                          "faces": [self.faces[e.first], self.faces[e.second]], "matched": e.matched,
                          "interval_ms": e.interval_ms, "page_interval_ms": e.page_interval_ms,
                          "ignored": e.ignored_by_time}
        self.turn = e.turn + 1
        self._new_turn()

    def _PickRejected(self, e) -> None:
        if e.pick_source == "board":
            self.notice = {"card": e.card, "reason": e.reason}

    def _RobotActed(self, e) -> None:
        self.robot = (self.robot + [{
            "round": e.round, "turn": e.turn, "attempt": e.attempt, "action": e.action, "backend": e.backend,
            "outcome": e.outcome, "commands": list(e.commands)[:8], "error": e.error,
            # plain ints for the page (the bus's Nanos would be {sec, nsec} objects in its JSON)
            "received_ns": int(e.received_ns), "sent_ns": int(e.sent_ns), "acked_ns": int(e.acked_ns),
            "done_ns": int(e.done_ns),
        }])[-5:]

    def _ControlTaken(self, e) -> None:
        # what the game took, not what the console asked: a refused pause or resume changed nothing
        if e.control in ("SessionPaused", "SessionResumed"):
            self.paused = e.control == "SessionPaused"

    def _SessionEnded(self, e) -> None:
        self.ended = e.reason or "ended"

    # -- what the pages draw -------------------------------------------------------
    def phase(self) -> str:
        if self.ended:
            return "over"
        if not self.started or self.round < 0:
            return "starting"
        if self.first < 0:
            return "first"
        if self.suggestion is None and self.requested >= 0:
            return "thinking"
        return "second" if self.suggestion is not None else "looking"

    def board_view(self) -> dict:
        """The touch screen: card states, the faces of cards that are up, the observed card."""
        shown = self.face_up | self.matched
        cards = [{"state": "matched" if self.matched >> c & 1 else "up" if self.face_up >> c & 1 else "down",
                  "face": self.faces[c] if shown >> c & 1 else -1} for c in range(N_CARDS)]
        return {"session": self.session, "rounds": self.rounds, "round": self.round, "turn": self.turn,
                "phase": self.phase(), "cards": cards, "observed": self.observed, "first": self.first,
                "attempt": self.suggestion["attempt"] if self.suggestion else -1, "matches": self.matches,
                "last_turn": self.last_turn, "turn_back_ms": self.turn_back_ms, "notice": self.notice,
                "ended": self.ended, "paused": self.paused and not self.ended}

    def mirror_view(self) -> dict:
        """The robot's stand-in: the board as the participant sees it, the suggestion, the robot."""
        view = self.board_view()
        s = self.suggestion
        if s is not None:
            # not the target: this page stands in for the robot, which points only as its action says
            s = {k: v for k, v in s.items() if k not in ("time_ns", "target")}
            s["observed_at"] = position(s["observed"])
            s["speech"] = s["parts"]["speech"]
        view.update({"suggestion": s, "robot": self.robot, "participant": self.participant,
                     "observed_source": self.observed_source})
        return view
