"""A scripted participant of the human study: a core persona choosing what a person would touch.

Rule: `ScriptedPlayer` plays a human session (observed card = the first pick,
ignore rule by time) as the board page would report it: it publishes only the
board's inputs (CardPicked, WrongSuggestionPressed, QuestionnaireAnswered; source
"board"), never what it perceived. Its choices are core.user.SimulatedUsers'
(thesis 6.1.3) on its own "user" stream (seeded by the session), so a pilot is
reproducible; a considered suggestion that is inconsistent is answered with the
wrong-suggestion button once per turn when `press_wrong` (what phase 1 asked of
its users, 7.2). The same object drives a real browser in the tests: `next_action`
says which card (or the button) to touch next.

Reaction time: a person who reads a suggestion takes longer than one who picks
from memory or ignores it. The player stamps its second pick `think_ms` after
the first when it considered the suggestion and `glance_ms` after otherwise
(an offset on its clock, `offset_ns`), so the game's ignore rule (7.1.2) sees
the persona's attention, not the speed of the script.

Paused from the console, it holds its touches until the game runs again and
makes again the one the game refused (services/pausehold.py), as a person would.

Questionnaire answers come from the persona's features (`answers_for`):
attention to speech follows hearing, to head movements sight, following the
robot focus; free text names the persona. They exist so that a pilot's report
has something to summarise, not as a model of people.
"""

from __future__ import annotations

import time

import numpy as np

from pairplay.core.geometry import ALL_CARDS
from pairplay.core.personas import persona
from pairplay.core.rng import UniformStream, game_seed
from pairplay.core.user import SimulatedUsers
from pairplay.schemas import events as ev
from pairplay.schemas.study import Item

from pairplay.services.node import NotYet
from pairplay.services.participant import end_turn, intend_second, partner_of
from pairplay.services.pausehold import CONSUMES as PAUSE_READS, PauseHold


class ScriptedPlayer:
    name = "board"
    consumes = frozenset({"SessionStarted", "RoundStarted", "CardRevealed", "SuggestionMade", "TurnResolved",
                          "SessionEnded"}) | PAUSE_READS
    sources = {tag: frozenset({"game"}) for tag in consumes} | {"SuggestionMade": frozenset({"learner"})}

    def __init__(self, persona_key: str, *, press_wrong: bool = True, questions: list[Item] | None = None,
                 questionnaire: str = "", think_ms: float = 2500.0, glance_ms: float = 400.0):
        self.persona = persona(persona_key)
        self.press_wrong = press_wrong
        self.questions = list(questions or [])
        self.questionnaire = questionnaire
        self.think_ns, self.glance_ns = int(think_ms * 1e6), int(glance_ms * 1e6)
        self.offset_ns = 0  # added to the wall clock: the simulated reaction times so far
        self.users: SimulatedUsers | None = None
        self.done = False
        self.stage = "idle"
        self.pressed = 0
        self.picks = 0
        self.presses = 0
        self.answered = False
        self.hold = PauseHold(self.name)  # its inputs while the console has the game paused

    def clock(self) -> int:
        """The clock of this player's Node: wall time plus the simulated reaction times."""
        return time.time_ns() + self.offset_ns

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
            c = e.config
            self.observed_first = c.observed_source == "first-pick"
            self.users = SimulatedUsers([self.persona], UniformStream(
                [game_seed(c.seed, f"scripted:{self.persona.key}:{c.participant}", c.game_index)], "user"))
            return []
        if self.users is None:
            raise NotYet
        if isinstance(e, ev.RoundStarted):
            self.round, self.partner, self.matched = e.round, partner_of(e.faces), 0
            self.users.new_round()
            return self._first(0)
        if isinstance(e, ev.CardRevealed):
            if (e.round, e.turn) == (self.round, self.turn) and e.pick == 0 and self.stage == "first":
                self.match, self.covered_now, self.intended, self.from_memory = intend_second(
                    self.users, self.partner, self.first, self.covered)
                self.stage = "suggested"
            return []
        if isinstance(e, ev.SuggestionMade):
            if (e.round, e.turn) != (self.round, self.turn):
                return []
            if self.stage == "first":
                raise NotYet
            return self._respond(e) if self.stage == "suggested" else []
        if isinstance(e, ev.TurnResolved):
            if (e.round, e.turn) != (self.round, self.turn):
                return []
            if self.stage != "second":
                raise NotYet
            self.matched = end_turn(self.users, self.matched, e)
            self.stage = "idle"
            return [] if e.round_over else self._first(self.turn + 1)
        if isinstance(e, ev.SessionEnded):
            self.done = True
            if self.questions and not self.answered:
                self.answered = True
                return [ev.QuestionnaireAnswered(questionnaire=self.questionnaire,
                                                 answers=answers_for(self.persona, self.questions))]
        return []

    def _first(self, turn: int) -> list[ev.Event]:
        self.turn, self.pressed = turn, 0
        self.covered = ALL_CARDS & ~self.matched
        self.first = int(self.users.first_pick(np.array([self.covered]), self.partner)[0])
        self.stage = "first"
        self.picks += 1
        return [ev.CardPicked(round=self.round, turn=turn, card=self.first)]

    def _respond(self, s: ev.SuggestionMade) -> list[ev.Event]:
        observed = self.first if self.observed_first else self.intended
        r = self.users.respond(np.array([s.action]), np.array([observed]), np.array([self.match]),
                               np.array([self.intended]), np.array([self.from_memory]), np.array([self.covered_now]))
        considered, consistent = bool(r.considered[0]), bool(r.consistent[0])
        if self.press_wrong and considered and not consistent and self.pressed == 0:
            self.pressed += 1
            self.presses += 1
            return [ev.WrongSuggestionPressed(round=self.round, turn=self.turn, attempt=s.attempt)]
        self.offset_ns += self.think_ns if considered else self.glance_ns
        self.stage = "second"
        self.picks += 1
        return [ev.CardPicked(round=self.round, turn=self.turn, card=int(r.second[0]))]


def _scale(feature: int, points: int) -> int:
    """A 1..6 persona feature on a 1..points Likert scale."""
    return int(round(1 + (feature - 1) * (points - 1) / 5))


def answers_for(who, questions: list[Item]) -> dict[str, str]:
    """Deterministic answers of a persona (see the module rule); every answer is a string."""
    by_topic = {"followed": who.focus, "avoided-wrong": who.focus, "speech": who.hearing, "visual": who.sight,
                "gaze": who.sight}
    out: dict[str, str] = {}
    for q in questions:
        if q.kind == "likert":
            out[q.id] = str(_scale(by_topic.get(q.id, 4), q.scale))
        elif q.kind == "choice":
            if q.id == "contradictory":
                pick = 0 if who.hearing >= who.sight else 1
            else:
                pick = (who.focus + who.memory) % len(q.options)
            out[q.id] = q.options[min(pick, len(q.options) - 1)]
        elif q.required or q.id == "comments":
            out[q.id] = f"scripted answer ({who.name})"
    return out
