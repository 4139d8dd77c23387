"""The simulated participant: a persona of appendix A playing through the bus.

Rule (thesis 6.1.3): the participant is core.user.SimulatedUsers with a batch
of one and the session's "user" stream, called in the order of the in-process
study (core.simulate): at the start of each turn the first pick (drawing the
turn's uniforms), once the game shows that card the intended card (published
as CardObserved when the session observes by intention), on the suggestion
the response (SuggestionPerceived, then the second pick), and when the game
resolves the turn the memory update. It waits for what each step needs
(NotYet): a suggestion that overtook the game's CardRevealed is kept until the
card is shown. It reads the faces from RoundStarted, as a person sees the
cards it turns; it never reads another participant's state. An input a paused game
refused is made again once it runs (services/pausehold.py).
"""

from __future__ import annotations

import numpy as np

from pairplay.core.geometry import ALL_CARDS
from pairplay.core.personas import persona
from pairplay.core.rng import UniformStream
from pairplay.core.user import SimulatedUsers
from pairplay.schemas import events as ev

from pairplay.services.game import PAUSED
from pairplay.services.node import NotYet, Rejected, refused_start, stream_seed
from pairplay.services.pausehold import CONSUMES as PAUSE_READS, PauseHold


class ParticipantLogic:
    name = "participant"
    consumes = frozenset({"SessionStarted", "RoundStarted", "CardRevealed", "PickRejected", "SuggestionMade",
                          "TurnResolved", "SessionEnded"}) | PAUSE_READS
    sources = {tag: frozenset({"game"}) for tag in consumes} | {"SuggestionMade": frozenset({"learner"})}

    def __init__(self, persona_key: str | None = None):
        self.persona_key = persona_key  # None: whatever the session config names
        self.users: SimulatedUsers | None = None
        self.done = False
        self.refused = ""  # why we refused the session's start (refused_start)
        self.stage = "idle"  # idle -> first -> observed -> second -> idle
        self.round, self.turn = -1, -1
        self.hold = PauseHold(self.name)  # its inputs while an experimenter has the game paused

    def start(self) -> list[ev.Event]:
        return []

    def handle(self, e: ev.Event) -> list[ev.Event]:
        # a paused game refuses every input: they wait in the hold until it runs again
        if isinstance(e, ev.ControlTaken):
            return self.hold.saw(e)
        self.hold.saw(e)
        return self.hold.send(self._play(e))

    def _play(self, e: ev.Event) -> list[ev.Event]:
        if isinstance(e, ev.SessionStarted):
            return self._configure(e)
        if self.users is None:
            self.done = refused_start(self, e)  # NotYet until the start comes; after a refused one, the end
            return []
        if isinstance(e, ev.RoundStarted):
            return self._round(e)
        if isinstance(e, ev.CardRevealed):
            return self._revealed(e)
        if isinstance(e, ev.SuggestionMade):
            return self._respond(e)
        if isinstance(e, ev.TurnResolved):
            return self._resolved(e)
        if isinstance(e, ev.PickRejected):
            if e.pick_source == self.name and e.reason != PAUSED:  # refused paused: made again on the resume
                raise Rejected(f"the game refused our pick of card {e.card}: {e.reason}")
            return []
        if isinstance(e, ev.SessionEnded):
            self.done = True
        return []

    def _configure(self, e: ev.SessionStarted) -> list[ev.Event]:
        c = e.config
        key = self.persona_key or c.persona
        if not c.participant.startswith("sim:"):
            self.refused = f"participant {c.participant!r} is not a simulated one"
        elif self.persona_key and self.persona_key != c.persona:
            self.refused = f"this participant plays {self.persona_key!r}, the session expects {c.persona!r}"
        else:
            try:
                who = persona(key)
            except KeyError as err:
                self.refused = str(err)
        if self.refused:
            raise Rejected(self.refused)
        self.config = c
        self.users = SimulatedUsers([who], UniformStream([stream_seed(c)], "user"))
        return []

    def _round(self, e: ev.RoundStarted) -> list[ev.Event]:
        if self.stage != "idle":
            raise NotYet  # the last turn of the round before is not over for us yet
        self.round = e.round
        self.partner = partner_of(e.faces)
        self.matched = 0
        self.users.new_round()
        return self._first_pick(0)

    def _first_pick(self, turn: int) -> list[ev.Event]:
        self.turn = turn
        self.covered = ALL_CARDS & ~self.matched
        self.first = int(self.users.first_pick(np.array([self.covered]), self.partner)[0])
        self.stage = "first"
        return [ev.CardPicked(round=self.round, turn=turn, card=self.first)]

    def _here(self, e) -> bool:
        """Is `e` about the turn we are playing? Later turns wait; earlier ones are stale."""
        now, then = (self.round, self.turn), (e.round, e.turn)
        if then > now:
            raise NotYet
        return then == now

    def _revealed(self, e: ev.CardRevealed) -> list[ev.Event]:
        if not self._here(e) or e.pick != 0 or self.stage != "first":
            return []
        self.match, self.covered_now, self.intended, self.from_memory = intend_second(
            self.users, self.partner, self.first, self.covered)
        self.stage = "observed"
        if self.config.observed_source == "intended":
            return [ev.CardObserved(round=self.round, turn=self.turn, card=self.intended, observed_source="intended")]
        return []

    def _respond(self, s: ev.SuggestionMade) -> list[ev.Event]:
        if not self._here(s):
            return []
        if self.stage == "first":
            raise NotYet  # the suggestion overtook the game's CardRevealed
        if self.stage != "observed":
            return []
        observed = self.intended if self.config.observed_source == "intended" else self.first
        r = self.users.respond(np.array([s.action]), np.array([observed]), np.array([self.match]),
                               np.array([self.intended]), np.array([self.from_memory]), np.array([self.covered_now]))
        self.second = int(r.second[0])
        self.stage = "second"
        cand = int(r.candidates[0])
        return [ev.SuggestionPerceived(round=self.round, turn=self.turn, attempt=s.attempt,
                                       considered=bool(r.considered[0]), consistent=bool(r.consistent[0]),
                                       candidate_size=cand.bit_count(), from_memory=self.from_memory,
                                       candidate_mask=cand, second=self.second),
                ev.CardPicked(round=self.round, turn=self.turn, card=self.second)]

    def _resolved(self, e: ev.TurnResolved) -> list[ev.Event]:
        if not self._here(e):
            return []
        if self.stage != "second":
            raise NotYet
        self.matched = end_turn(self.users, self.matched, e)
        self.stage = "idle"
        if e.round_over:
            return []
        return self._first_pick(self.turn + 1)


