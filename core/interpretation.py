"""How a user reads a suggestion: appendix B as data, perception per table 6.1.

Rule (SPEC "Interpretation"): each perceived, non-"nothing" part of an action
names a set of cards: "It is the right card", a smile and a nod name the observed
card; "Try at row x and column y" names the matching card; a direction, spoken or
by the head, names the cards of that state cell seen from the observed card (so
"Maybe up" is the TOP cell: same column, every row above); the gaze names the
matching card plus its up/down/left/right neighbours that exist (table B.4,
note 2). The user's candidate set is the no-information set (covered cards the
user does not remember) intersected with every perceived part's set; an empty
intersection makes the action inconsistent (the user falls back to the NIS).

Perception (thesis 6.1.3): speech is heard with q = (hearing - 1) * 0.2; sight
decides which visual families are seen (table 6.1): 5-6 head, smile and gaze;
3-4 head and smile; 2 head; 1 nothing.

Whole readings (beyond the thesis: its chapter 8 and 7.4 saw users read a
suggestion as one whole): a persona may read speech and head together
(READINGS). "together": a spoken word is understood only while the head moves
with it, and a head movement only while words come with it; alone, each is
ignored (not perceived). "compound": a spoken straight direction and a
perpendicular head turn mean the diagonal between them ("Maybe up" + turn left
= the TOP_LEFT cell, COMPOUND), where the plain reading intersects them to
nothing. Every other pair is read as above; a persona without readings is the
thesis's user, bit for bit.
"""

from __future__ import annotations

import numpy as np

from .actions import FACIAL, GAZE, HEAD, HEARING_PARTS, SPEECH, VISUAL_PARTS
from .geometry import ALL_CARDS, CELL_INDEX, CELL_MASK, N_CARDS, neighbours_mask

# Appendix B, tables B.1-B.4: what each suggestion code points at.
# "observed": the observed card; "match": the matching card; "cross": the
# matching card and its four neighbours; a cell name: that cell of figure 4.4
# around the observed card; None: says nothing (the NIS).
SPEECH_MEANS = (None, "observed", "match", "TOP", "BOTTOM", "LEFT", "RIGHT")
FACIAL_MEANS = (None, "observed")
HEAD_MEANS = (None, "observed", "LEFT", "RIGHT", "TOP", "BOTTOM",
              "TOP_LEFT", "TOP_RIGHT", "BOTTOM_LEFT", "BOTTOM_RIGHT")
GAZE_MEANS = (None, "cross")
assert len(SPEECH_MEANS) == len(SPEECH) and len(FACIAL_MEANS) == len(FACIAL)
assert len(HEAD_MEANS) == len(HEAD) and len(GAZE_MEANS) == len(GAZE)

# The perception channel each family needs.
CHANNELS = ("hearing", "smile", "head", "gaze")
# Table 6.1: sight level -> visual channels seen.
SIGHT_SEES: dict[int, frozenset[str]] = {
    6: frozenset({"head", "smile", "gaze"}),
    5: frozenset({"head", "smile", "gaze"}),
    4: frozenset({"head", "smile"}),
    3: frozenset({"head", "smile"}),
    2: frozenset({"head"}),
    1: frozenset(),
}


def consider_probability(focus: int) -> float:
    """p = (focus - 1) * 0.2, eq. 6.1: the chance a suggestion is considered at all."""
    return (focus - 1) * 0.2


def hear_probability(hearing: int) -> float:
    """q = (hearing - 1) * 0.2, eq. 6.3: the chance speech is heard."""
    return (hearing - 1) * 0.2


def memory_capacity(memory: int) -> int:
    """m = memory + 1, eq. 6.2: how many cards the user remembers."""
    return memory + 1


def cards_meant(meaning: str | None, observed: int, match: int) -> int:
    """The card set (bit mask) a suggestion meaning names; ALL_CARDS for None."""
    if meaning is None:
        return ALL_CARDS
    if meaning == "observed":
        return 1 << observed
    if meaning == "match":
        return 1 << match
    if meaning == "cross":
        return neighbours_mask(match)
    return int(CELL_MASK[observed, CELL_INDEX[meaning]])


