"""From a composite action to a timeline of robot commands, backend-neutral.

Rule (thesis 4.2, tables 4.1-4.4, appendix D): one command per non-"nothing" part,
all due at once (t = 0) except the later steps of a head turn:
  speech 1..6  -> Say(text)   1-based "row x and column y" of the matching card
  smile        -> Gesture(smile name)
  nod          -> Look at the observed card, Gesture(nod name)
  head turn    -> Look(head) at the observed card; after `head_turn_lead_s` Look(head)
                  at the point `head_turn_offset_m` past it in the turn's direction on
                  the board; after `head_turn_hold_s` more, Look(head) back at rest.
                  (Appendix D: "concatenations of multiple gaze events produce a head
                  movement".)
  gaze         -> Look at the matching card
Speech goes first: it is what the participant waits for. Every Say aborts the
robot's current speech; what a superseded suggestion left playing or turned is
undone by the driver, which knows what was written (StopSpeech, the head back
to rest: services/robot/driver.py).
Texts and gesture names are data (RobotConfig), the table below is the only logic.
"""

from __future__ import annotations

from typing import Union

import msgspec

from pairplay.core.actions import action
from pairplay.core.geometry import card_col, card_row
from pairplay.schemas.robot import GestureNames, RobotConfig, SpeechTexts

from pairplay.services.robot.calibration import Board


class Say(msgspec.Struct, frozen=True, tag="say"):
    text: str
    abort: bool = True


class StopSpeech(msgspec.Struct, frozen=True, tag="stop_speech"):
    pass


class Gesture(msgspec.Struct, frozen=True, tag="gesture"):
    name: str


class Look(msgspec.Struct, frozen=True, tag="look"):
    """Gaze at a point (metres, robot frame); head=True turns the head (a head movement)."""

    x: float
    y: float
    z: float
    head: bool = False


Command = Union[Say, StopSpeech, Gesture, Look]


class Step(msgspec.Struct, frozen=True):
    """A command due `at_s` seconds after the suggestion reached the bridge."""

    at_s: float
    command: Command


# Speech code -> SpeechTexts field (thesis table 4.1; 2 is formatted with the card).
SPEECH_TEXT_FIELD = {1: "right_card", 2: "exact", 3: "up", 4: "down", 5: "left", 6: "right"}
# Head code -> (rows, cols) direction on the board (thesis table 4.3; 1 is the nod).
HEAD_DIRECTION = {
    2: (0, -1), 3: (0, 1), 4: (-1, 0), 5: (1, 0),
    6: (-1, -1), 7: (-1, 1), 8: (1, -1), 9: (1, 1),
}


def speech_text(code: int, target: int, texts: SpeechTexts) -> str:
    template = getattr(texts, SPEECH_TEXT_FIELD[code])
    return template.format(row=card_row(target) + 1, column=card_col(target) + 1)


class Renderer:
    """Renders actions with one board calibration, gesture set and config."""

    def __init__(self, board: Board, gestures: GestureNames, config: RobotConfig) -> None:
        self.board = board
        self.gestures = gestures
        self.config = config

    def render(self, action_code: int, observed: int, target: int) -> list[Step]:
        parts = action(action_code)
        self.board.card(observed), self.board.card(target)  # refuse off-board cards early
        steps: list[Step] = []
        if parts.speech:
            steps.append(Step(0.0, Say(speech_text(parts.speech, target, self.config.speech))))
        if parts.facial:
            steps.append(Step(0.0, Gesture(self.gestures.smile)))
        if parts.head == 1:
            steps.append(Step(0.0, self._look(self.board.card(observed))))
            steps.append(Step(0.0, Gesture(self.gestures.nod)))
        elif parts.head:
            rows, cols = HEAD_DIRECTION[parts.head]
            lead, hold = self.config.head_turn_lead_s, self.config.head_turn_hold_s
            beside = self.board.beside(observed, rows, cols, self.config.head_turn_offset_m)
            steps.append(Step(0.0, self._look(self.board.card(observed), head=True)))
            steps.append(Step(lead, self._look(beside, head=True)))
            steps.append(Step(lead + hold, self.rest_look()))
        if parts.gaze:
            steps.append(Step(0.0, self._look(self.board.card(target))))
        return steps

    def rest_look(self) -> Look:
        """The head turned back to the rest point (the participant): the last step of a head turn."""
        return self._look(self.board.rest, head=True)

    @staticmethod
    def _look(p, head: bool = False) -> Look:
        return Look(round(p.x, 4), round(p.y, 4), round(p.z, 4), head)
