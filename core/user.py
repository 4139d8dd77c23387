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
  allows; directions and the exact position read in the user's frame,
  core/frames.py, the robot's own unless given) and the user picks at random in the candidate set, or in the NIS when
  the action is inconsistent (empty candidate set).
- Memory holds m = memory + 1 cards: the two cards of a missed turn enter it at
  the end of the turn (first pick, then second), the oldest leaving when it is
  full; matched cards leave it; a new round (a new deal) empties it. A card of a
  missed turn is never already remembered (first picks from memory always match,
  other picks come from the NIS), so "re-seeing" needs no rule.

Whole readings (future work 1, core/interpretation.py READINGS): a persona of
core/personas.py READING_PERSONAS may read speech and head only together, or a
word and a head turn as one compound direction; the thesis's personas read as above.

Draws: DRAWS_PER_TURN uniforms from the "user" stream at the start of every turn,
used or not, in this order: first pick, intended card, focus, hearing, choice in
the candidate set.
"""

from __future__ import annotations

from typing import NamedTuple, Sequence

import numpy as np

from pairplay.schemas.config import Persona

from . import kernels
from .frames import N_FRAMES
from .geometry import N_CARDS
from .interpretation import consider_probability, hear_probability, memory_capacity, reading_code, sees
from .rng import UniformStream

DRAWS_PER_TURN = kernels.DRAWS_PER_TURN
_ALL_GAMES = slice(None)
_NEVER = kernels.NEVER  # stamp of a card not in memory


class Response(NamedTuple):
    second: np.ndarray  # the card picked second
    considered: np.ndarray  # the suggestion was read (not ignored, not from memory)
    consistent: np.ndarray  # its candidate set was not empty
    candidates: np.ndarray  # the candidate set (bit mask; 0 when inconsistent)


def _distinct(personas: Sequence[Persona]) -> tuple[list[Persona], np.ndarray]:
    """(the distinct persona objects, each game's index among them): a batch of thousands of games has a
    handful of personas, whose figures are computed once each."""
    first: dict[int, int] = {}
    distinct: list[Persona] = []
    rows = np.empty(len(personas), dtype=np.int64)
    for g, p in enumerate(personas):
        i = first.get(id(p))
        if i is None:
            i = first[id(p)] = len(distinct)
            distinct.append(p)
        rows[g] = i
    return distinct, rows


def persona_arrays(personas: Sequence[Persona]) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(p_consider, q_hear, capacity, sees (n, 3): smile, head, gaze) of each game's persona."""
    distinct, rows = _distinct(personas)
    p_consider = np.array([consider_probability(p.focus) for p in distinct], dtype=np.float64)[rows]
    q_hear = np.array([hear_probability(p.hearing) for p in distinct], dtype=np.float64)[rows]
    capacity = np.array([memory_capacity(p.memory) for p in distinct], dtype=np.int64)[rows]
    seen = np.array([sees(p.sight) for p in distinct], dtype=bool).reshape(-1, 4)[:, 1:][rows]
    return p_consider, q_hear, capacity, np.ascontiguousarray(seen)


def reading_codes(personas: Sequence[Persona]) -> np.ndarray:
    """(n,) int64: each persona's whole readings (core/interpretation.py READINGS; 0 for the thesis's
    personas, which have no `reads`: core/personas.py ReadingPersona has)."""
    distinct, rows = _distinct(personas)
    return np.array([reading_code(getattr(p, "reads", ())) for p in distinct], dtype=np.int64).reshape(-1)[rows]


def _ints(x, n: int) -> np.ndarray:
    return kernels.as_batch(x, n, np.int64)


def frames_of(frames, n: int) -> np.ndarray:
    """(n,) frame indices (core/frames.py) from one frame or one per user; ValueError when out of range."""
    out = _ints(frames, n)
    if n and not ((out >= 0) & (out < N_FRAMES)).all():
        raise ValueError(f"a frame is 0..{N_FRAMES - 1} (core/frames.py FRAMES)")
    return out.copy()


class SimulatedUsers:
    """One simulated user per game; arrays indexed by game (core/kernels.py `_user_*` per game)."""

    def __init__(self, personas: Sequence[Persona], stream: UniformStream, frames=0):
        """`frames`: the frame each user reads suggestions in (core/frames.py; 0 = the robot's, as
        the thesis's users), one for all or one per persona."""
        if stream.role != "user" or stream.n_games != len(personas):
            raise ValueError("SimulatedUsers needs a 'user' stream with one game per persona")
        self.stream = stream
        n = len(personas)
        self.frames = frames_of(frames, n)
        self.p_consider, self.q_hear, self.capacity, seen = persona_arrays(personas)
        self.sees_smile, self.sees_head, self.sees_gaze = (np.ascontiguousarray(seen[:, i]) for i in range(3))
        self.reading = reading_codes(personas)
        self.stamp = np.full((n, N_CARDS), _NEVER, dtype=np.int64)  # when a card entered memory
        self.memory = np.zeros(n, dtype=np.int64)  # bit mask of remembered cards
        self.clock = np.zeros(n, dtype=np.int64)
        self._u = np.zeros((n, DRAWS_PER_TURN))
        self._n = n

    def new_round(self, games=_ALL_GAMES) -> None:
        self.stamp[games] = _NEVER
        self.memory[games] = 0

    def first_pick(self, covered: np.ndarray, partner: np.ndarray) -> np.ndarray:
        """Draw this turn's uniforms and choose the first card of every game."""
        self._u = np.ascontiguousarray(self.stream.take(DRAWS_PER_TURN), dtype=np.float64)
        partner = np.ascontiguousarray(np.broadcast_to(np.asarray(partner, dtype=np.int64), (self._n, N_CARDS)))
        out = np.empty(self._n, dtype=np.int64)
        kernels.users_first_pick(self.memory, partner, _ints(covered, self._n), self._u, out)
        return out

    def intend(self, first: np.ndarray, match: np.ndarray, covered: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The card the user would pick unaided, and whether it is the remembered match.

        `covered` excludes the first card (it is face up).
        """
        n = self._n
        intended, from_memory = np.empty(n, dtype=np.int64), np.empty(n, dtype=bool)
        kernels.users_intend(self.memory, _ints(first, n), _ints(match, n), _ints(covered, n), self._u,
                             intended, from_memory)
        return intended, from_memory

    def nis(self, covered: np.ndarray) -> np.ndarray:
        """No-information set: covered cards the user does not remember."""
        out = np.empty(self._n, dtype=np.int64)
        kernels.users_nis(self.memory, _ints(covered, self._n), out)
        return out

    def respond(self, actions: np.ndarray, observed: np.ndarray, match: np.ndarray,
                intended: np.ndarray, from_memory: np.ndarray, covered: np.ndarray) -> Response:
        """The second pick after a suggestion (see the module rule)."""
        n = self._n
        second, candidates = np.empty(n, dtype=np.int64), np.empty(n, dtype=np.int64)
        considered, consistent = np.empty(n, dtype=bool), np.empty(n, dtype=bool)
        kernels.users_respond(kernels.TABLES, self.memory, _ints(actions, n), _ints(observed, n), _ints(match, n),
                              _ints(intended, n), kernels.as_batch(from_memory, n, bool),
                              _ints(covered, n), self._u, self.p_consider, self.q_hear, self.sees_smile,
                              self.sees_head, self.sees_gaze, self.reading, self.frames, second, considered, consistent,
                              candidates)
        return Response(second, considered, consistent, candidates)

    def end_turn(self, first: np.ndarray, second: np.ndarray, matched: np.ndarray) -> None:
        """Memory after the turn: a miss adds both cards (first, then second), a match removes them.

        Both cards of a miss are new to memory (see the module rule), and newer
        than any card in it: adding them one by one evicts the (count + 2 - m) oldest.
        """
        n = self._n
        kernels.users_end_turn(_ints(first, n), _ints(second, n),
                               kernels.as_batch(matched, n, bool),
                               self.memory, self.stamp, self.clock, self.capacity)


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
