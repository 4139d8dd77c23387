"""The game service: the board, the turns, the observed card, ignore by time.

Rule (SPEC "Board and game", "Observed card"; thesis 6.1.1, 7.1.2): the game
owns the session config and announces it (SessionStarted), deals every round
from the session's "deal" stream (18 draws a round, core.board.deal), checks
every pick with core.board.Board and answers it with CardRevealed or
PickRejected (the reason from IllegalPick; the board is unchanged). The
observed card comes from the configured source: "first-pick" (the human study:
the game itself observes the first card) or "intended" (the simulated
participant reports the card it would pick unaided, CardObserved) or "gaze"
(an eye tracker's GazeFixated: the first fixation, on the bus's clock at or
after the first pick, of a covered card other than the first; the game
publishes it as CardObserved). Once the
observed card is known it asks for a suggestion (SuggestionRequested with the
state of thesis 4.1); a WrongSuggestionPressed asks again (attempt + 1). The
second pick resolves the turn (TurnResolved); `end` stops the session early with its
reason (interrupted, aborted, a service failed) and how far it got. Under the "time" ignore rule a
turn whose picks are closer than the window (1.5 s, thesis 7.1.2) is marked
ignored, timed by the picks' own times so a replay decides the same: their
envelope times (the server's clock) or, with `ignore_clock` "page", the board
page's performance clock (CardPicked.page_time_ms); both are recorded.

Under "gaze", a second pick that comes before any fixation resolves the turn
without a suggestion (a silent tracker must not stall a person's game).
The experimenter's SessionPaused / SessionResumed / SessionAborted (the console)
are inputs like any other: while paused every touch is refused with the
reason; an abort ends the session at once (SessionEnded "aborted", the reason as its detail).
A pause or resume taken is answered with ControlTaken (naming it): the recorder files the console's
message as it reaches it, which may be the other side of a touch in flight, and verify feeds it where
the game's own numbered stream says it was taken (node.py `resume`), as it ends an aborted game where
its SessionEnded says.
"""

from __future__ import annotations

import re
from collections import deque

import msgspec

from pairplay.core.board import Board, IllegalPick, Outcome, deal
from pairplay.core.geometry import N_CARDS, state_of
from pairplay.core.rng import UniformStream
from pairplay.schemas import events as ev
from pairplay.schemas.session import SessionConfig
from pairplay.schemas.trust import MAX_REASON, clip

from pairplay.services.node import Rejected, stream_seed


def elsewhen(got: tuple[int, int], now: tuple[int, int]) -> str:
    """Why an input for another moment of the game is refused, `for round 2, turn 4, but the game is in
    round 3, turn 1`: (round, turn) indices as events hold them (from 0), counted from 1 where a user
    reads them, as the board shows them (README). Before, the reasons said the indices (`pick for round 1
    turn 3, but the game is at round 2 turn 0`), a round behind the board's: recorded PickRejected
    reasons of that wording are still the same reason (`GameLogic.comparable`)."""
    return (f"for round {got[0] + 1}, turn {got[1] + 1}, but the game is in round {now[0] + 1}, "
            f"turn {now[1] + 1}")


# A recorded PickRejected reason of the wording before `elsewhen` (its numbers from 0): recordings made
# before it verify, and a game restarted over one resumes (node.py Driver.same).
_OLD_ELSEWHEN = re.compile(r"pick for round (-?\d+) turn (-?\d+), but the game is at round (-?\d+) turn (-?\d+)")


# the participant's inputs: a simulated participant, or the touch-screen board of the human study
PLAYERS = frozenset({"participant", "board"})
# the experimenter's console
CONTROL = frozenset({"SessionPaused", "SessionResumed", "SessionAborted"})
PAUSED = "the session is paused"  # why a paused game refuses an input (a player logic holds it: services/pausehold.py)


