"""Per-game, per-role streams of uniform numbers (the only randomness in core/).

Rule: every game owns three independent streams, one per role that decides
something at random: "deal" (the game: 18 draws per round, the shuffle), "agent"
(the learner: DRAWS_PER_SUGGESTION per suggestion) and "user" (the simulated
participant: DRAWS_PER_TURN per turn); a fourth, "snapshot", breaks the ties of
greedy policies read off a learner during a study, outside the game. A role draws the same count for every
event whatever branch it then takes, so a game's outcome depends only on its
seed: alone on the bus (a batch of one, each role in its own process) or stepped
together with thousands of games in the in-process study, it is the same game.

Seeds: `game_seed(seed, persona, game)` hashes the study seed, the persona's name
and the game's index through numpy's SeedSequence; each role spawns its child by
a fixed key. Draws come from PCG64 in blocks, so stepping a batch costs one
array index per draw, not one Python call per game.
"""

from __future__ import annotations

import zlib
from typing import Sequence

import numpy as np

ROLES = ("deal", "agent", "user", "snapshot")
_ROLE_KEY = {role: i for i, role in enumerate(ROLES)}


def game_seed(seed: int, persona: str, game: int) -> int:
    """A 64-bit seed for one game of one persona in a study seeded with `seed`."""
    key = zlib.crc32(persona.encode("utf-8"))
    state = np.random.SeedSequence([int(seed) & 0xFFFFFFFF, key, int(game)]).generate_state(2, np.uint32)
    return int(state[0]) << 32 | int(state[1])


class UniformStream:
    """Uniform [0, 1) draws for a batch of games, one PCG64 per game and role."""

    def __init__(self, seeds: Sequence[int], role: str, block: int = 1024):
        if role not in _ROLE_KEY:
            raise ValueError(f"unknown role {role!r}; roles are {ROLES}")
        self.role = role
        self._gens = [
            np.random.Generator(np.random.PCG64(np.random.SeedSequence(
                [int(s) >> 32, int(s) & 0xFFFFFFFF, _ROLE_KEY[role]])))
            for s in seeds
        ]
        self._block = int(block)
        self._buf = np.empty((len(self._gens), self._block))
        for i, g in enumerate(self._gens):
            self._buf[i] = g.random(self._block)
        self._pos = np.zeros(len(self._gens), dtype=np.int64)
        self._consumed = np.zeros(len(self._gens), dtype=np.int64)
        # While every game has drawn the same count (the lockstep case), draws
        # are one slice of the buffer instead of a gather.
        self._aligned = True

    @property
    def n_games(self) -> int:
        return len(self._gens)

    @property
    def drawn(self) -> np.ndarray:
        """Draws consumed so far, per game (kept for restarts and checks)."""
        return self._consumed + self._pos

    def _refill(self, games: np.ndarray) -> None:
        for i in games:
            rest = self._buf[i, self._pos[i]:].copy()
            self._buf[i, :rest.size] = rest
            self._buf[i, rest.size:] = self._gens[i].random(self._block - rest.size)
            self._consumed[i] += self._pos[i]
            self._pos[i] = 0

    def take(self, k: int, games: np.ndarray | None = None) -> np.ndarray:
        """The next `k` draws of each game (or of `games`, an index array): shape (n, k)."""
        if k > self._block:
            raise ValueError(f"cannot take {k} draws at once (block is {self._block})")
        if games is None and self._aligned:
            pos = int(self._pos[0])
            if pos + k > self._block:
                self._refill(np.arange(self.n_games))
                pos = 0
            self._pos += k
            return self._buf[:, pos:pos + k].copy()
        idx = np.arange(self.n_games) if games is None else np.asarray(games)
        if idx.size != self.n_games:
            self._aligned = False
        short = idx[self._pos[idx] + k > self._block]
        if short.size:
            self._refill(short)
        out = self._buf[idx[:, None], self._pos[idx, None] + np.arange(k)]
        self._pos[idx] += k
        return out

    def skip(self, n_draws: int, games: np.ndarray | None = None) -> None:
        """Fast-forward by `n_draws` (a restarted service catches up with its log)."""
        left = int(n_draws)
        while left > 0:
            step = min(left, self._block)
            self.take(step, games)
            left -= step


def _select_table() -> np.ndarray:
    """SELECT[mask, k]: the k-th set bit (ascending) of an 18-bit mask; -1 past the end."""
    masks = np.arange(1 << 18, dtype=np.int64)
    table = np.full((1 << 18, 18), -1, dtype=np.int8)
    for k in range(18):  # strip the lowest set bit k times
        lowest = masks & -masks
        table[:, k] = np.where(masks != 0, np.bitwise_count(lowest - 1), -1)
        masks &= masks - 1
    return table


_SELECT = _select_table()


def pick_from_mask(masks: np.ndarray, u: np.ndarray) -> np.ndarray:
    """Uniformly pick one set bit of each mask with draw `u`: the floor(u*n)-th bit.

    Masks (18-bit card sets) must be non-empty. Returns card indices (int64).
    Every random choice of a card is made this way, with exactly one draw.
    """
    masks = np.asarray(masks, dtype=np.int64)
    n = np.bitwise_count(masks)
    k = np.minimum((u * n).astype(np.int64), n - 1)
    return _SELECT[masks, k].astype(np.int64)
