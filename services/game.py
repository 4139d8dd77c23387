"""The game service: the board, the turns, the observed card, ignore by time.

Rule (SPEC "Board and game", "Observed card"; thesis 6.1.1, 7.1.2): the game
owns the session config and announces it (SessionStarted), deals every round
from the session's "deal" stream (18 draws a round, core.board.deal), checks
every pick with core.board.Board and answers it with CardRevealed or
PickRejected (the reason from IllegalPick; the board is unchanged). The
observed card comes from the configured source: "first-pick" (the human study:
the game itself observes the first card) or "intended" (the simulated
participant reports the card it would pick unaided, CardObserved). Once the
observed card is known it asks for a suggestion (SuggestionRequested with the
state of thesis 4.1); a WrongSuggestionPressed asks again (attempt + 1). The
second pick resolves the turn (TurnResolved); `end` stops the session early with its
reason (interrupted, aborted, a service failed) and how far it got. Under the "time" ignore rule a
turn whose picks are closer than the window (1.5 s, thesis 7.1.2) is marked
ignored, timed by the picks' own envelope times so a replay decides the same.
"""

from __future__ import annotations

import numpy as np

from pairplay.core.board import Board, IllegalPick, Outcome, deal
from pairplay.core.geometry import N_CARDS, states_of
from pairplay.core.rng import UniformStream
from pairplay.schemas import events as ev
from pairplay.schemas.session import SessionConfig

from pairplay.services.node import Rejected, stream_seed


class GameLogic:
    name = "game"
    consumes = frozenset({"CardPicked", "CardObserved", "WrongSuggestionPressed"})
    # the participant's inputs: a simulated participant, or the touch-screen board of the human study
    PLAYERS = frozenset({"participant", "board"})
    sources = dict.fromkeys(consumes, PLAYERS)

    def __init__(self, config: SessionConfig):
        config.validate()
        self.config = config
        self.deals = UniformStream([stream_seed(config)], "deal")
        self.round = 0
        self.done = False
        self.board: Board | None = None
        self._new_turn(0)

    def _new_turn(self, turn: int) -> None:
        self.turn = turn
        self.first = -1
        self.first_time_ns = 0
        self.observed = -1
        self.attempt = -1  # no suggestion asked yet this turn

    def start(self) -> list[ev.Event]:
        return [ev.SessionStarted(config=self.config), *self._deal()]

    def end(self, reason: str, detail: str = "") -> list[ev.Event]:
        """End the session early (interrupted, aborted or failed), saying how far it got; [] if it is over."""
        if self.done:
            return []
        self.done = True
        return [ev.SessionEnded(reason=reason, rounds_played=self.round, detail=detail, round=self.round,
                                turns_in_round=self.turn)]

    def _deal(self) -> list[ev.Event]:
        faces, _ = deal(self.deals.take(N_CARDS))
        faces = faces[0]
        self.board = Board.from_faces(faces)
        self.matches = 0
        self._new_turn(0)
        return [ev.RoundStarted(round=self.round, faces=[int(f) for f in faces])]

    def handle(self, e: ev.Event) -> list[ev.Event]:
        if self.done:
            raise Rejected(f"the session is over; {type(e).__name__} ignored")
        if isinstance(e, ev.CardPicked):
            return self._pick(e)
        if (e.round, e.turn) != (self.round, self.turn):
            raise Rejected(f"{type(e).__name__} for round {e.round} turn {e.turn}, but the game is at "
                           f"round {self.round} turn {self.turn}")
        if isinstance(e, ev.CardObserved):
            return self._observed(e)
        return self._wrong_suggestion(e)

    def _pick(self, e: ev.CardPicked) -> list[ev.Event]:
        def refuse(reason: str) -> list[ev.Event]:
            return [ev.PickRejected(round=e.round, turn=e.turn, card=e.card, reason=reason,
                                    pick_source=e.source, pick_seq=e.seq)]
        if (e.round, e.turn) != (self.round, self.turn):
            return refuse(f"pick for round {e.round} turn {e.turn}, but the game is at round {self.round} "
                          f"turn {self.turn}")
        if self.first >= 0 and self.attempt < 0:
            return refuse("the second card comes after the suggestion: the observed card is not known yet")
        try:
            board, outcome = self.board.pick(e.card)
        except IllegalPick as err:
            return refuse(str(err))
        self.board = board
        out: list[ev.Event] = [ev.CardRevealed(round=self.round, turn=self.turn, card=e.card,
                                               face=board.faces[e.card], pick=int(outcome is Outcome.SECOND),
                                               pick_seq=e.seq)]
        if outcome is Outcome.FIRST:
            self.first, self.first_time_ns = e.card, e.time_ns
            if self.config.observed_source == "first-pick":
                out.append(ev.CardObserved(round=self.round, turn=self.turn, card=e.card,
                                           observed_source="first-pick"))
                out.append(self._request(e.card))
            return out
        return out + self._resolve(e)

    def _observed(self, e: ev.CardObserved) -> list[ev.Event]:
        if self.config.observed_source != "intended" or e.observed_source != "intended":
            raise Rejected(f"this session observes by {self.config.observed_source!r}, not {e.observed_source!r}")
        if self.first < 0 or self.attempt >= 0:
            raise Rejected("the observed card is reported once, after the first pick and before the suggestion")
        if not (isinstance(e.card, int) and 0 <= e.card < N_CARDS and self.board.covered >> e.card & 1):
            raise Rejected(f"observed card {e.card} is not a covered card of the board")
        return [self._request(e.card)]

    def _wrong_suggestion(self, e: ev.WrongSuggestionPressed) -> list[ev.Event]:
        if self.attempt < 0 or len(self.board.up) != 1:
            raise Rejected("'wrong suggestion' is pressed between a suggestion and the second pick")
        return [self._request(self.observed)]

    def _request(self, observed: int) -> ev.SuggestionRequested:
        match = self.board.partner(self.first)
        covered = self.board.covered
        state = int(states_of(np.array([observed]), np.array([match]), np.array([covered], dtype=np.int64))[0])
        self.observed = observed
        self.attempt += 1
        return ev.SuggestionRequested(round=self.round, turn=self.turn, attempt=self.attempt, state=state,
                                      observed=observed, match=match, covered_mask=covered, first=self.first)

    def _resolve(self, e: ev.CardPicked) -> list[ev.Event]:
        self.board, res = self.board.resolve()
        interval_ms = (e.time_ns - self.first_time_ns) / 1e6
        ignored = self.config.ignore_rule == "time" and interval_ms < self.config.ignore_window_ms
        self.matches += res.matched
        out: list[ev.Event] = [ev.TurnResolved(round=self.round, turn=self.turn, first=res.first,
                                               second=res.second, matched=res.matched, round_over=res.round_over,
                                               interval_ms=interval_ms, ignored_by_time=ignored)]
        if not res.round_over:
            self._new_turn(self.turn + 1)
            return out
        out.append(ev.RoundEnded(round=self.round, turns=self.turn + 1, matches=self.matches))
        self.round += 1
        if self.round >= self.config.rounds:
            self.done = True
            return out + [ev.SessionEnded(reason="completed", rounds_played=self.round)]
        return out + self._deal()
