"""The simulated user of thesis section 6.1.3, for a batch of games.

Rule (SPEC "Interpretation and user perception", "Memory"):
- First pick: a card of a pair the user remembers whole, if any; otherwise a
  random covered card the user does not remember.
- Intended card (the observed card of the simulation): the remembered match if
  the user knows it; otherwise a random card of the no-information set (NIS:
  covered cards minus those remembered).
- Second pick: the remembered match if known (the suggestion is then not
  learned from); otherwise the suggestion is considered with p = (focus-1)*0.2,
  else ignored and the intended card is picked; a considered suggestion is read
  part by part (speech heard with q = (hearing-1)*0.2, visual parts as sight
  allows) and the user picks at random in the candidate set, or in the NIS when
  the action is inconsistent (empty candidate set).
- Memory holds m = memory + 1 cards: the two cards of a missed turn enter it at
  the end of the turn (first pick, then second), the oldest leaving when it is
  full; matched cards leave it; a new round (a new deal) empties it. A card of a
  missed turn is never already remembered (first picks from memory always match,
  other picks come from the NIS), so "re-seeing" needs no rule.

Draws: DRAWS_PER_TURN uniforms from the "user" stream at the start of every turn,
used or not, in this order: first pick, intended card, focus, hearing, choice in
the candidate set.
"""

from __future__ import annotations

from typing import NamedTuple, Sequence

import numpy as np

from pairplay.schemas.config import Persona

from .actions import ACTION_HEARING, ACTION_VISUAL, HEARING_SMILE, VISUAL_GAZE
from .geometry import N_CARDS
from .interpretation import (HEAR_SET, VIS_SET, consider_probability, hear_probability,
                             memory_capacity, sees)
from .rng import UniformStream, pick_from_mask

DRAWS_PER_TURN = 5
_BIT = np.int64(1) << np.arange(N_CARDS, dtype=np.int64)
_SHIFT = np.arange(N_CARDS, dtype=np.int64)
_ALL_GAMES = slice(None)
_NEVER = np.iinfo(np.int64).max  # stamp of a card not in memory


class Response(NamedTuple):
    second: np.ndarray  # the card picked second
    considered: np.ndarray  # the suggestion was read (not ignored, not from memory)
    consistent: np.ndarray  # its candidate set was not empty
    candidates: np.ndarray  # the candidate set (bit mask; 0 when inconsistent)


