"""The Memory board and its rules (SPEC "Board and game", thesis 6.1.1).

Rule: 18 cards, 9 pairs, 3 x 6, card = row * 6 + col. A turn is a first pick and
a second pick; the two cards then stay up together until the turn is resolved:
equal faces stay up for good (match), otherwise both turn back (miss). A round
is every turn until the board is cleared; each round starts from a new deal.
A pick of a card off the board, face up or matched, a third card while two are
up, or any pick once the round is over is illegal: `IllegalPick` says why and
the board is unchanged (Board is immutable, so "unchanged" is by construction).
"""

from __future__ import annotations

from enum import Enum
from typing import NamedTuple

import numpy as np

from . import kernels
from .geometry import ALL_CARDS, COLS, N_CARDS, N_PAIRS, ROWS


class IllegalPick(ValueError):
    """A pick that the rules refuse; the message says which rule."""


def deal(u: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """A new round from 18 uniform draws per game: (faces, partner), each (B, 18).

    The order of the draws is a uniformly random permutation of the 18 places
    (a stable sort); places 2k and 2k+1 of it get face k, so they are each
    other's partner (core/kernels.py `_deal`, which the simulator runs inline).
    """
    u = np.atleast_2d(np.asarray(u, dtype=np.float64))
    if u.shape[-1] != N_CARDS:
        raise ValueError(f"a deal needs {N_CARDS} draws per game, got {u.shape[-1]}")
    faces = np.empty(u.shape, dtype=np.int8)
    partner = np.empty(u.shape, dtype=np.int64)
    kernels.deal_batch(np.ascontiguousarray(u), faces, partner)
    return faces, partner


class Outcome(str, Enum):
    FIRST = "first"  # first card of a turn is up
    SECOND = "second"  # two cards are up; resolve() ends the turn


class Resolution(NamedTuple):
    first: int
    second: int
    matched: bool
    round_over: bool


_new_board = tuple.__new__


class Board(NamedTuple):
    """One game's board between events: faces, matched cards, cards up this turn."""

    faces: tuple[int, ...]
    matched: int = 0  # bit mask
    up: tuple[int, ...] = ()  # cards face up this turn, in pick order (0, 1 or 2)

    @classmethod
    def from_faces(cls, faces) -> "Board":
        faces = tuple(int(f) for f in faces)
        if len(faces) != N_CARDS or sorted(faces) != sorted(list(range(N_PAIRS)) * 2):
            raise ValueError(f"a deal must hold each of the faces 0..{N_PAIRS - 1} exactly twice")
        return cls(faces)

    @property
    def covered(self) -> int:
        """Bit mask of face-down cards."""
        up = 0
        for c in self.up:
            up |= 1 << c
        return ALL_CARDS & ~self.matched & ~up

    @property
    def round_over(self) -> bool:
        return self.matched == ALL_CARDS

    def partner(self, card: int) -> int:
        face = self.faces[card]
        return next(c for c in range(N_CARDS) if c != card and self.faces[c] == face)

    def check(self, card: int) -> None:
        """Raise IllegalPick if `card` may not be picked now."""
        if not isinstance(card, (int, np.integer)) or isinstance(card, bool) or not 0 <= card < N_CARDS:
            raise IllegalPick(f"card {card!r} is off the board (cards are 0..{N_CARDS - 1}, "
                              f"{ROWS} rows x {COLS} columns)")
        if self.round_over:
            raise IllegalPick("the round is over: every pair is matched")
        if len(self.up) == 2:
            raise IllegalPick(f"two cards ({self.up[0]}, {self.up[1]}) are already up: a third card "
                              "cannot be picked before the turn is resolved")
        if self.matched >> card & 1:
            raise IllegalPick(f"card {card} is already matched")
        if card in self.up:
            raise IllegalPick(f"card {card} is already face up")

    def pick(self, card: int) -> tuple["Board", Outcome]:
        self.check(card)
        up = self.up + (int(card),)
        # the tuple built directly: NamedTuple._replace is a Python call chain, on every live pick (issue 16)
        return _new_board(Board, (self.faces, self.matched, up)), (Outcome.FIRST if len(up) == 1 else Outcome.SECOND)

    def resolve(self) -> tuple["Board", Resolution]:
        """End a turn with two cards up: a pair stays up, a miss turns back."""
        if len(self.up) != 2:
            raise IllegalPick(f"a turn is resolved after two picks; {len(self.up)} card(s) are up")
        a, b = self.up
        hit = self.faces[a] == self.faces[b]
        matched = self.matched | ((1 << a) | (1 << b) if hit else 0)
        board = self._replace(matched=matched, up=())
        return board, Resolution(a, b, bool(hit), board.round_over)