def intend_second(users: SimulatedUsers, partner: np.ndarray, first: int, covered: int) -> tuple[int, int, int, bool]:
    """The one simulated user's second-pick intention once its first card `first` is face up (thesis 6.1.3).

    `partner` is `partner_of`'s (1, 18) table, `covered` the covered cards' bitmask before the
    first pick. Returns (the first card's partner, the covered mask without `first`, the
    intended card, whether it comes from memory)."""
    match = int(partner[0, first])
    covered_now = covered & ~(1 << first)
    intended, from_memory = users.intend(np.array([first]), np.array([match]), np.array([covered_now]))
    return match, covered_now, int(intended[0]), bool(from_memory[0])


def end_turn(users: SimulatedUsers, matched: int, e: ev.TurnResolved) -> int:
    """Tell the one simulated user how the turn `e` ended (it remembers both cards); returns the
    matched cards' bitmask with this turn's pair added when it matched."""
    users.end_turn(np.array([e.first]), np.array([e.second]), np.array([e.matched]))
    return matched | (1 << e.first) | (1 << e.second) if e.matched else matched


def partner_of(faces: list[int]) -> np.ndarray:
    """PARTNER[0, card]: the other card with the same face, as core.board.deal gives it."""
    f = np.asarray(faces)
    same = (f[:, None] == f[None, :]) & ~np.eye(f.size, dtype=bool)
    return np.argmax(same, axis=1)[None, :]