class SimulatedUsers:
    """One simulated user per game; arrays indexed by game."""

    def __init__(self, personas: Sequence[Persona], stream: UniformStream):
        if stream.role != "user" or stream.n_games != len(personas):
            raise ValueError("SimulatedUsers needs a 'user' stream with one game per persona")
        self.stream = stream
        n = len(personas)
        self.p_consider = np.array([consider_probability(p.focus) for p in personas])
        self.q_hear = np.array([hear_probability(p.hearing) for p in personas])
        self.capacity = np.array([memory_capacity(p.memory) for p in personas], dtype=np.int64)
        seen = np.array([sees(p.sight) for p in personas])  # (n, channels)
        self.sees_smile, self.sees_head, self.sees_gaze = seen[:, 1], seen[:, 2], seen[:, 3]
        self.stamp = np.full((n, N_CARDS), _NEVER, dtype=np.int64)  # when a card entered memory
        self.memory = np.zeros(n, dtype=np.int64)  # bit mask of remembered cards
        self.clock = np.zeros(n, dtype=np.int64)
        self._u = np.zeros((n, DRAWS_PER_TURN))
        self._rows = np.arange(n)

    def new_round(self, games=_ALL_GAMES) -> None:
        self.stamp[games] = _NEVER
        self.memory[games] = 0

    def first_pick(self, covered: np.ndarray, partner: np.ndarray) -> np.ndarray:
        """Draw this turn's uniforms and choose the first card of every game."""
        self._u = self.stream.take(DRAWS_PER_TURN)
        # A remembered card whose partner is remembered too: a whole pair.
        partner_remembered = ((self.memory[:, None] >> partner) & 1) << _SHIFT
        known = self.memory & partner_remembered.sum(1)
        pool = np.where(known != 0, known, covered & ~self.memory)
        return pick_from_mask(pool, self._u[:, 0])

    def intend(self, first: np.ndarray, match: np.ndarray, covered: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The card the user would pick unaided, and whether it is the remembered match.

        `covered` excludes the first card (it is face up).
        """
        from_memory = (self.memory >> match & 1) == 1
        unaided = pick_from_mask(self.nis(covered), self._u[:, 1])
        return np.where(from_memory, match, unaided), from_memory

    def nis(self, covered: np.ndarray) -> np.ndarray:
        """No-information set: covered cards the user does not remember."""
        nis = covered & ~self.memory
        return np.where(nis != 0, nis, covered)  # never empty while a card is covered

    def respond(self, actions: np.ndarray, observed: np.ndarray, match: np.ndarray,
                intended: np.ndarray, from_memory: np.ndarray, covered: np.ndarray) -> Response:
        """The second pick after a suggestion (see the module rule)."""
        u = self._u
        considered = ~from_memory & (u[:, 2] < self.p_consider)
        heard = u[:, 3] < self.q_hear
        h, v = ACTION_HEARING[actions], ACTION_VISUAL[actions]
        hear_seen = np.where(h == HEARING_SMILE, self.sees_smile, (h > HEARING_SMILE) & heard)
        vis_seen = np.where(v == VISUAL_GAZE, self.sees_gaze, (v > VISUAL_GAZE) & self.sees_head)
        nis = self.nis(covered)
        cand = nis & np.where(hear_seen, HEAR_SET[observed, match, h], -1) \
            & np.where(vis_seen, VIS_SET[observed, match, v], -1)
        consistent = cand != 0
        chosen = pick_from_mask(np.where(consistent, cand, nis), u[:, 4])
        second = np.where(from_memory, match, np.where(considered, chosen, intended))
        return Response(second, considered, consistent, np.where(consistent, cand, 0))

    def end_turn(self, first: np.ndarray, second: np.ndarray, matched: np.ndarray) -> None:
        """Memory after the turn: a miss adds both cards (first, then second), a match removes them."""
        if matched.any():
            g = self._rows[matched]
            self.stamp[g, first[matched]] = _NEVER
            self.stamp[g, second[matched]] = _NEVER
            self.memory[g] &= ~(_BIT[first[matched]] | _BIT[second[matched]])
        missed = ~matched
        if not missed.any():
            return
        g = self._rows[missed]
        # Both cards are new to memory (see the module rule), and newer than any
        # card in it: adding them one by one evicts the (count + 2 - m) oldest.
        evict = np.bitwise_count(self.memory[g]) + 2 - self.capacity[g]
        for nth in (1, 2):
            e = g[evict >= nth]
            if e.size:
                oldest = np.argmin(self.stamp[e], axis=1)
                self.stamp[e, oldest] = _NEVER
                self.memory[e] &= ~_BIT[oldest]
        clock = self.clock[g]
        self.stamp[g, first[g]] = clock
        self.stamp[g, second[g]] = clock + 1
        self.memory[g] |= _BIT[first[g]] | _BIT[second[g]]
        self.clock[g] = clock + 2


UNKNOWN_PARTNER = N_CARDS  # a shift past the 18 card bits: "no remembered partner"


def known_partners(seen_faces: np.ndarray) -> np.ndarray:
    """The partner table a user can know: from the faces it has seen (-1 = unseen).

    The simulated user only ever asks for the partner of a card it remembers,
    and only to see whether that partner is remembered too; so the ground-truth
    table of the in-process study and this one (built on the bus from the faces
    the participant has seen) give the same choices. Unknown -> UNKNOWN_PARTNER.
    """
    faces = np.atleast_2d(seen_faces)
    same = (faces[:, :, None] == faces[:, None, :]) & (faces[:, :, None] >= 0) & ~np.eye(N_CARDS, dtype=bool)
    return np.where(same.any(-1), np.argmax(same, -1), UNKNOWN_PARTNER)
