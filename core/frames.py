"""Frames of reference: how a user mirrors the board when reading a suggestion (thesis 7.3, chapter 8).

Rule: a frame is two bits, columns mirrored (the user counts columns from the
right, so "left" is the robot's right) and rows mirrored (rows counted from the
bottom, so "up" is the robot's down): FRAMES[f] for f = columns + 2 * rows.
A user in frame f reads every direction of a suggestion (speech "Maybe up/down/
left/right", every head turn) mirrored, and reads the coordinates of "Try at
row x and column y" in its own frame, so it names the mirrored card. What the
robot shows physically does not depend on the frame: the observed card (smile,
nod, "It is the right card") and the gaze at the matching card. The human study
saw each of these (7.3: columns counted from the right; head up read as the
card nearest to oneself by some, the farthest by others; "Maybe left/right");
one mirror per user for every family is this module's simplification.

Frames compose by XOR (mirroring twice is no mirror), and each map is an
involution. A robot that renders its actions in frame r to a user in frame f
is read as frame f ^ r (`mismatch`): the simulated user (core/kernels.py
`_user_respond`) takes that one number per game, 0 being the thesis's user.

Tables, derived from the geometry (core/geometry.py) and appendix B
(core/interpretation.py), never typed in:
  CARD_MAP[f, card]   the mirrored card            (4, 18)
  CELL_MAP[f, cell]   the mirrored cell of fig 4.4 (4, 9)
  STATE_MAP[f, s]     the mirrored state (cell, same level; NOT_ONE_CARD stays)  (4, 24)
  HEARING_MAP, VISUAL_MAP, ACTION_MAP[f, a]: the action whose directions are
                      mirrored (4, 8), (4, 11), (4, 88); exact speech, smile,
                      nod and gaze map to themselves.
  FRAME_HEAR[f, observed, match, hearing part], FRAME_VIS[...]: the card sets a
                      frame-f user reads (appendix B mirrored); FRAME_*[0] is
                      interpretation.HEAR_SET / VIS_SET exactly.
A policy moves between frames by its actions alone (`to_frame`): the state is
the robot's reading of the real board, the same whatever the user's frame, and
a frame-f user reads action a as a thesis user reads ACTION_MAP[f, a] (exact
speech aside: its coordinates are mirrored when the robot speaks them, not by
the action code). STATE_MAP is where a state lands on a mirrored board; the
tests check with it that ACTION_MAP is the mirror of appendix B.
"""

from __future__ import annotations

from importlib import resources

import msgspec
import numpy as np

from pairplay.schemas.config import Persona

from .actions import HEARING_EXACT, HEARING_PARTS, N_ACTIONS, N_VISUAL, VISUAL_PARTS
from .geometry import (CELL_INDEX, CELL_NAMES, CELLS, COLS, N_CARDS, N_STATES, NOT_ONE_CARD_STATE, ROWS,
                       SPATIAL_STATES, STATE_INDEX, card_col, card_of, card_row)
from .interpretation import HEAR_SET, VIS_SET, cards_meant, hearing_meaning, visual_meaning
from pairplay.schemas.nesting import json_decode

FRAMES = ("robot's frame", "columns from the right", "rows from the bottom", "both mirrored")
FRAME_KEYS = ("canonical", "mirror-columns", "mirror-rows", "mirror-both")
N_FRAMES = len(FRAMES)
MIRROR_COLUMNS, MIRROR_ROWS = 1, 2


def frame_index(key: str) -> int:
    """The frame of a FRAME_KEYS key; ValueError naming the known keys."""
    if key not in FRAME_KEYS:
        raise ValueError(f"unknown frame {key!r}; known: {', '.join(FRAME_KEYS)}")
    return FRAME_KEYS.index(key)


def mismatch(user_frame, rendered_frame):
    """The frame a user in `user_frame` reads a robot rendering in `rendered_frame` as (XOR; arrays too)."""
    return np.bitwise_xor(user_frame, rendered_frame)


def _mirror_card(f: int, card: int) -> int:
    r, c = card_row(card), card_col(card)
    return card_of(ROWS - 1 - r if f & MIRROR_ROWS else r, COLS - 1 - c if f & MIRROR_COLUMNS else c)


def _mirror_cell(f: int, cell: int) -> int:
    _, dr, dc = CELLS[cell]
    dr, dc = (-dr if f & MIRROR_ROWS else dr), (-dc if f & MIRROR_COLUMNS else dc)
    return (dr + 1) * 3 + (dc + 1)


