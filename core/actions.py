"""The composite actions of thesis section 4.2 (tables 4.1-4.4), as data.

Rule: an action is four suggestions, one per family: speech 0..6, facial 0..1,
head 0..9, gaze 0..1. Speech and smile exclude each other (one cannot speak while
smiling), head and gaze exclude each other (the eyes cannot be read while the head
moves). That leaves 8 hearing parts (speech, facial) x 11 visual parts (head,
gaze) = 88 actions, coded as in the thesis's figures (its merged policies sit in
codes 33-43, the "exact position" speech):

    code = 11 * hearing_index + visual_index
    hearing order (speech, facial): (0,0) (0,1) (1,0) (2,0) (3,0) (4,0) (5,0) (6,0)
    visual order  (head, gaze):     (0,0) (0,1) (1,0) (2,0) ... (9,0)
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

SPEECH = (
    "say nothing",
    "\"It is the right card\"",
    "\"Try at row x and column y\"",
    "\"Maybe up\"",
    "\"Maybe down\"",
    "\"Maybe left\"",
    "\"Maybe right\"",
)
FACIAL = ("no expression", "smile")
HEAD = (
    "head still", "nod", "turn left", "turn right", "turn up", "turn down",
    "turn up-left", "turn up-right", "turn down-left", "turn down-right",
)
GAZE = ("no gaze", "gaze at the matching card")

# Speech and head codes that point at the exact card, used by the algebra and the
# user-information exceptions (thesis 5.2).
SPEECH_NOTHING, SPEECH_RIGHT_CARD, SPEECH_EXACT = 0, 1, 2
HEAD_NOTHING, HEAD_NOD = 0, 1

HEARING_PARTS: tuple[tuple[int, int], ...] = ((0, 0), (0, 1)) + tuple((s, 0) for s in range(1, 7))
VISUAL_PARTS: tuple[tuple[int, int], ...] = ((0, 0), (0, 1)) + tuple((h, 0) for h in range(1, 10))
N_HEARING = len(HEARING_PARTS)  # 8
N_VISUAL = len(VISUAL_PARTS)  # 11
N_ACTIONS = N_HEARING * N_VISUAL  # 88

HEARING_NOTHING, HEARING_SMILE, HEARING_EXACT = 0, 1, HEARING_PARTS.index((SPEECH_EXACT, 0))
VISUAL_NOTHING, VISUAL_GAZE, VISUAL_NOD = 0, 1, VISUAL_PARTS.index((HEAD_NOD, 0))


class Action(NamedTuple):
    """One composite action with its thesis code and its four suggestion codes."""

    code: int
    speech: int
    facial: int
    head: int
    gaze: int

    @property
    def hearing(self) -> int:
        return self.code // N_VISUAL

    @property
    def visual(self) -> int:
        return self.code % N_VISUAL

    @property
    def name(self) -> str:
        parts = [SPEECH[self.speech] if self.speech else "", FACIAL[self.facial] if self.facial else "",
                 HEAD[self.head] if self.head else "", GAZE[self.gaze] if self.gaze else ""]
        return " + ".join(p for p in parts if p) or "do nothing"


def code_of(hearing: int, visual: int) -> int:
    return hearing * N_VISUAL + visual


def action(code: int) -> Action:
    if not 0 <= code < N_ACTIONS:
        raise ValueError(f"action code {code} is outside 0..{N_ACTIONS - 1}")
    speech, facial = HEARING_PARTS[code // N_VISUAL]
    head, gaze = VISUAL_PARTS[code % N_VISUAL]
    return Action(code, speech, facial, head, gaze)


def code_of_parts(speech: int, facial: int, head: int, gaze: int) -> int:
    """Thesis code of a four-part action; ValueError if the parts exclude each other."""
    try:
        return code_of(HEARING_PARTS.index((speech, facial)), VISUAL_PARTS.index((head, gaze)))
    except ValueError:
        raise ValueError(
            f"no composite action (speech={speech}, facial={facial}, head={head}, gaze={gaze}):"
            " speech and smile exclude each other, and so do head and gaze") from None


ACTIONS: tuple[Action, ...] = tuple(action(c) for c in range(N_ACTIONS))
ACTION_NAMES: tuple[str, ...] = tuple(a.name for a in ACTIONS)
ACTION_HEARING = np.array([a.hearing for a in ACTIONS], dtype=np.int8)
ACTION_VISUAL = np.array([a.visual for a in ACTIONS], dtype=np.int8)