class GameLogic:
    name = "game"
    consumes = frozenset({"CardPicked", "CardObserved", "WrongSuggestionPressed", "GazeFixated"}) | CONTROL
    PLAYERS = PLAYERS
    CONTROL = CONTROL
    # inputs whose whole effect is the session's end: a verification of a stopped session ends the game where
    # its recorded SessionEnded says (node.py resume), never where the file holds the input (the recorder
    # orders two sources' messages as they reach it, not as the game took them)
    ENDS_SESSION = frozenset({"SessionAborted"})
    # inputs the game answers with a mark of its own where it took them (ControlTaken): resume and verify feed
    # each where its mark stands among the game's outputs, not where the file holds it (node.py resume)
    PLACED = frozenset({"SessionPaused", "SessionResumed"})
    sources = {tag: (frozenset({"experimenter"}) if tag in CONTROL else PLAYERS) for tag in consumes} \
        | {"GazeFixated": frozenset({"tracker"})}
    GAZE_KEPT = 64  # fixations kept for a first pick that arrives after them

    def __init__(self, config: SessionConfig):
        config.validate()
        self.config = config
        self.deals = UniformStream([stream_seed(config)], "deal")
        self.round = 0
        self.done = False
        self.ended = ""  # the SessionEnded reason once the session is over (a caller's summary: completed or not)
        self.board: Board | None = None
        self.paused = False
        self.fixations: deque[ev.GazeFixated] = deque(maxlen=self.GAZE_KEPT)
        self._new_turn(0)

    def _new_turn(self, turn: int) -> None:
        self.turn = turn
        self.first = -1
        self.first_time_ns = 0
        self.first_page_ms = 0.0
        self.observed = -1
        self.attempt = -1  # no suggestion asked yet this turn

    def start(self) -> list[ev.Event]:
        return [ev.SessionStarted(config=self.config), *self._deal()]

    @staticmethod
    def comparable(e: ev.Event) -> ev.Event:
        """`e` as resume and verify compare it (node.py Driver.same): a PickRejected whose reason has the
        wording of before `elsewhen` (numbers from 0) in today's; anything else as it is."""
        old = _OLD_ELSEWHEN.fullmatch(e.reason) if isinstance(e, ev.PickRejected) else None
        if old is None:
            return e
        r, t, now_r, now_t = map(int, old.groups())
        return msgspec.structs.replace(e, reason=f"pick {elsewhen((r, t), (now_r, now_t))}")

    @staticmethod
    def placed(e: ev.Event) -> tuple[str, str, int] | None:
        """The input (source, tag, seq) an output of the game marks the place of (ControlTaken); else None."""
        return (e.control_source, e.control, e.control_seq) if isinstance(e, ev.ControlTaken) else None

    def end(self, reason: str, detail: str = "") -> list[ev.Event]:
        """End the session early (interrupted, aborted or failed), saying how far it got; [] if it is over."""
        if self.done:
            return []
        self.done, self.ended = True, reason
        # the detail may copy outside text (an abort's reason off the bus): clipped, so the end fits the bus
        return [ev.SessionEnded(reason=reason, rounds_played=self.round, detail=clip(detail, MAX_REASON), round=self.round,
                                turns_in_round=self.turn)]

    def _deal(self) -> list[ev.Event]:
        faces, partners = deal(self.deals.take(N_CARDS))
        faces = faces[0]
        self.board = Board.from_faces(faces)
        # each card's partner, read once a round: a request's match (Board.partner scans the faces: a pick's
        # cost after an idle turn, issue 16)
        self.partners = tuple(int(p) for p in partners[0])
        self.matches = 0
        self._new_turn(0)
        return [ev.RoundStarted(round=self.round, faces=[int(f) for f in faces])]

    def handle(self, e: ev.Event) -> list[ev.Event]:
        if self.done:
            raise Rejected(f"the session is over; {type(e).__name__} ignored")
        if type(e).__name__ in self.CONTROL:
            return self._control(e)
        if self.paused and not isinstance(e, (ev.CardPicked, ev.GazeFixated)):
            raise Rejected(f"{PAUSED}; {type(e).__name__} ignored")
        if isinstance(e, ev.CardPicked):
            return self._pick(e)
        if isinstance(e, ev.GazeFixated):
            return self._gaze(e)
        if (e.round, e.turn) != (self.round, self.turn):
            raise Rejected(f"{type(e).__name__} {elsewhen((e.round, e.turn), (self.round, self.turn))}")
        if isinstance(e, ev.CardObserved):
            return self._observed(e)
        return self._wrong_suggestion(e)

    def _pick(self, e: ev.CardPicked) -> list[ev.Event]:
        def refuse(reason: str) -> list[ev.Event]:
            return [ev.PickRejected(round=e.round, turn=e.turn, card=e.card, reason=reason,
                                    pick_source=e.source, pick_seq=e.seq)]
        if self.paused:
            return refuse(PAUSED)
        if (e.round, e.turn) != (self.round, self.turn):
            return refuse(f"pick {elsewhen((e.round, e.turn), (self.round, self.turn))}")
        if self.first >= 0 and self.attempt < 0 and self.config.observed_source != "gaze":
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
            self.first, self.first_time_ns, self.first_page_ms = e.card, e.time_ns, e.page_time_ms
            if self.config.observed_source == "first-pick":
                out.append(ev.CardObserved(round=self.round, turn=self.turn, card=e.card,
                                           observed_source="first-pick"))
                out.append(self._request(e.card))
            elif self.config.observed_source == "gaze":
                seen = next((f for f in self.fixations if self._looks_for_second(f)), None)
                if seen is not None:
                    out += self._observed_by_gaze(seen)
            return out
        return out + self._resolve(e)

    def _control(self, e: ev.Event) -> list[ev.Event]:
        """The experimenter's console (services/protocol.py): pause, resume (ControlTaken says where), abort."""
        if isinstance(e, ev.SessionAborted):
            return self.end("aborted", e.reason)
        pause = isinstance(e, ev.SessionPaused)
        if pause == self.paused:
            raise Rejected("the session is already " + ("paused" if pause else "running"))
        self.paused = pause
        return [ev.ControlTaken(control=type(e).__name__, control_source=e.source, control_seq=e.seq)]

    def _observed(self, e: ev.CardObserved) -> list[ev.Event]:
        if self.config.observed_source != "intended" or e.observed_source != "intended":
            raise Rejected(f"this session observes by {self.config.observed_source!r}, not {e.observed_source!r}")
        if self.first < 0 or self.attempt >= 0:
            raise Rejected("the observed card is reported once, after the first pick and before the suggestion")
        if not (isinstance(e.card, int) and 0 <= e.card < N_CARDS and self.board.covered >> e.card & 1):
            raise Rejected(f"observed card {e.card} is not a covered card of the board")
        return [self._request(e.card)]

    def _gaze(self, e: ev.GazeFixated) -> list[ev.Event]:
        if self.config.observed_source != "gaze":
            return []  # a tracker may run in any session; only a gaze session reads it
        if not (isinstance(e.card, int) and 0 <= e.card < N_CARDS):
            raise Rejected(f"fixation on card {e.card!r}: off the board")
        if self.first >= 0 and self.attempt < 0 and self._looks_for_second(e):
            return self._observed_by_gaze(e)
        self.fixations.append(e)
        return []

    def _looks_for_second(self, f: ev.GazeFixated) -> bool:
        """A fixation that tells the observed card: after the first pick, on a covered card."""
        return (f.time_ns >= self.first_time_ns and f.card != self.first and 0 <= f.card < N_CARDS
                and bool(self.board.covered >> f.card & 1))

    def _observed_by_gaze(self, f: ev.GazeFixated) -> list[ev.Event]:
        self.fixations.clear()
        return [ev.CardObserved(round=self.round, turn=self.turn, card=f.card, observed_source="gaze"),
                self._request(f.card)]

    def _wrong_suggestion(self, e: ev.WrongSuggestionPressed) -> list[ev.Event]:
        if self.attempt < 0 or len(self.board.up) != 1:
            raise Rejected("'wrong suggestion' is pressed between a suggestion and the second pick")
        if e.attempt >= 0 and e.attempt != self.attempt:
            raise Rejected(f"'wrong suggestion' for attempt {e.attempt}, but the open suggestion is attempt "
                           f"{self.attempt}: stale (pressed twice?)")
        return [self._request(self.observed)]

    def _request(self, observed: int) -> ev.SuggestionRequested:
        match = self.partners[self.first]
        covered = self.board.covered
        # the scalar form (the batch one's numpy calls were most of a first pick's cost cold: issue 16);
        # the match, the first card's partner, is covered, so the state exists
        state = state_of(observed, match, covered)
        self.observed = observed
        self.attempt += 1
        return ev.SuggestionRequested(round=self.round, turn=self.turn, attempt=self.attempt, state=state,
                                      observed=observed, match=match, covered_mask=covered, first=self.first)

    def _resolve(self, e: ev.CardPicked) -> list[ev.Event]:
        self.board, res = self.board.resolve()
        interval_ms = (e.time_ns - self.first_time_ns) / 1e6
        page_ms = e.page_time_ms - self.first_page_ms if e.page_time_ms > 0 and self.first_page_ms > 0 else -1.0
        timed = page_ms if self.config.ignore_clock == "page" and page_ms >= 0 else interval_ms
        ignored = self.config.ignore_rule == "time" and timed < self.config.ignore_window_ms
        self.matches += res.matched
        out: list[ev.Event] = [ev.TurnResolved(round=self.round, turn=self.turn, first=res.first,
                                               second=res.second, matched=res.matched, round_over=res.round_over,
                                               interval_ms=interval_ms, ignored_by_time=ignored,
                                               page_interval_ms=page_ms)]
        if not res.round_over:
            self._new_turn(self.turn + 1)
            return out
        out.append(ev.RoundEnded(round=self.round, turns=self.turn + 1, matches=self.matches))
        self.round += 1
        if self.round >= self.config.rounds:
            self.done, self.ended = True, "completed"
            return out + [ev.SessionEnded(reason="completed", rounds_played=self.round)]
        return out + self._deal()