CARD_MAP = np.array([[_mirror_card(f, c) for c in range(N_CARDS)] for f in range(N_FRAMES)], dtype=np.int64)
CELL_MAP = np.array([[_mirror_cell(f, c) for c in range(len(CELLS))] for f in range(N_FRAMES)], dtype=np.int64)
STATE_MAP = np.array([[int(STATE_INDEX[CELL_MAP[f, cell], level]) for cell, level in SPATIAL_STATES]
                      + [NOT_ONE_CARD_STATE] for f in range(N_FRAMES)], dtype=np.int64)
assert (STATE_MAP >= 0).all() and STATE_MAP.shape == (N_FRAMES, N_STATES)  # the board is symmetric


def _mirror_meaning(f: int, meaning: str | None) -> str | None:
    """A meaning of appendix B as a frame-f user reads it: a cell is mirrored, the rest is physical."""
    if meaning in CELL_INDEX:
        return CELL_NAMES[CELL_MAP[f, CELL_INDEX[meaning]]]
    return meaning


def _part_map(meanings: list) -> np.ndarray:
    """For each frame, the part whose (meaning, channel) is the mirror of each part's."""
    return np.array([[meanings.index((_mirror_meaning(f, m), ch)) for m, ch in meanings]
                     for f in range(N_FRAMES)], dtype=np.int64)


HEARING_MAP = _part_map([hearing_meaning(h) for h in range(len(HEARING_PARTS))])
VISUAL_MAP = _part_map([visual_meaning(v) for v in range(len(VISUAL_PARTS))])
ACTION_MAP = (HEARING_MAP[:, np.arange(N_ACTIONS) // N_VISUAL] * N_VISUAL
              + VISUAL_MAP[:, np.arange(N_ACTIONS) % N_VISUAL])


def read_in_frame(f: int, meaning: str | None, observed: int, match: int) -> int:
    """The cards (bit mask) a frame-f user takes a suggestion meaning of appendix B to name.

    The scalar reference of FRAME_HEAR and FRAME_VIS (tested against them)."""
    if meaning == "match":  # "Try at row x and column y", coordinates read in the user's frame
        return cards_meant("match", observed, int(CARD_MAP[f, match]))
    return cards_meant(_mirror_meaning(f, meaning), observed, match)


def _frame_tables() -> tuple[np.ndarray, np.ndarray]:
    """Appendix B's tables with each frame's parts swapped in; the exact position at the mirrored match."""
    hear = np.stack([HEAR_SET[:, :, HEARING_MAP[f]] for f in range(N_FRAMES)])
    for f in range(N_FRAMES):
        hear[f, :, :, HEARING_EXACT] = HEAR_SET[:, CARD_MAP[f], HEARING_EXACT]
    vis = np.stack([VIS_SET[:, :, VISUAL_MAP[f]] for f in range(N_FRAMES)])
    return np.ascontiguousarray(hear), np.ascontiguousarray(vis)


FRAME_HEAR, FRAME_VIS = _frame_tables()


def to_frame(policy: np.ndarray, frame, q: np.ndarray | None = None):
    """A policy (..., 24) of action codes, and optionally its Q-table (..., 24, 88), moved by `frame`.

    The maps are involutions, so the one function goes both ways: from a
    user's frame to the canonical one (what a frame-f user was shown, as the
    thesis's user would need it) and back. `frame` is one frame or one per
    policy (leading axes). Returns the policy, or (policy, q) when q is given:
    q'[s, a] = q[s, ACTION_MAP[f, a]].
    """
    policy = np.asarray(policy, dtype=np.int64)
    f = np.asarray(frame, dtype=np.int64)
    moved = ACTION_MAP[f.reshape(f.shape + (1,) * (policy.ndim - f.ndim)), policy]
    if q is None:
        return moved
    q = np.asarray(q)
    index = np.broadcast_to(ACTION_MAP[f].reshape(f.shape + (1,) * (q.ndim - 1 - f.ndim) + (N_ACTIONS,)), q.shape)
    return moved, np.take_along_axis(q, index, axis=-1)


class FramedPersona(msgspec.Struct, frozen=True, forbid_unknown_fields=True):
    """A persona of appendix A's kind with the frame it reads suggestions in."""

    frame: str
    persona: Persona

    def __post_init__(self) -> None:
        frame_index(self.frame)


class _FramePersonaFile(msgspec.Struct, forbid_unknown_fields=True):
    note: str
    personas: list[FramedPersona]


def parse_frame_personas(data: bytes) -> dict[str, FramedPersona]:
    """Framed personas by key from the JSON text of a frame persona file."""
    return {p.persona.key: p for p in json_decode(data, type=_FramePersonaFile).personas}


# Their own table: the default study's personas (core/personas.py) are the thesis's and stay as they are.
FRAME_PERSONAS: dict[str, FramedPersona] = parse_frame_personas(
    resources.files("pairplay.core").joinpath("data/frame_personas.json").read_bytes())