def hearing_meaning(part: int) -> tuple[str | None, str | None]:
    """(meaning, channel) of a hearing part (speech, facial)."""
    speech, facial = HEARING_PARTS[part]
    if speech:
        return SPEECH_MEANS[speech], "hearing"
    if facial:
        return FACIAL_MEANS[facial], "smile"
    return None, None


def visual_meaning(part: int) -> tuple[str | None, str | None]:
    """(meaning, channel) of a visual part (head, gaze)."""
    head, gaze = VISUAL_PARTS[part]
    if head:
        return HEAD_MEANS[head], "head"
    if gaze:
        return GAZE_MEANS[gaze], "gaze"
    return None, None


def _tables() -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    hear = np.zeros((N_CARDS, N_CARDS, len(HEARING_PARTS)), dtype=np.int64)
    vis = np.zeros((N_CARDS, N_CARDS, len(VISUAL_PARTS)), dtype=np.int64)
    for obs in range(N_CARDS):
        for match in range(N_CARDS):
            for h in range(len(HEARING_PARTS)):
                hear[obs, match, h] = cards_meant(hearing_meaning(h)[0], obs, match)
            for v in range(len(VISUAL_PARTS)):
                vis[obs, match, v] = cards_meant(visual_meaning(v)[0], obs, match)
    hear_channel = np.array([CHANNELS.index(c) if c else -1 for c in (hearing_meaning(h)[1] for h in range(len(HEARING_PARTS)))])
    vis_channel = np.array([CHANNELS.index(c) if c else -1 for c in (visual_meaning(v)[1] for v in range(len(VISUAL_PARTS)))])
    return hear, vis, hear_channel, vis_channel


# HEAR_SET[observed, match, hearing part] and VIS_SET[observed, match, visual
# part]: the card masks of appendix B, precomputed for the batched user.
HEAR_SET, VIS_SET, HEAR_CHANNEL, VIS_CHANNEL = _tables()


# Whole readings, as bits of a persona's reading code (core/kernels.py `_user_respond`).
READ_TOGETHER, READ_COMPOUND = 1, 2
READINGS = {"together": READ_TOGETHER, "compound": READ_COMPOUND}


def reading_code(readings) -> int:
    """The bit code of a persona's whole readings (names of READINGS); ValueError for an unknown one."""
    code = 0
    for name in readings:
        if name not in READINGS:
            raise ValueError(f"unknown reading {name!r}; known: {', '.join(READINGS)}")
        code |= READINGS[name]
    return code


def compound_part(hearing_part: int, visual_part: int) -> int:
    """The diagonal head part a (straight speech, perpendicular head) pair means to a "compound"
    reader, or -1 when the pair has no compound meaning."""
    spoken, _ = hearing_meaning(hearing_part)
    turned, channel = visual_meaning(visual_part)
    if channel != "head":
        return -1
    for vertical, horizontal in ((spoken, turned), (turned, spoken)):
        if vertical in ("TOP", "BOTTOM") and horizontal in ("LEFT", "RIGHT"):
            head = HEAD_MEANS.index(f"{vertical}_{horizontal}")
            return VISUAL_PARTS.index((head, 0))
    return -1


# COMPOUND[hearing part, visual part]: compound_part, for the batched user.
COMPOUND = np.array([[compound_part(h, v) for v in range(len(VISUAL_PARTS))] for h in range(len(HEARING_PARTS))],
                    dtype=np.int64)


def sees(sight: int) -> np.ndarray:
    """Bool per CHANNELS entry: which channels a user of this sight perceives (hearing aside)."""
    if sight not in SIGHT_SEES:
        raise ValueError(f"sight must be 1..6, got {sight}")
    return np.array([False] + [ch in SIGHT_SEES[sight] for ch in CHANNELS[1:]])


def candidate_set(nis: int, observed: int, match: int, hearing_part: int, visual_part: int,
                  hearing_perceived: bool, visual_perceived: bool) -> int:
    """The candidate set of one suggestion (scalar reference of the batched user)."""
    cand = nis
    if hearing_perceived:
        cand &= int(HEAR_SET[observed, match, hearing_part])
    if visual_perceived:
        cand &= int(VIS_SET[observed, match, visual_part])
    return cand

