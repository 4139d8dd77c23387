"""What a player logic sends the game while the experimenter has it paused.

Rule: a paused game refuses every input of its player (services/game.py: a pick
is answered PickRejected "the session is paused", an observed card or a
wrong-suggestion press MessageRejected), and a player that waits for the answer
to a refused input waits for good: a persona's pilot paused and resumed from the
console never went on (trial34 F). A person touches again; a player logic
(services/scripted.py, services/participant.py) keeps a `PauseHold`, which
learns the pause and the resume from the game's own stream (ControlTaken, where
the game took each), holds what the player would send the game while it is
paused and sends it once the resume is taken, after the one input the game
never answered (in flight when the game took the pause, so refused). A player
has one input open at a time (it waits for the answer before the next), so
that one is all there is to send again.

An input in flight across the whole pause (taken after the resume) is sent
twice; the game refuses the second as a stale pick or press and goes on.
"""

from __future__ import annotations

from pairplay.schemas import events as ev

from pairplay.services.game import PAUSED

# the player's inputs the game takes (GameLogic.consumes less the console and the gaze tracker)
INPUTS = (ev.CardPicked, ev.CardObserved, ev.WrongSuggestionPressed)
# what the game answers a player's input with (a press's MessageRejected aside: no player reads those)
ANSWERS = (ev.CardRevealed, ev.PickRejected, ev.SuggestionRequested)
# what a player logic reads of the game for its hold, besides what it plays by
CONSUMES = frozenset({"ControlTaken", "SuggestionRequested", "PickRejected", "CardRevealed", "SessionEnded"})


class PauseHold:
    def __init__(self, player: str):
        self.player = player  # the player's source name: its own picks' PickRejected say it
        self.paused = False
        self.open: ev.Event | None = None  # the last input sent that the game has not answered
        self.held: list[ev.Event] = []

    def send(self, out: list[ev.Event]) -> list[ev.Event]:
        """`out`, the player's outputs, as they go now: none while paused (held, in order), else all of them."""
        if not any(isinstance(e, INPUTS) for e in out):
            return out  # nothing for the game (a questionnaire's answers): never held
        if self.paused:
            self.held += out
            return []
        self.open = next(e for e in reversed(out) if isinstance(e, INPUTS))
        return out

    def saw(self, e: ev.Event) -> list[ev.Event]:
        """Read an event of the game: an answer closes the open input; ControlTaken pauses or resumes (the
        outputs to send then: the open input again, what was held). Reading one twice changes nothing more
        (a logic's NotYet feeds it again), but for ControlTaken, which no player logic defers."""
        if isinstance(e, ev.ControlTaken):
            if e.control == "SessionPaused":
                self.paused = True
                return []
            self.paused = False
            again, held, self.held = ([self.open] if self.open is not None else []), self.held, []
            self.open = None
            return self.send(again) + self.send(held)
        if isinstance(e, ev.SessionEnded):
            self.paused, self.open, self.held = False, None, []
        elif self._answers(e):
            self.open = None
        return []

    def _answers(self, e: ev.Event) -> bool:
        o = self.open
        if o is None or not isinstance(e, ANSWERS) or (e.round, e.turn) != (o.round, o.turn):
            return False
        if isinstance(o, ev.CardPicked):
            if isinstance(e, ev.CardRevealed):
                return e.card == o.card
            # refused for anything but the pause: answered (the player's own logic says what it does then)
            return isinstance(e, ev.PickRejected) and e.pick_source == self.player and e.card == o.card \
                and e.reason != PAUSED
        if isinstance(e, ev.SuggestionRequested):  # an observed card asks attempt 0, a press the next one
            return e.attempt == (0 if isinstance(o, ev.CardObserved) else o.attempt + 1)
        return False
