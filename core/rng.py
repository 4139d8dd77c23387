"""Per-game, per-role streams of uniform numbers (the only randomness in core/).

Rule: every game owns independent streams, one per role that decides something
at random: "deal" (the game: 18 draws per round, the shuffle), "agent" (the
learner: DRAWS_PER_SUGGESTION per suggestion), "user" (the simulated
participant: DRAWS_PER_TURN per turn) and "snapshot" (ties of greedy policies
read off a learner during a study, outside the game). A role draws the same
count for every event whatever branch it then takes, so a game's outcome
depends only on its seed: alone on the bus (a batch of one, each role in its own
process) or stepped together with thousands of games in the in-process study,
it is the same game.

Generator: SplitMix64 (Steele, Lea and Flood, OOPSLA 2014), the generator that
seeds Java's SplittableRandom and xoshiro: draw n of a stream is
mix(key + (n + 1) * 0x9E3779B97F4A7C15), a pure function of the stream's key
and the draw's index. So a batch of streams is a few uint64 array operations
per draw (no per-game Python loop, no buffers), and skipping ahead is adding
to a counter (a restarted service catches up with its log in O(1)). Keys come
from numpy's SeedSequence hashing of (game seed, role), 64 bits each. The
draws themselves are core/kernels.py's `_draw`, the one the compiled simulator
uses inline.
"""

from __future__ import annotations

import zlib
from functools import lru_cache
from typing import Sequence

import numpy as np

from . import kernels

ROLES = ("deal", "agent", "user", "snapshot")
_ROLE_KEY = {role: i for i, role in enumerate(ROLES)}
assert (kernels.DEAL, kernels.AGENT, kernels.USER, kernels.SNAPSHOT) == tuple(_ROLE_KEY[r] for r in ROLES)


@lru_cache(maxsize=1 << 16)
def game_seed(seed: int, persona: str, game: int) -> int:
    """A 64-bit seed for one game of one persona in a study seeded with `seed`."""
    key = zlib.crc32(persona.encode("utf-8"))
    state = np.random.SeedSequence([int(seed) & 0xFFFFFFFF, key, int(game)]).generate_state(2, np.uint32)
    return int(state[0]) << 32 | int(state[1])


def stream_key(seed: int, role: str) -> int:
    """The 64-bit SplitMix64 key of one game's stream for one role."""
    if role not in _ROLE_KEY:
        raise ValueError(f"unknown role {role!r}; roles are {ROLES}")
    return _stream_key(int(seed) & 0xFFFFFFFFFFFFFFFF, _ROLE_KEY[role])


@lru_cache(maxsize=1 << 16)
def _stream_key(s: int, role: int) -> int:
    # SeedSequence hashing costs ~20 us; a study asks for the same evaluation games many times.
    return int(np.random.SeedSequence([s >> 32, s & 0xFFFFFFFF, role]).generate_state(1, np.uint64)[0])


def stream_keys(seeds: Sequence[int], roles: Sequence[str] = ROLES) -> np.ndarray:
    """(n, 4) uint64: the keys of `roles` (default all) of every game, columns in ROLES order, 0 elsewhere."""
    keys = np.zeros((len(seeds), len(ROLES)), dtype=np.uint64)
    for role in roles:
        keys[:, _ROLE_KEY[role]] = [stream_key(s, role) for s in seeds]
    return keys


class UniformStream:
    """Uniform [0, 1) draws for a batch of games, one SplitMix64 stream per game and role."""

    def __init__(self, seeds: Sequence[int], role: str):
        self.role = role
        self._key = np.array([stream_key(s, role) for s in seeds], dtype=np.uint64)
        self._pos = np.zeros(len(self._key), dtype=np.uint64)
        self._all = np.arange(len(self._key))

    @property
    def n_games(self) -> int:
        return len(self._key)

    @property
    def drawn(self) -> np.ndarray:
        """Draws consumed so far, per game."""
        return self._pos.astype(np.int64)

    def take(self, k: int, games: np.ndarray | None = None) -> np.ndarray:
        """The next `k` draws of each game (or of `games`, an index array): shape (n, k)."""
        idx = self._all if games is None else np.asarray(games, dtype=np.int64)
        out = np.empty((idx.size, k))
        kernels.draw_block(self._key, self._pos, k, idx, out)
        return out

    def skip(self, n_draws: int, games: np.ndarray | None = None) -> None:
        """Fast-forward by `n_draws` (a restarted service catches up with its log)."""
        if games is None:
            self._pos += np.uint64(n_draws)
        else:
            self._pos[np.asarray(games)] += np.uint64(n_draws)


def pick_from_mask(masks: np.ndarray, u: np.ndarray) -> np.ndarray:
    """Uniformly pick one set bit of each mask with draw `u`: the floor(u*n)-th bit.

    Masks (18-bit card sets) must be non-empty (an empty one gives -1). Returns
    card indices (int64). Every random choice of a card is made this way, with
    exactly one draw.
    """
    masks, u = np.broadcast_arrays(np.asarray(masks, dtype=np.int64), np.asarray(u, dtype=np.float64))
    out = np.empty(masks.shape, dtype=np.int64)
    kernels.pick_batch(np.ascontiguousarray(masks).reshape(-1), np.ascontiguousarray(u).reshape(-1), out.reshape(-1))
    return out
